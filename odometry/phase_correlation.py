"""2-D phase correlation with a smooth, sub-pixel-locatable peak and a peak quality measure.

Spectra are packed real spectra (`odometry.packed`: OpenCV's CCS layout, (H, W) float32, H and W
even), made by `forward`. The normalised
cross-power spectrum is multiplied by a Gaussian low-pass, which convolves the correlation surface
with a Gaussian of `smoothing_px`: the peak of a pure shift becomes a sampled Gaussian, and a
quadratic fit of the log surface on its 3 x 3 neighbourhood then locates it to a small fraction of
a pixel and gives its curvature.

Shift convention: `correlate(f_ref, f_mov)` peaks at d (rows, cols) when mov(p) = ref(p - d), i.e.
when the content of `mov` is that of `ref` moved by +d pixels.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from odometry.packed import PackedSpectrum, forward, inverse, pack

__all__ = ["PackedSpectrum", "correlate", "forward", "locate_peak"]

FloatImage = NDArray[np.float32]
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


@dataclass(frozen=True)
class Peak:
    """A located correlation peak.

    Attributes:
        shift_px: (2,) sub-pixel shift (rows, cols) [pixels], wrapped to [-H/2, H/2).
        height: surface value at the integer peak.
        quality: peak-to-noise ratio: height over the standard deviation of the surface away
            from the peak (dimensionless; about 3-5 for noise alone).
        curvature: (2, 2) negative Hessian of the log surface at the peak [1/pixel^2] (positive
            definite for a proper peak), from the 3 x 3 quadratic fit.
        noise: standard deviation of the surface away from the peak.
    """

    shift_px: NDArray[np.float64]
    height: float
    quality: float
    curvature: NDArray[np.float64]
    noise: float

    def covariance_px(self) -> NDArray[np.float64]:
        """(2, 2) covariance [pixel^2] of `shift_px`: peak width squared over peak-to-noise.

        The fitted Gaussian peak has covariance inv(curvature); the location of a peak of that
        width measured against noise of relative level 1/quality is uncertain by roughly that
        width divided by the quality.
        """
        cov = _safe_inverse(self.curvature)
        return cov / max(self.quality, 1.0) ** 2


def _safe_inverse(matrix: NDArray[np.float64]) -> NDArray[np.float64]:
    """Inverse of a 2x2 curvature, falling back to a wide isotropic peak when not definite."""
    (a, b), (_, c) = matrix
    min_eigenvalue = 0.5 * (a + c) - math.hypot(0.5 * (a - c), b)
    if not min_eigenvalue > MIN_CURVATURE:
        return np.eye(2) * WIDE_PEAK_VARIANCE_PX2
    return np.array([[c, -b], [-b, a]]) / (a * c - b * b)


@functools.lru_cache(maxsize=16)
def gaussian_lowpass(shape: tuple[int, int], sigma_px: float) -> NDArray[np.float32]:
    """Half-spectrum weights that convolve a surface of `shape` with a Gaussian of `sigma_px`."""
    fy = np.fft.fftfreq(shape[0])[:, None]
    fx = np.fft.rfftfreq(shape[1])[None, :]
    weights = np.exp(-2.0 * (np.pi * sigma_px) ** 2 * (fy * fy + fx * fx)).astype(np.float32)
    weights.setflags(write=False)  # shared through the cache
    return weights


@functools.lru_cache(maxsize=16)
def _packed_lowpass(shape: tuple[int, int], sigma_px: float) -> PackedSpectrum:
    """`gaussian_lowpass` at every packed position (both of a pair), times 1 / (H W) (the
    scale of the unscaled inverse DFT)."""
    weights = gaussian_lowpass(shape, sigma_px).astype(np.float64) / (shape[0] * shape[1])
    packed = pack(weights + 1j * weights)
    packed.setflags(write=False)
    return packed


@functools.lru_cache(maxsize=4)
def half_turn_ramp(size_px: int) -> NDArray[np.complex64]:
    """exp(2 pi i (k_r + k_c) / n) on the half spectrum of a square image: the spectrum of the
    image turned by pi is this times its conjugate spectrum (the grid is centred between
    pixels)."""
    k_r = np.fft.fftfreq(size_px)[:, None]
    k_c = np.fft.rfftfreq(size_px)[None, :]
    ramp = np.exp(2j * np.pi * (k_r + k_c)).astype(np.complex64)
    ramp.setflags(write=False)
    return ramp


@functools.lru_cache(maxsize=4)
def _packed_half_turn_ramp(size_px: int) -> PackedSpectrum:
    packed = pack(half_turn_ramp(size_px))  # +-1 at the four real positions
    packed.setflags(write=False)
    return packed


def correlate(
    f_ref: PackedSpectrum,
    f_mov: PackedSpectrum,
    shape: tuple[int, int],
    smoothing_px: float,
    whitening: float = 1.0,
    half_turn: bool = False,
) -> FloatImage:
    """Phase-correlation surface (H, W) float32 of two packed spectra of images of `shape`.

    Args:
        f_ref, f_mov: packed spectra (`forward`) of the reference and moved images.
        shape: (H, W) of the images.
        smoothing_px: Gaussian width of the peak [pixels].
        whitening: exponent of the magnitude normalisation (1: phase only; 0: plain
            cross-correlation).
        half_turn: correlate with the moved image turned by pi (square images only; its
            spectrum is `half_turn_ramp` times the conjugate of `f_mov`).

    The cross-power spectrum is made in one compiled pass over the packed spectra
    (`_cross_power_kernel`).
    """
    weights = _packed_lowpass(shape, float(smoothing_px))
    ramp = _packed_half_turn_ramp(shape[0]) if half_turn else weights
    cross = np.empty(shape, dtype=np.float32)
    _cross_power_kernel(f_ref, f_mov, weights, ramp, half_turn, float(whitening), cross)
    return inverse(cross)


@numba.njit(nogil=True, cache=True)
def _cross_power_kernel(ref, mov, weights, ramp, half_turn, whitening, out):  # type: ignore[no-untyped-def]  # fmt: skip
    """out = weights * C / (|C| + eps) ** whitening with C = mov * conj(ref) (mov replaced by
    ramp * conj(mov) for a half turn), on packed spectra, in float32 like numpy's complex64.

    The (Re, Im) pairs lie along the rows in the inner columns and down the two edge columns
    (their paired rows); the four remaining values are real.
    """
    h, w = out.shape
    zero = np.float32(0.0)
    for i in range(h):
        for j in range(1, w - 1, 2):
            out[i, j], out[i, j + 1] = _whitened_product(
                mov[i, j], mov[i, j + 1], ref[i, j], ref[i, j + 1], ramp[i, j], ramp[i, j + 1],
                half_turn, whitening, weights[i, j],
            )  # fmt: skip
    for j in (0, w - 1):
        for i in range(1, h - 1, 2):
            out[i, j], out[i + 1, j] = _whitened_product(
                mov[i, j], mov[i + 1, j], ref[i, j], ref[i + 1, j], ramp[i, j], ramp[i + 1, j],
                half_turn, whitening, weights[i, j],
            )  # fmt: skip
        for i in (0, h - 1):
            out[i, j], _ = _whitened_product(
                mov[i, j], zero, ref[i, j], zero, ramp[i, j], zero, half_turn, whitening,
                weights[i, j],
            )  # fmt: skip


@numba.njit(nogil=True, cache=True, inline="always")
def _whitened_product(m_re, m_im, r_re, r_im, p_re, p_im, half_turn, whitening, weight):  # type: ignore[no-untyped-def]  # fmt: skip
    """weight * C / (|C| + eps) ** whitening, C = m conj(r) (m replaced by p conj(m) for a half
    turn), as (Re, Im) float32."""
    if half_turn:
        m_re, m_im = p_re * m_re + p_im * m_im, p_im * m_re - p_re * m_im
    c_re = m_re * r_re + m_im * r_im
    c_im = m_im * r_re - m_re * r_im
    scale = weight
    if whitening > 0.0:
        magnitude = np.float32(math.sqrt(c_re * c_re + c_im * c_im)) + np.float32(SPECTRUM_EPS)
        if whitening != 1.0:
            magnitude = np.float32(magnitude**whitening)
        scale = scale / magnitude
    return c_re * scale, c_im * scale


def locate_peak(
    surface: FloatImage,
    smoothing_px: float,
    center_px: tuple[float, float] | None = None,
    radius_px: float | None = None,
) -> Peak:
    """Find the peak of a (periodic) correlation surface, to sub-pixel precision.

    Args:
        surface: (H, W) correlation surface; index (i, j) stands for the shift (i, j) mod (H, W).
        smoothing_px: the peak's Gaussian width [pixels] (sets the noise exclusion zone).
        center_px, radius_px: restrict the search to shifts within `radius_px` (Chebyshev) of
            `center_px` (rows, cols); None searches everywhere.

    The integer peak is refined by a quadratic fit of the log surface on its 3 x 3
    neighbourhood; the noise is the standard deviation of the surface outside a band of rows
    around the peak (both compiled: `_fit_log_quadratic`, `_std_outside_rows`).
    """
    h, w = surface.shape
    if center_px is None or radius_px is None:
        i0, j0 = divmod(int(np.argmax(surface)), w)
    else:
        i0, j0 = _window_argmax(
            surface, int(round(center_px[0])), int(round(center_px[1])), int(np.ceil(radius_px))
        )
    height = float(surface[i0, j0])
    fit = _fit_log_quadratic(surface, i0, j0, max(height, TINY) * LOG_FLOOR_FRACTION)
    curvature = np.array([[fit[2], fit[3]], [fit[3], fit[4]]])
    exclude = int(np.ceil(PEAK_EXCLUSION_SIGMAS * smoothing_px)) + 1
    noise = float(_std_outside_rows(surface, i0, exclude))
    quality = height / noise if noise > 0 else 0.0  # a flat surface carries no information
    shift = np.array([(i0 + fit[0] + h / 2.0) % h - h / 2.0, (j0 + fit[1] + w / 2.0) % w - w / 2.0])
    return Peak(shift_px=shift, height=height, quality=quality, curvature=curvature, noise=noise)


@numba.njit(nogil=True, cache=True)
def _window_argmax(surface, ci, cj, r):  # type: ignore[no-untyped-def]  # fmt: skip
    """(row, col) of the largest value within Chebyshev distance r of (ci, cj), periodic;
    the first in row-major window order on ties (as np.argmax of the window)."""
    h, w = surface.shape
    best_i = ci % h
    best_j = cj % w
    best = surface[best_i, best_j]
    first = True
    for a in range(-r, r + 1):
        i = (ci + a) % h
        for b in range(-r, r + 1):
            j = (cj + b) % w
            v = surface[i, j]
            if first or v > best:
                best, best_i, best_j, first = v, i, j, False
    return best_i, best_j


@numba.njit(nogil=True, cache=True)
def _fit_log_quadratic(surface, i0, j0, floor):  # type: ignore[no-untyped-def]  # fmt: skip
    """(d_row, d_col, c_rr, c_rc, c_cc): the sub-pixel offset (clipped to +-1) and the
    curvature (negative Hessian) of a quadratic through the log of the 3 x 3 neighbourhood of
    (i0, j0) (values floored at `floor`); a zero offset when the curvature is not positive
    definite."""
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
def _std_outside_rows(surface, i0, exclude):  # type: ignore[no-untyped-def]  # fmt: skip
    """Standard deviation (float64) of the surface without the rows within `exclude` of row i0
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


@dataclass(frozen=True)
class Peak1D:
    """A located peak of a periodic 1-D correlation.

    Attributes:
        shift: sub-sample shift [samples], wrapped to [-n/2, n/2).
        height: value at the integer peak.
        quality: height over the standard deviation away from the peak.
        curvature: negative second derivative of the log curve at the peak [1/sample^2].
    """

    shift: float
    height: float
    quality: float
    curvature: float

    def variance(self) -> float:
        """Variance [sample^2] of `shift`: squared peak width over squared peak-to-noise."""
        width2 = 1.0 / self.curvature if self.curvature > MIN_CURVATURE else WIDE_PEAK_VARIANCE_PX2
        return width2 / max(self.quality, 1.0) ** 2


def correlate_1d(
    s_ref: PackedSpectrum, s_mov: PackedSpectrum, n: int, smoothing: float
) -> NDArray[np.float64]:
    """Summed phase correlation of row spectra (`odometry.packed.forward_rows`, (rows, n)).

    Each element of the cross-power spectrum is whitened, the rows are summed, the zero
    frequency is dropped (it carries no shift), and a Gaussian of `smoothing` samples shapes the
    peak. Returns the (n,) periodic correlation; it peaks at d when mov(t) = ref(t - d).
    The whitened sum is one compiled pass (`_summed_cross_power`, float32 products summed in
    float64).
    """
    summed_re = np.zeros(n // 2 + 1)
    summed_im = np.zeros(n // 2 + 1)
    _summed_cross_power(s_ref, s_mov, summed_re, summed_im)
    summed = (summed_re + 1j * summed_im) * _gaussian_lowpass_1d(n, float(smoothing))
    return np.fft.irfft(summed, n=n) / max(1, s_ref.shape[0])


@functools.lru_cache(maxsize=16)
def _gaussian_lowpass_1d(n: int, smoothing: float) -> NDArray[np.float64]:
    weights = np.exp(-2.0 * (np.pi * smoothing * np.fft.rfftfreq(n)) ** 2)
    weights.setflags(write=False)  # shared through the cache
    return weights


@numba.njit(nogil=True, cache=True)
def _summed_cross_power(s_ref, s_mov, out_re, out_im):  # type: ignore[no-untyped-def]  # fmt: skip
    """out[k] += sum over rows of C / (|C| + eps), C = mov * conj(ref) (float32 products), for
    the frequencies k >= 1 of packed row spectra (the zero frequency is left out)."""
    eps = np.float32(SPECTRUM_EPS)
    n = s_ref.shape[1]
    pairs = (n - 1) // 2
    for i in range(s_ref.shape[0]):
        for k in range(1, pairs + 1):
            m_re = s_mov[i, 2 * k - 1]
            m_im = s_mov[i, 2 * k]
            r_re = s_ref[i, 2 * k - 1]
            r_im = s_ref[i, 2 * k]
            c_re = m_re * r_re + m_im * r_im
            c_im = m_im * r_re - m_re * r_im
            inverse = np.float32(1.0) / (np.float32(math.sqrt(c_re * c_re + c_im * c_im)) + eps)
            out_re[k] += c_re * inverse
            out_im[k] += c_im * inverse
        if n % 2 == 0:  # the real Nyquist value
            c = s_mov[i, n - 1] * s_ref[i, n - 1]
            out_re[n // 2] += c / (np.float32(abs(c)) + eps)


def locate_peak_1d(curve: NDArray[np.float64], smoothing: float) -> Peak1D:
    """Sub-sample peak of a periodic curve by a parabola through the log of its 3 top samples."""
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
    noise = float(_std_outside_rows(curve.reshape(-1, 1), i0, exclude))
    shift = (i0 + offset + n / 2.0) % n - n / 2.0
    return Peak1D(
        shift=shift,
        height=height,
        quality=height / noise if noise > 0 else 0.0,
        curvature=-second,
    )
