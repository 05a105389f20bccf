"""Rotation between two scans by Fourier-Mellin (modulo pi: a shift along the angle of the
polar-resampled magnitude spectra), then refined on a polar grid about the reference sensor once
the translation is known (Fourier-Mellin locks toward zero for small turns; docs/method.md)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numba
import numpy as np
from numpy.typing import NDArray

from odometry.phase_correlation import (
    LOG_FLOOR_FRACTION,
    MIN_CURVATURE,
    PEAK_EXCLUSION_SIGMAS,
    SPECTRUM_EPS,
    TINY,
    WIDE_PEAK_VARIANCE_PX2,
    PackedSpectrum,
    forward_rows,
    std_outside_rows,
)


@dataclass(frozen=True)
class RotationSettings:
    """Fourier-Mellin rotation settings (internal constants: `ROTATION`).

    Attributes:
        n_angles, n_radii: samples of the spectrum's angle over [0, pi) and of its radius.
        min_frequency, max_frequency: spectral radii used, as fractions of Nyquist.
        smoothing_bins: Gaussian width [angle bins] of the correlation peak.
        refine: refine the rotation on the polar grid; refine_n_angles: its samples of a turn.
        refine_min_range_m, refine_max_range_m, refine_range_step_m: its radial samples [m].
        refine_smoothing_bins: Gaussian width [angle bins] of the refinement peak.
        refine_passes: at most this many refinements, each after the first preceded by a coarse
            translation at the refined yaw.
        refine_repeat_min_deg: a refinement is repeated only while the last one turned more.
    """

    n_angles: int = 720
    n_radii: int = 96
    min_frequency: float = 0.05
    max_frequency: float = 0.9
    smoothing_bins: float = 1.0
    refine: bool = True
    refine_n_angles: int = 720
    refine_min_range_m: float = 5.0
    refine_max_range_m: float = 80.0
    refine_range_step_m: float = 0.5
    refine_smoothing_bins: float = 2.0
    refine_passes: int = 2
    refine_repeat_min_deg: float = 0.05


ROTATION = RotationSettings()


@dataclass(frozen=True)
class RotationEstimate:
    """Rotation of a scan relative to a reference: `angle_rad` in [-pi/2, pi/2) from
    Fourier-Mellin (or + pi), in [-pi, pi) from a refinement; its standard deviation [rad] and
    peak-to-noise ratio from the angular correlation peak."""

    angle_rad: float
    sigma_rad: float
    quality: float


@functools.lru_cache(maxsize=8)
def _sampler(
    size_px: int, cfg: RotationSettings
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
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
    """out (h, w // 2 + 1) = log(1 + |half spectrum|) of a packed spectrum (h, w), rows
    fftshifted, float32."""
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

    x_m: NDArray[np.float32]
    y_m: NDArray[np.float32]
    range_m: NDArray[np.float32]
    bearing_rad: NDArray[np.float32]

    def shifted(
        self, dx_m: float, dy_m: float
    ) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]]:
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
    ref_spectrum: PackedSpectrum, mov: NDArray[np.float32], cfg: RotationSettings
) -> RotationEstimate:
    """The residual rotation [rad] to add to the estimate's yaw, of `mov` (the moved scan on
    the grid through the current estimate) against the reference's `forward_rows` spectra."""
    n = mov.shape[1]
    curve = correlate_1d(ref_spectrum, forward_rows(mov), n, cfg.refine_smoothing_bins)
    return _rotation_of_peak(curve, cfg.refine_smoothing_bins, 2.0 * np.pi / n)


def _rotation_of_peak(
    curve: NDArray[np.float64], smoothing: float, step_rad: float
) -> RotationEstimate:
    """The rotation at the peak of an angular correlation (samples `step_rad` apart, peak width
    `smoothing` samples), by a parabola through the log of its 3 top samples; minus the shift
    (a signature's angle runs against a CCW turn; on a `PolarGrid` content d samples further
    CCW was rendered turned too far by d)."""
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
    return RotationEstimate(
        angle_rad=float(-shift * step_rad),
        sigma_rad=float(np.sqrt(width2 / max(quality, 1.0) ** 2) * step_rad),
        quality=float(quality),
    )


def correlate_1d(
    s_ref: PackedSpectrum, s_mov: PackedSpectrum, n: int, smoothing: float
) -> NDArray[np.float64]:
    """Summed phase correlation (n,) of row spectra (rows, n), peaking at d when
    mov(t) = ref(t - d): whitened, summed over rows, without the zero frequency, shaped by a
    Gaussian of `smoothing` samples."""
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
    """out[k] += sum over rows of C / (|C| + eps), C = mov * conj(ref), frequencies k >= 1."""
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
