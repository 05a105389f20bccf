"""Phase correlation on packed spectra (OpenCV's CCS layout, `pack`): the whitened cross-power
spectrum times a Gaussian low-pass, so that a shift's peak is a sampled Gaussian located to a
small fraction of a pixel by a quadratic fit of its log (docs/method.md)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numba
import numpy as np
from numpy.typing import NDArray

FloatImage = NDArray[np.float32]
PackedSpectrum = NDArray[np.float32]
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
    """The real image (H, W) float32 of a packed spectrum, unscaled (H W times the image whose
    `forward` it is)."""
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
    """A located correlation peak: its sub-pixel shift (2,) (rows, cols) [pixels] wrapped to
    [-H/2, H/2), its quality (the surface at the integer peak over the standard deviation away
    from it; about 3-5 for noise alone) and the (2, 2) negative Hessian of the log surface
    [1/pixel^2] (positive definite for a proper peak)."""

    shift_px: NDArray[np.float64]
    quality: float
    curvature: NDArray[np.float64]

    def covariance_px(self) -> NDArray[np.float64]:
        """(2, 2) covariance [pixel^2] of `shift_px`: inv(curvature) over the squared quality."""
        (a, b), (_, c) = self.curvature
        if not 0.5 * (a + c) - math.hypot(0.5 * (a - c), b) > MIN_CURVATURE:
            cov = np.eye(2) * WIDE_PEAK_VARIANCE_PX2
        else:
            cov = np.array([[c, -b], [-b, a]]) / (a * c - b * b)
        return cov / max(self.quality, 1.0) ** 2


@functools.lru_cache(maxsize=16)
def _packed_lowpass(shape: tuple[int, int], sigma_px: float) -> PackedSpectrum:
    """Packed weights that convolve a surface of `shape` with a Gaussian of `sigma_px` [pixels],
    times 1 / (H W) (the unscaled inverse DFT's)."""
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


@numba.njit(nogil=True, cache=True)
def _cross_power_kernel(ref, mov, weights, ramp, half_turn, out):  # type: ignore[no-untyped-def]  # fmt: skip
    """out = weights * C / (|C| + eps), C = mov * conj(ref) (mov replaced by ramp * conj(mov)
    for a half turn), on packed spectra, in float32."""
    h, w = out.shape
    zero = np.float32(0.0)
    for i in range(h):
        for j in range(1, w - 1, 2):
            out[i, j], out[i, j + 1] = _whitened_product(
                mov[i, j], mov[i, j + 1], ref[i, j], ref[i, j + 1], ramp[i, j], ramp[i, j + 1],
                half_turn, weights[i, j],
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
    """weight * C / (|C| + eps), C = m conj(r) (m replaced by p conj(m) for a half turn), as
    (Re, Im) float32."""
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
    """The sub-pixel peak of a periodic (H, W) correlation surface (index (i, j): the shift
    (i, j) mod (H, W)), within `radius_px` (Chebyshev) of `center_px` (rows, cols) when given;
    the noise is the surface's standard deviation outside a band of rows about the peak, its
    half-width set by the peak width `smoothing_px` [pixels]."""
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
    return Peak(
        shift_px=shift,
        quality=height / noise if noise > 0 else 0.0,  # a flat surface carries no information
        curvature=np.array([[fit[2], fit[3]], [fit[3], fit[4]]]),
    )


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
    half_trace = 0.5 * (c_rr + c_cc)
    min_eig = half_trace - math.sqrt((0.5 * (c_rr - c_cc)) ** 2 + c_rc * c_rc)
    d_r = 0.0
    d_c = 0.0
    if min_eig > MIN_CURVATURE:  # solve C d = g (the Newton step on the log surface)
        det = c_rr * c_cc - c_rc * c_rc
        d_r = min(max((c_cc * g_r - c_rc * g_c) / det, -1.0), 1.0)
        d_c = min(max((c_rr * g_c - c_rc * g_r) / det, -1.0), 1.0)
    return d_r, d_c, c_rr, c_rc, c_cc


@numba.njit(nogil=True, cache=True, fastmath={"reassoc", "contract"})  # vectorised sums
def std_outside_rows(surface, i0, exclude):  # type: ignore[no-untyped-def]  # fmt: skip
    """Standard deviation of the (H, W) surface without the rows within `exclude` of row i0
    (periodic); 0 when nothing is left."""
    h, w = surface.shape
    total = 0.0
    total_sq = 0.0
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
