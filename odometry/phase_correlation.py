"""2-D phase correlation with a smooth, sub-pixel-locatable peak and a peak quality measure.

Spectra are half spectra (`numpy.fft.rfft2` layout, (H, W // 2 + 1) complex64). The normalised
cross-power spectrum is multiplied by a Gaussian low-pass, which convolves the correlation surface
with a Gaussian of `smoothing_px`: the peak of a pure shift becomes a sampled Gaussian, and a
quadratic fit of the log surface on its 3 x 3 neighbourhood then locates it to a small fraction of
a pixel and gives its curvature.

Shift convention: `correlate(f_ref, f_mov)` peaks at d (rows, cols) when mov(p) = ref(p - d), i.e.
when the content of `mov` is that of `ref` moved by +d pixels.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

FloatImage = NDArray[np.float32]
HalfSpectrum = NDArray[np.complex64]
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
    eigvals = np.linalg.eigvalsh(matrix)
    if eigvals.min() <= MIN_CURVATURE:
        return np.eye(len(matrix)) * WIDE_PEAK_VARIANCE_PX2
    return np.asarray(np.linalg.inv(matrix), dtype=np.float64)


def forward(image: FloatImage) -> HalfSpectrum:
    """Half spectrum (H, W // 2 + 1) complex64 of a real float32 image (cv2's fast DFT)."""
    full = cv2.dft(np.ascontiguousarray(image, dtype=np.float32), flags=cv2.DFT_COMPLEX_OUTPUT)
    return full.view(np.complex64)[:, : image.shape[1] // 2 + 1, 0]


@functools.lru_cache(maxsize=16)
def gaussian_lowpass(shape: tuple[int, int], sigma_px: float) -> NDArray[np.float32]:
    """Half-spectrum weights that convolve a surface of `shape` with a Gaussian of `sigma_px`."""
    fy = np.fft.fftfreq(shape[0])[:, None]
    fx = np.fft.rfftfreq(shape[1])[None, :]
    weights = np.exp(-2.0 * (np.pi * sigma_px) ** 2 * (fy * fy + fx * fx)).astype(np.float32)
    weights.setflags(write=False)  # shared through the cache
    return weights


def correlate(
    f_ref: HalfSpectrum,
    f_mov: HalfSpectrum,
    shape: tuple[int, int],
    smoothing_px: float,
    whitening: float = 1.0,
) -> FloatImage:
    """Phase-correlation surface (H, W) float32 of two half spectra of images of `shape`.

    Args:
        f_ref, f_mov: half spectra of the reference and moved images.
        shape: (H, W) of the images.
        smoothing_px: Gaussian width of the peak [pixels].
        whitening: exponent of the magnitude normalisation (1: phase only; 0: plain
            cross-correlation).
    """
    cross = f_mov * np.conj(f_ref)
    if whitening > 0:
        magnitude = np.abs(cross) + np.float32(SPECTRUM_EPS)
        cross /= magnitude if whitening == 1.0 else magnitude**whitening
    cross *= gaussian_lowpass(shape, float(smoothing_px))
    return np.fft.irfft2(cross, s=shape).astype(np.float32, copy=False)


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
    """
    h, w = surface.shape
    if center_px is None or radius_px is None:
        flat = int(np.argmax(surface))
        i0, j0 = divmod(flat, w)
    else:
        r = int(np.ceil(radius_px))
        rows = (int(round(center_px[0])) + np.arange(-r, r + 1)) % h
        cols = (int(round(center_px[1])) + np.arange(-r, r + 1)) % w
        window = surface[np.ix_(rows, cols)]
        a, b = divmod(int(np.argmax(window)), window.shape[1])
        i0, j0 = int(rows[a]), int(cols[b])
    height = float(surface[i0, j0])

    patch = surface[np.ix_((i0 + np.arange(-1, 2)) % h, (j0 + np.arange(-1, 2)) % w)]
    logp = np.log(np.maximum(patch.astype(np.float64), max(height, TINY) * LOG_FLOOR_FRACTION))
    grad = np.array([logp[2, 1] - logp[0, 1], logp[1, 2] - logp[1, 0]]) * 0.5
    hyy = logp[2, 1] - 2.0 * logp[1, 1] + logp[0, 1]
    hxx = logp[1, 2] - 2.0 * logp[1, 1] + logp[1, 0]
    hxy = 0.25 * (logp[2, 2] - logp[2, 0] - logp[0, 2] + logp[0, 0])
    hessian = np.array([[hyy, hxy], [hxy, hxx]])
    curvature = -hessian
    if np.linalg.eigvalsh(curvature).min() > MIN_CURVATURE:
        offset = np.linalg.solve(hessian, -grad)
        offset = np.clip(offset, -1.0, 1.0)
    else:  # degenerate neighbourhood: keep the integer peak
        offset = np.zeros(2)

    # Noise: spread of the surface away from the peak (a band of rows/cols is cheap to skip).
    exclude = int(np.ceil(PEAK_EXCLUSION_SIGMAS * smoothing_px)) + 1
    keep_rows = np.ones(h, dtype=bool)
    keep_rows[(i0 + np.arange(-exclude, exclude + 1)) % h] = False
    noise = float(np.std(surface[keep_rows]))
    quality = height / noise if noise > 0 else 0.0  # a flat surface carries no information

    shift = np.array([i0, j0], dtype=np.float64) + offset
    shift = (shift + np.array([h, w]) / 2.0) % np.array([h, w]) - np.array([h, w]) / 2.0
    return Peak(shift_px=shift, height=height, quality=quality, curvature=curvature, noise=noise)


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
    s_ref: NDArray[np.complex64], s_mov: NDArray[np.complex64], n: int, smoothing: float
) -> NDArray[np.float64]:
    """Summed phase correlation along the last axis of half spectra (..., n // 2 + 1).

    Each element of the cross-power spectrum is whitened, the rows are summed, the zero
    frequency is dropped (it carries no shift), and a Gaussian of `smoothing` samples shapes the
    peak. Returns the (n,) periodic correlation; it peaks at d when mov(t) = ref(t - d).
    """
    cross = s_mov * np.conj(s_ref)
    cross /= np.abs(cross) + np.float32(SPECTRUM_EPS)
    summed = cross.reshape(-1, cross.shape[-1]).sum(axis=0)
    summed[0] = 0.0
    freq = np.fft.rfftfreq(n)
    summed *= np.exp(-2.0 * (np.pi * smoothing * freq) ** 2)
    return np.fft.irfft(summed, n=n) / max(1, cross.size // cross.shape[-1])


def locate_peak_1d(curve: NDArray[np.float64], smoothing: float) -> Peak1D:
    """Sub-sample peak of a periodic curve by a parabola through the log of its 3 top samples."""
    n = len(curve)
    i0 = int(np.argmax(curve))
    height = float(curve[i0])
    trio = curve[(i0 + np.arange(-1, 2)) % n].astype(np.float64)
    logt = np.log(np.maximum(trio, max(height, TINY) * LOG_FLOOR_FRACTION))
    second = logt[0] - 2.0 * logt[1] + logt[2]
    offset = 0.0
    if second < -MIN_CURVATURE:
        offset = float(np.clip(0.5 * (logt[0] - logt[2]) / second, -1.0, 1.0))
    exclude = int(np.ceil(PEAK_EXCLUSION_SIGMAS * smoothing)) + 1
    keep = np.ones(n, dtype=bool)
    keep[(i0 + np.arange(-exclude, exclude + 1)) % n] = False
    noise = float(np.std(curve[keep]))
    shift = (i0 + offset + n / 2.0) % n - n / 2.0
    return Peak1D(
        shift=shift,
        height=height,
        quality=height / noise if noise > 0 else 0.0,
        curvature=-second,
    )
