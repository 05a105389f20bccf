"""Rotation between two scans by Fourier-Mellin: the angle of their magnitude spectra.

The magnitude of an image's spectrum ignores translation and turns with the image. Resampled on a
polar grid (angle x radius), a rotation becomes a shift along the angle axis, found by phase
correlation along that axis (summed over radii). A real image's magnitude spectrum is symmetric
under a half turn, so the angle axis spans [0, pi) and the rotation is known modulo pi: the caller
tests both hypotheses (`odometry.registration` keeps the one with the stronger translation peak).

Fourier-Mellin alone locks toward zero for small rotations (the pixel grid and the window are
fixed in both images), so `refine_rotation` follows once the translation is known: both scans are
sampled on one polar grid centred on the reference sensor (`PolarGrid`), the moved one through the
current motion estimate; the remaining rotation is then a pure shift along the angle axis.
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
from odometry.phase_correlation import correlate_1d, locate_peak_1d

Signature = PackedSpectrum
"""Packed row spectra ((n_radii, n_angles) float32, `odometry.packed.forward_rows`)."""


@dataclass(frozen=True)
class RotationSettings:
    """Fourier-Mellin rotation settings (internal: `ROTATION`): polar resampling of the coarse
    image's magnitude spectrum and the refinement that follows.

    Attributes:
        n_angles: samples of the spectrum's angle over [0, pi) (resolution pi / n_angles).
        n_radii: samples of the spectrum's radius.
        min_frequency: lowest spectral radius used, as a fraction of Nyquist (skips the
            window-dominated low frequencies).
        max_frequency: highest spectral radius used, as a fraction of Nyquist.
        log_radius: sample the radius logarithmically (log-polar, PhaRaO) instead of linearly.
        smoothing_bins: Gaussian width [angle bins] of the correlation peak (low-pass on the
            cross-power spectrum), for a smooth peak and a sub-bin fit.
        refine: after the coarse translation, refine the rotation by angular correlation of
            both scans resampled on a polar grid about the reference sensor (translation
            removed): Fourier-Mellin alone is biased toward zero by the fixed pixel grid.
        refine_n_angles: angular samples of that polar grid over a full turn.
        refine_min_range_m, refine_max_range_m, refine_range_step_m: its radial samples [m].
        refine_smoothing_bins: Gaussian width [angle bins] of the refinement peak.
        refine_passes: at most this many refinements in a row; each after the first
            re-estimates the coarse translation at the refined yaw (near the previous one)
            first. The first coarse translation is made at the Fourier-Mellin yaw, which locks
            toward zero for rotations below about a degree; its error leaks into a single
            refinement as a rotation error proportional to the rotation (see
            `scripts/diagnose_rotation_bias.py`). 2 removes that error
            (`tests/test_odometry_rotation_bias.py`).
        refine_repeat_min_deg: the refinement is repeated only while its last correction was
            larger than this [deg] (the translation was made at a yaw off by that much).
    """

    n_angles: int = 720
    n_radii: int = 96
    min_frequency: float = 0.05
    max_frequency: float = 0.9
    log_radius: bool = False
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
    """Rotation of a scan relative to a reference, modulo pi.

    Attributes:
        angle_rad: rotation in [-pi/2, pi/2) [rad] (the other hypothesis is angle_rad + pi).
        sigma_rad: standard deviation from the correlation peak [rad].
        quality: peak-to-noise ratio of the angular correlation peak.
    """

    angle_rad: float
    sigma_rad: float
    quality: float


@dataclass(frozen=True)
class _PolarSampler:
    map_cols: NDArray[np.float32]
    map_rows: NDArray[np.float32]


@functools.lru_cache(maxsize=8)
def _sampler(size_px: int, cfg: RotationSettings) -> _PolarSampler:
    """cv2.remap maps from (radius, angle) to the row-centred half spectrum of a square image."""
    nyquist = size_px / 2.0
    lo, hi = cfg.min_frequency * nyquist, cfg.max_frequency * nyquist
    if cfg.log_radius:
        radii = np.geomspace(max(lo, 1.0), hi, cfg.n_radii)
    else:
        radii = np.linspace(lo, hi, cfg.n_radii)
    angles = np.arange(cfg.n_angles) * (np.pi / cfg.n_angles)
    k_row = radii[:, None] * np.cos(angles)[None, :]
    k_col = radii[:, None] * np.sin(angles)[None, :]
    return _PolarSampler(
        map_cols=k_col.astype(np.float32), map_rows=(k_row + nyquist).astype(np.float32)
    )


def signature(spectrum: PackedSpectrum, cfg: RotationSettings) -> Signature:
    """Rotation signature of an image from its packed spectrum (size_px, size_px).

    Returns (n_radii, n_angles) float32: the packed angular spectra (`forward_rows`) of the
    polar-resampled log magnitude spectrum.
    """
    size = spectrum.shape[0]
    centred = np.empty((size, size // 2 + 1), dtype=np.float32)
    _centred_log_magnitude(spectrum, centred)
    sampler = _sampler(size, cfg)
    polar = cv2.remap(
        centred,
        sampler.map_cols,
        sampler.map_rows,
        interpolation=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REPLICATE,
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
    peak = locate_peak_1d(curve, cfg.smoothing_bins)
    step = np.pi / cfg.n_angles
    # The spectrum's angle runs from the row- toward the column-frequency axis: the opposite
    # sense to a CCW turn in the image convention (+x up, +y left).
    return RotationEstimate(
        angle_rad=float(-peak.shift * step),
        sigma_rad=float(np.sqrt(peak.variance()) * step),
        quality=float(peak.quality),
    )


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

    @property
    def n_angles(self) -> int:
        return int(self.x_m.shape[1])

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


def refine_rotation(
    ref: NDArray[np.float32], mov: NDArray[np.float32], cfg: RotationSettings
) -> RotationEstimate:
    """Residual rotation of `mov` relative to `ref`, both sampled on the same `PolarGrid`.

    Args:
        ref: (n_ranges, n_angles) the reference scan on the grid.
        mov: (n_ranges, n_angles) the moved scan on the grid, rendered through the current
            motion estimate (so only a residual rotation remains).
        cfg: rotation settings.

    Returns:
        The residual rotation in [-pi, pi) [rad] to add to the estimate's yaw.
    """
    return refine_rotation_against(angular_spectrum(ref), mov, cfg)


def refine_rotation_against(
    ref_spectrum: PackedSpectrum, mov: NDArray[np.float32], cfg: RotationSettings
) -> RotationEstimate:
    """`refine_rotation` with the reference given by its `angular_spectrum` (kept by a
    reference scan that many scans are registered against)."""
    n = mov.shape[1]
    curve = correlate_1d(ref_spectrum, angular_spectrum(mov), n, cfg.refine_smoothing_bins)
    peak = locate_peak_1d(curve, cfg.refine_smoothing_bins)
    step = 2.0 * np.pi / n
    # mov(bearing) = ref(bearing - d): the moved content sits d columns further CCW, i.e. the
    # rendering turned it too far by d; the yaw needs -d.
    return RotationEstimate(
        angle_rad=float(-peak.shift * step),
        sigma_rad=float(np.sqrt(peak.variance()) * step),
        quality=float(peak.quality),
    )
