"""Rotation between two scans by Fourier-Mellin, then a refinement on a polar grid.

The magnitude of an image's spectrum ignores translation and turns with the image. Resampled on a
polar grid (angle x radius), a rotation becomes a shift along the angle axis, found by phase
correlation along that axis (summed over radii). A real image's magnitude spectrum is symmetric
under a half turn, so the angle axis spans [0, pi) and the rotation is known modulo pi: the caller
tests both hypotheses.

Fourier-Mellin alone locks toward zero for small rotations (the pixel grid and the window are
fixed in both images), so `refine_rotation_against` follows once the translation is known: both
scans are sampled on one polar grid centred on the reference sensor (`PolarGrid`), the moved one
through the current motion estimate; the remaining rotation is a pure shift along the angle axis.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numba
import numpy as np
from numpy.typing import NDArray

from odometry.packed import PackedSpectrum, forward_rows
from odometry.phase_correlation import (
    LOG_FLOOR_FRACTION,
    MIN_CURVATURE,
    PEAK_EXCLUSION_SIGMAS,
    SPECTRUM_EPS,
    TINY,
    WIDE_PEAK_VARIANCE_PX2,
    std_outside_rows,
)

Signature = PackedSpectrum
"""Packed row spectra ((n_radii, n_angles) float32, `odometry.packed.forward_rows`)."""


@dataclass(frozen=True)
class RotationSettings:
    """Fourier-Mellin rotation settings (internal: `ROTATION`).

    Attributes:
        n_angles: samples of the spectrum's angle over [0, pi) (resolution pi / n_angles).
        n_radii: samples of the spectrum's radius.
        min_frequency, max_frequency: spectral radii used, as fractions of Nyquist (the lowest
            frequencies are dominated by the window).
        smoothing_bins: Gaussian width [angle bins] of the correlation peak.
        refine: after the coarse translation, refine the rotation on the polar grid about the
            reference sensor (`refine_rotation_against`).
        refine_n_angles: angular samples of that grid over a full turn.
        refine_min_range_m, refine_max_range_m, refine_range_step_m: its radial samples [m].
        refine_smoothing_bins: Gaussian width [angle bins] of the refinement peak.
        refine_passes: at most this many refinements in a row, each after the first preceded by
            a coarse translation at the refined yaw: the first translation is made at the
            Fourier-Mellin yaw, whose error would otherwise leak into the refined rotation in
            proportion to the rotation.
        refine_repeat_min_deg: a refinement is repeated only while its last correction was
            larger than this [deg].
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
"""The rotation settings the odometry and loop verification use (not a user setting: they
follow the image levels, not a sensor or a vehicle)."""


@dataclass(frozen=True)
class RotationEstimate:
    """Rotation of a scan relative to a reference.

    Attributes:
        angle_rad: rotation [rad]: in [-pi/2, pi/2) from Fourier-Mellin (the other hypothesis
            is angle_rad + pi), in [-pi, pi) from a refinement.
        sigma_rad: standard deviation from the correlation peak [rad].
        quality: peak-to-noise ratio of the angular correlation peak.
    """

    angle_rad: float
    sigma_rad: float
    quality: float


@functools.lru_cache(maxsize=8)
def _sampler(
    size_px: int, cfg: RotationSettings
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """cv2.remap maps (cols, rows) from (radius, angle) to the row-centred half spectrum of a
    square image."""
    nyquist = size_px / 2.0
    radii = np.linspace(cfg.min_frequency * nyquist, cfg.max_frequency * nyquist, cfg.n_radii)
    angles = np.arange(cfg.n_angles) * (np.pi / cfg.n_angles)
    k_row = radii[:, None] * np.cos(angles)[None, :]
    k_col = radii[:, None] * np.sin(angles)[None, :]
    return k_col.astype(np.float32), (k_row + nyquist).astype(np.float32)


def signature(spectrum: PackedSpectrum, cfg: RotationSettings) -> Signature:
    """Rotation signature of an image from its packed spectrum (size_px, size_px): the packed
    angular spectra (n_radii, n_angles) float32 of its polar-resampled log magnitude spectrum."""
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
    """out (h, w // 2 + 1) = log(1 + |half spectrum|) of a packed spectrum (h, w), the rows
    shifted by half (numpy's fftshift along axis 0), float32."""
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


def estimate_rotation(ref: Signature, mov: Signature, cfg: RotationSettings) -> RotationEstimate:
    """Rotation of the `mov` image relative to `ref` (modulo pi) from their signatures."""
    curve = correlate_1d(ref, mov, cfg.n_angles, cfg.smoothing_bins)
    return _rotation_of_peak(curve, cfg.smoothing_bins, np.pi / cfg.n_angles)


@dataclass(frozen=True)
class PolarGrid:
    """Points on a polar grid about a sensor: row k at range min_range_m + (k + 0.5) *
    range_step_m, column j at bearing j * 2 pi / n_angles (CCW from +x). Arrays
    (n_ranges, n_angles) float32 [m, rad] (the angle along the rows, where the row DFT of
    `angular_spectrum` needs it)."""

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


def angular_spectrum(image: NDArray[np.float32]) -> PackedSpectrum:
    """(n_ranges, n_angles) float32 packed spectra (`forward_rows`) along the angle axis of a
    scan sampled on a `PolarGrid` ((n_ranges, n_angles) float32), one per range."""
    return forward_rows(image)


def refine_rotation_against(
    ref_spectrum: PackedSpectrum, mov: NDArray[np.float32], cfg: RotationSettings
) -> RotationEstimate:
    """Residual rotation of `mov` relative to the reference, both sampled on the same
    `PolarGrid`.

    Args:
        ref_spectrum: `angular_spectrum` of the reference scan on the grid.
        mov: (n_ranges, n_angles) the moved scan on the grid, rendered through the current
            motion estimate (so only a residual rotation remains).
        cfg: rotation settings.

    Returns:
        The residual rotation in [-pi, pi) [rad] to add to the estimate's yaw.
    """
    n = mov.shape[1]
    curve = correlate_1d(ref_spectrum, angular_spectrum(mov), n, cfg.refine_smoothing_bins)
    return _rotation_of_peak(curve, cfg.refine_smoothing_bins, 2.0 * np.pi / n)


def _rotation_of_peak(
    curve: NDArray[np.float64], smoothing: float, step_rad: float
) -> RotationEstimate:
    """The rotation at the peak of an angular correlation (`correlate_1d`, samples `step_rad`
    apart, peak width `smoothing` samples), located by a parabola through the log of its 3 top
    samples.

    The angle is minus the correlation's shift: in a signature the spectrum's angle runs from the
    row- toward the column-frequency axis, against a CCW turn in the image convention; on a
    `PolarGrid` content d samples further CCW was rendered turned too far by d.
    """
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
    """Summed phase correlation (n,) of row spectra (`forward_rows`, (rows, n)); it peaks at d
    when mov(t) = ref(t - d).

    Each element of the cross-power spectrum is whitened, the rows are summed, the zero
    frequency is dropped (it carries no shift), and a Gaussian of `smoothing` samples shapes the
    peak.
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
