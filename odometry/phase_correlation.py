"""Phase correlation on packed spectra (OpenCV's CCS layout, `pack`; docs/method.md): translation
by a whitened cross-power spectrum times a Gaussian low-pass (peaks fitted sub-pixel); rotation by
Fourier-Mellin (modulo pi; locks toward zero for small turns), refined on a polar grid."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numba
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
FloatImage = NDArray[np.float32]
PackedSpectrum = NDArray[np.float32]
Points = tuple[FloatImage, FloatImage, FloatImage, FloatImage]
"""(x, y, range, bearing) [m, rad] of points, each (H, W) float32."""
SPECTRUM_EPS = 1e-12
"""Added to spectral magnitudes before whitening (avoids 0 / 0 on empty frequencies)."""
TINY = 1e-30
LOG_FLOOR_FRACTION = 1e-3
"""Surface values are floored at this fraction of the peak before taking logs."""
MIN_CURVATURE = 1e-6
"""Curvatures [1/pixel^2] below this mean a flat (degenerate) peak."""
WIDE_PEAK_VARIANCE_PX2 = 1e2
"""Variance [pixel^2] assumed for a peak whose curvature is not positive definite."""
PEAK_EXCLUSION_SIGMAS = 4.0
"""The noise level is measured outside this many smoothing widths around the peak."""


def forward(image: FloatImage) -> PackedSpectrum:
    """Packed spectrum (H, W) float32 of a real (H, W) float32 image (H, W even, >= 4)."""
    shape = image.shape
    if len(shape) != 2 or shape[0] % 2 or shape[1] % 2 or min(shape) < 4:
        raise ValueError(f"packed spectra need a 2-D image with even sides >= 4, got {shape}")
    return np.asarray(cv2.dft(np.ascontiguousarray(image, dtype=np.float32)), dtype=np.float32)


def inverse(packed: PackedSpectrum) -> FloatImage:
    """The real image (H, W) float32 of a packed spectrum, unscaled (H W times its `forward`'s)."""
    return np.asarray(cv2.idft(packed, flags=cv2.DFT_REAL_OUTPUT), dtype=np.float32)


def pack(half: NDArray[np.complexfloating]) -> PackedSpectrum:
    """The packed spectrum (H, W) of a half spectrum (H, W // 2 + 1) (`numpy.fft.rfft2`'s):
    columns 1 .. W - 2 hold (Re, Im) of column frequencies 1 .. W / 2 - 1; columns 0 and W - 1
    the real values of row frequencies 0 (row 0) and H / 2 (row H - 1) of column frequencies 0
    and W / 2, and (Re, Im) of row frequencies 1 .. H / 2 - 1 in rows (2 k - 1, 2 k)."""
    h, w = half.shape[0], 2 * (half.shape[1] - 1)
    out = np.empty((h, w), dtype=np.float32)
    out[:, 1 : w - 1 : 2] = half[:, 1 : w // 2].real
    out[:, 2 : w - 1 : 2] = half[:, 1 : w // 2].imag
    for col, k in ((0, 0), (w - 1, w // 2)):
        column = half[:, k]
        out[0, col] = column[0].real
        out[1 : h - 1 : 2, col] = column[1 : h // 2].real
        out[2 : h - 1 : 2, col] = column[1 : h // 2].imag
        out[h - 1, col] = column[h // 2].real
    return out


def forward_rows(image: FloatImage) -> PackedSpectrum:
    """Packed spectra (rows, n) float32 of every row of a real (rows, n) image: per row Re(0),
    (Re, Im) pairs of the frequencies 1 .. (n - 1) // 2, then Re(n / 2) when n is even."""
    image = np.ascontiguousarray(image, dtype=np.float32)
    return np.asarray(cv2.dft(image, flags=cv2.DFT_ROWS), dtype=np.float32)


@dataclass(frozen=True)
class Peak:
    """A correlation peak: sub-pixel shift (2,) (rows, cols) [pixels] in [-H/2, H/2), quality (the
    peak over the standard deviation away from it; 3-5 for noise alone) and the (2, 2) negative
    Hessian of the log surface [1/pixel^2] (positive definite for a proper peak)."""

    shift_px: FloatArray
    quality: float
    curvature: FloatArray

    def covariance_px(self) -> FloatArray:
        """(2, 2) covariance [pixel^2] of `shift_px`: inv(curvature) over the squared quality."""
        (a, b), (_, c) = self.curvature
        if not 0.5 * (a + c) - math.hypot(0.5 * (a - c), b) > MIN_CURVATURE:
            cov = np.eye(2) * WIDE_PEAK_VARIANCE_PX2
        else:
            cov = np.array([[c, -b], [-b, a]]) / (a * c - b * b)
        return cov / max(self.quality, 1.0) ** 2


@functools.lru_cache(maxsize=16)
def _packed_lowpass(shape: tuple[int, int], sigma_px: float) -> PackedSpectrum:
    """Packed Gaussian (`sigma_px` [pixels]) low-pass for a surface of `shape`, times 1 / (H W)."""
    fy = np.fft.fftfreq(shape[0])[:, None]
    fx = np.fft.rfftfreq(shape[1])[None, :]
    weights = np.exp(-2.0 * (np.pi * sigma_px) ** 2 * (fy * fy + fx * fx)).astype(np.float32)
    scaled = weights.astype(np.float64) / (shape[0] * shape[1])
    packed = pack(scaled + 1j * scaled)
    packed.setflags(write=False)  # shared through the cache
    return packed


@functools.lru_cache(maxsize=4)
def _packed_half_turn_ramp(size_px: int) -> PackedSpectrum:
    """exp(2 pi i (k_r + k_c) / n), packed: a square image turned by pi has this times its
    conjugate spectrum (the grid is centred between pixels)."""
    k_r = np.fft.fftfreq(size_px)[:, None]
    k_c = np.fft.rfftfreq(size_px)[None, :]
    packed = pack(np.exp(2j * np.pi * (k_r + k_c)).astype(np.complex64))
    packed.setflags(write=False)
    return packed


def correlate(
    f_ref: PackedSpectrum,
    f_mov: PackedSpectrum,
    shape: tuple[int, int],
    smoothing_px: float,
    half_turn: bool = False,
) -> FloatImage:
    """Phase-correlation surface (H, W) float32 of the packed spectra of two images of `shape`
    (the moved one turned by pi with `half_turn`, square images only), peaking at d (rows, cols)
    when mov(p) = ref(p - d); peak width `smoothing_px` [pixels]."""
    weights = _packed_lowpass(shape, float(smoothing_px))
    ramp = _packed_half_turn_ramp(shape[0]) if half_turn else weights
    cross = np.empty(shape, dtype=np.float32)
    _cross_power_kernel(f_ref, f_mov, weights, ramp, half_turn, cross)
    return inverse(cross)


@numba.njit(nogil=True, cache=True, error_model="numpy")  # vectorised: no zero-divisor checks
def _cross_power_kernel(ref, mov, weights, ramp, half_turn, out):  # type: ignore[no-untyped-def]  # fmt: skip
    """out = weights * C / (|C| + eps) on packed spectra (`_whitened_product`), float32."""
    h, w = out.shape
    zero = np.float32(0.0)
    for i in range(h):
        m, r, p, o = mov[i], ref[i], ramp[i], out[i]
        for k in range(1, w // 2):  # (Re, Im) at columns (2 k - 1, 2 k)
            o[2 * k - 1], o[2 * k] = _whitened_product(
                m[2 * k - 1], m[2 * k], r[2 * k - 1], r[2 * k], p[2 * k - 1], p[2 * k],
                half_turn, weights[i, 2 * k - 1],
            )  # fmt: skip
    for j in (0, w - 1):
        for i in range(1, h - 1, 2):
            out[i, j], out[i + 1, j] = _whitened_product(
                mov[i, j], mov[i + 1, j], ref[i, j], ref[i + 1, j], ramp[i, j], ramp[i + 1, j],
                half_turn, weights[i, j],
            )  # fmt: skip
        for i in (0, h - 1):
            out[i, j], _ = _whitened_product(
                mov[i, j], zero, ref[i, j], zero, ramp[i, j], zero, half_turn, weights[i, j]
            )


@numba.njit(nogil=True, cache=True, inline="always")
def _whitened_product(m_re, m_im, r_re, r_im, p_re, p_im, half_turn, weight):  # type: ignore[no-untyped-def]  # fmt: skip
    """weight * C / (|C| + eps), C = m conj(r) (m: p conj(m) for a half turn), (Re, Im) float32."""
    if half_turn:
        m_re, m_im = p_re * m_re + p_im * m_im, p_im * m_re - p_re * m_im
    c_re = m_re * r_re + m_im * r_im
    c_im = m_im * r_re - m_re * r_im
    scale = weight / (np.float32(math.sqrt(c_re * c_re + c_im * c_im)) + np.float32(SPECTRUM_EPS))
    return c_re * scale, c_im * scale


def locate_peak(
    surface: FloatImage,
    smoothing_px: float,
    center_px: tuple[float, float] | None = None,
    radius_px: float | None = None,
) -> Peak:
    """The sub-pixel peak of a periodic (H, W) surface ((i, j): the shift (i, j) mod (H, W)),
    within `radius_px` (Chebyshev) of `center_px` (rows, cols) when given; the noise is measured
    outside a band of rows about it, as wide as the peak width `smoothing_px` [pixels] sets."""
    h, w = surface.shape
    if center_px is None or radius_px is None:
        i0, j0 = divmod(int(np.argmax(surface)), w)
    else:
        offsets = np.arange(-int(np.ceil(radius_px)), int(np.ceil(radius_px)) + 1)
        rows = (int(round(center_px[0])) + offsets) % h
        cols = (int(round(center_px[1])) + offsets) % w
        a, b = divmod(int(np.argmax(surface[np.ix_(rows, cols)])), len(offsets))
        i0, j0 = int(rows[a]), int(cols[b])
    height = float(surface[i0, j0])
    fit = _fit_log_quadratic(surface, i0, j0, max(height, TINY) * LOG_FLOOR_FRACTION)
    exclude = int(np.ceil(PEAK_EXCLUSION_SIGMAS * smoothing_px)) + 1
    noise = float(std_outside_rows(surface, i0, exclude))
    shift = np.array([(i0 + fit[0] + h / 2.0) % h - h / 2.0, (j0 + fit[1] + w / 2.0) % w - w / 2.0])
    quality = height / noise if noise > 0 else 0.0  # a flat surface carries no information
    return Peak(shift, quality, np.array([[fit[2], fit[3]], [fit[3], fit[4]]]))


@numba.njit(nogil=True, cache=True)
def _fit_log_quadratic(surface, i0, j0, floor):  # type: ignore[no-untyped-def]  # fmt: skip
    """(d_row, d_col, c_rr, c_rc, c_cc): offset (clipped to +-1; 0 unless the curvature is
    positive definite) and negative Hessian of a quadratic through the log of the 3 x 3
    neighbourhood of (i0, j0) (values floored at `floor`)."""
    h, w = surface.shape
    logp = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            value = np.float64(surface[(i0 + a - 1) % h, (j0 + b - 1) % w])
            logp[a, b] = math.log(max(value, floor))
    g_r = 0.5 * (logp[2, 1] - logp[0, 1])
    g_c = 0.5 * (logp[1, 2] - logp[1, 0])
    h_rr = logp[2, 1] - 2.0 * logp[1, 1] + logp[0, 1]
    h_cc = logp[1, 2] - 2.0 * logp[1, 1] + logp[1, 0]
    h_rc = 0.25 * (logp[2, 2] - logp[2, 0] - logp[0, 2] + logp[0, 0])
    c_rr, c_rc, c_cc = -h_rr, -h_rc, -h_cc
    min_eig = 0.5 * (c_rr + c_cc) - math.sqrt((0.5 * (c_rr - c_cc)) ** 2 + c_rc * c_rc)
    d_r = d_c = 0.0
    if min_eig > MIN_CURVATURE:  # solve C d = g (the Newton step on the log surface)
        det = c_rr * c_cc - c_rc * c_rc
        d_r = min(max((c_cc * g_r - c_rc * g_c) / det, -1.0), 1.0)
        d_c = min(max((c_rr * g_c - c_rc * g_r) / det, -1.0), 1.0)
    return d_r, d_c, c_rr, c_rc, c_cc


@numba.njit(nogil=True, cache=True, fastmath={"reassoc", "contract"})  # vectorised sums
def std_outside_rows(surface, i0, exclude):  # type: ignore[no-untyped-def]  # fmt: skip
    """Standard deviation of the surface (H, W) beyond `exclude` rows (periodic) of row i0, or 0."""
    h, w = surface.shape
    total = total_sq = 0.0
    count = 0
    for i in range(h):
        d = (i - i0) % h
        if d <= exclude or d >= h - exclude:
            continue
        for j in range(w):
            v = np.float64(surface[i, j])
            total += v
            total_sq += v * v
        count += w
    if count == 0:
        return 0.0
    mean = total / count
    return math.sqrt(max(total_sq / count - mean * mean, 0.0))


@dataclass(frozen=True)
class RotationSettings:
    """Fourier-Mellin rotation settings (internal constants: `ROTATION`)."""

    n_angles: int = 720  # samples of the spectrum's angle over [0, pi)
    n_radii: int = 96  # ... and of its radius, from min to max frequency (fractions of Nyquist)
    min_frequency: float = 0.05
    max_frequency: float = 0.9
    smoothing_bins: float = 1.0  # Gaussian width [angle bins] of the correlation peak
    refine: bool = True  # refine the rotation on a polar grid about the reference sensor
    refine_n_angles: int = 720  # the grid's samples of a turn and of range [m]
    refine_min_range_m: float = 5.0
    refine_max_range_m: float = 80.0
    refine_range_step_m: float = 0.5
    refine_smoothing_bins: float = 2.0  # Gaussian width [angle bins] of the refinement peak
    # At most this many refinements (a second converges from a predicted yaw degrees off), each
    # after the first preceded by a coarse translation at the refined yaw, while the last one
    # turned more than `refine_repeat_min_deg`; then one at the fine translation.
    refine_passes: int = 2
    refine_repeat_min_deg: float = 0.05
    refine_at_fine: bool = True


ROTATION = RotationSettings()


@dataclass(frozen=True)
class RotationEstimate:
    """Rotation of a scan relative to a reference [rad] (in [-pi/2, pi/2) from Fourier-Mellin, in
    [-pi, pi) from a refinement), its standard deviation and the angular peak's quality."""

    angle_rad: float
    sigma_rad: float
    quality: float


@functools.lru_cache(maxsize=8)
def _sampler(size_px: int, cfg: RotationSettings) -> tuple[FloatImage, FloatImage]:
    """cv2.remap maps (cols, rows): (radius, angle) to a row-centred half spectrum."""
    nyquist = size_px / 2.0
    radii = np.linspace(cfg.min_frequency * nyquist, cfg.max_frequency * nyquist, cfg.n_radii)
    angles = np.arange(cfg.n_angles) * (np.pi / cfg.n_angles)
    k_row = radii[:, None] * np.cos(angles)[None, :]
    k_col = radii[:, None] * np.sin(angles)[None, :]
    return k_col.astype(np.float32), (k_row + nyquist).astype(np.float32)


def signature(spectrum: PackedSpectrum, cfg: RotationSettings) -> PackedSpectrum:
    """Packed angular spectra (n_radii, n_angles) of the polar-resampled log magnitude of an
    image's packed spectrum (size_px, size_px)."""
    size = spectrum.shape[0]
    centred = np.empty((size, size // 2 + 1), dtype=np.float32)
    _centred_log_magnitude(spectrum, centred)
    map_cols, map_rows = _sampler(size, cfg)
    polar = cv2.remap(
        centred, map_cols, map_rows, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
    )
    return forward_rows(np.asarray(polar, dtype=np.float32))


@numba.njit(nogil=True, cache=True)
def _log_magnitude(re, im):  # type: ignore[no-untyped-def]  # fmt: skip
    # log(1 + m): log1p is several times slower and no more accurate for magnitudes far above 1.
    return math.log(np.float32(1.0) + np.float32(math.sqrt(re * re + im * im)))


@numba.njit(nogil=True, cache=True)
def _centred_log_magnitude(packed, out):  # type: ignore[no-untyped-def]  # fmt: skip
    """out (h, w // 2 + 1) = log(1 + |half spectrum|) of packed (h, w), rows fftshifted."""
    h, w = packed.shape
    half = h // 2
    for i in range(h):
        row = (i + half) % h
        for k in range(1, w // 2):
            out[row, k] = _log_magnitude(packed[i, 2 * k - 1], packed[i, 2 * k])
    for col, k in ((0, 0), (w - 1, w // 2)):
        out[half, k] = _log_magnitude(packed[0, col], np.float32(0.0))
        out[0, k] = _log_magnitude(packed[h - 1, col], np.float32(0.0))
        for r in range(1, half):  # row frequencies r and -r share the magnitude
            value = _log_magnitude(packed[2 * r - 1, col], packed[2 * r, col])
            out[r + half, k] = value
            out[half - r, k] = value


def estimate_rotation(
    ref: PackedSpectrum, mov: PackedSpectrum, cfg: RotationSettings
) -> RotationEstimate:
    """Rotation of the `mov` image relative to `ref` (modulo pi) from their signatures."""
    curve = correlate_1d(ref, mov, cfg.n_angles, cfg.smoothing_bins)
    return _rotation_of_peak(curve, cfg.smoothing_bins, np.pi / cfg.n_angles)


@dataclass(frozen=True)
class PolarGrid:
    """Points of a polar grid about a sensor, (n_ranges, n_angles) float32 [m, rad]: row k at
    range min_range_m + (k + 0.5) * range_step_m, column j at bearing j * 2 pi / n_angles."""

    x_m: FloatImage
    y_m: FloatImage
    range_m: FloatImage
    bearing_rad: FloatImage

    def shifted(self, dx_m: float, dy_m: float) -> Points:
        """(x, y, range, bearing) of the grid's points seen from a sensor at (dx_m, dy_m)."""
        x = np.subtract(self.x_m, np.float32(dx_m), dtype=np.float32)
        y = np.subtract(self.y_m, np.float32(dy_m), dtype=np.float32)
        # cv2's polar conversion: ~0.01 deg angle error, ~25x faster than numpy's arctan2.
        rng, bearing = cv2.cartToPolar(x, y)
        return x, y, np.asarray(rng, np.float32), np.asarray(bearing, np.float32)


@functools.lru_cache(maxsize=4)
def polar_grid(cfg: RotationSettings) -> PolarGrid:
    """The refinement grid of a rotation config (cached)."""
    n_ranges = max(
        1, int(round((cfg.refine_max_range_m - cfg.refine_min_range_m) / cfg.refine_range_step_m))
    )
    ranges = cfg.refine_min_range_m + (np.arange(n_ranges) + 0.5) * cfg.refine_range_step_m
    bearings = np.arange(cfg.refine_n_angles) * (2.0 * np.pi / cfg.refine_n_angles)
    bearings = np.where(bearings >= np.pi, bearings - 2.0 * np.pi, bearings)
    x = ranges[:, None] * np.cos(bearings)[None, :]
    y = ranges[:, None] * np.sin(bearings)[None, :]
    rng = np.broadcast_to(ranges[:, None], x.shape)
    bear = np.broadcast_to(bearings[None, :], x.shape)
    return PolarGrid(
        x_m=x.astype(np.float32),
        y_m=y.astype(np.float32),
        range_m=np.ascontiguousarray(rng, dtype=np.float32),
        bearing_rad=np.ascontiguousarray(bear, dtype=np.float32),
    )


def refine_rotation_against(
    ref_spectrum: PackedSpectrum, mov: FloatImage, cfg: RotationSettings
) -> RotationEstimate:
    """The residual rotation [rad] to add to the estimate's yaw, of `mov` (the moved scan on
    the grid through the current estimate) against the reference's `forward_rows` spectra."""
    n = mov.shape[1]
    curve = correlate_1d(ref_spectrum, forward_rows(mov), n, cfg.refine_smoothing_bins)
    return _rotation_of_peak(curve, cfg.refine_smoothing_bins, 2.0 * np.pi / n)


def _rotation_of_peak(curve: FloatArray, smoothing: float, step_rad: float) -> RotationEstimate:
    """The rotation at the peak of an angular correlation (samples `step_rad` apart, peak width
    `smoothing` samples) by a parabola through the log of its top 3, minus the shift (signature
    angles run against a CCW turn; on a `PolarGrid`, content d further CCW was turned d too far)."""
    n = len(curve)
    i0 = int(np.argmax(curve))
    height = float(curve[i0])
    floor = max(height, TINY) * LOG_FLOOR_FRACTION
    logt = [math.log(max(float(curve[(i0 + k) % n]), floor)) for k in (-1, 0, 1)]
    second = logt[0] - 2.0 * logt[1] + logt[2]
    offset = 0.0
    if second < -MIN_CURVATURE:
        offset = min(max(0.5 * (logt[0] - logt[2]) / second, -1.0), 1.0)
    exclude = int(np.ceil(PEAK_EXCLUSION_SIGMAS * smoothing)) + 1
    # The samples as the rows of a one-column surface: the same noise as the 2-D peaks.
    noise = float(std_outside_rows(curve.reshape(-1, 1), i0, exclude))
    quality = height / noise if noise > 0 else 0.0
    shift = (i0 + offset + n / 2.0) % n - n / 2.0
    width2 = 1.0 / -second if -second > MIN_CURVATURE else WIDE_PEAK_VARIANCE_PX2  # [sample^2]
    sigma_rad = float(np.sqrt(width2 / max(quality, 1.0) ** 2) * step_rad)
    return RotationEstimate(float(-shift * step_rad), sigma_rad, float(quality))


def correlate_1d(
    s_ref: PackedSpectrum, s_mov: PackedSpectrum, n: int, smoothing: float
) -> FloatArray:
    """Whitened phase correlation (n,) of row spectra (rows, n) summed over rows without the zero
    frequency, peaking at d when mov(t) = ref(t - d), a Gaussian of `smoothing` samples."""
    summed_re = np.zeros(n // 2 + 1)
    summed_im = np.zeros(n // 2 + 1)
    _summed_cross_power(s_ref, s_mov, summed_re, summed_im)
    summed = (summed_re + 1j * summed_im) * _gaussian_lowpass_1d(n, float(smoothing))
    return np.fft.irfft(summed, n=n) / max(1, s_ref.shape[0])


@functools.lru_cache(maxsize=16)
def _gaussian_lowpass_1d(n: int, smoothing: float) -> FloatArray:
    weights = np.exp(-2.0 * (np.pi * smoothing * np.fft.rfftfreq(n)) ** 2)
    weights.setflags(write=False)  # shared through the cache
    return weights


@numba.njit(nogil=True, cache=True, error_model="numpy")  # vectorised: no zero-divisor checks
def _summed_cross_power(s_ref, s_mov, out_re, out_im):  # type: ignore[no-untyped-def]  # fmt: skip
    """out[k] += sum over rows of C / (|C| + eps), C = mov * conj(ref), frequencies k >= 1."""
    n, one = s_ref.shape[1], np.float32(1.0)
    for i in range(s_ref.shape[0]):
        m, r = s_mov[i], s_ref[i]
        for k in range(1, (n - 1) // 2 + 1):
            c_re, c_im = _whitened_product(
                m[2 * k - 1], m[2 * k], r[2 * k - 1], r[2 * k], one, one, False, one
            )
            out_re[k] += c_re
            out_im[k] += c_im
        if n % 2 == 0:  # the real Nyquist value
            c = m[n - 1] * r[n - 1]
            out_re[n // 2] += c / (np.float32(abs(c)) + np.float32(SPECTRUM_EPS))
