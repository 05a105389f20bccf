"""Relative pose of two scans from their sinogram spectra (RING-style), for loop verification.

Notation: the query scan q and the map (candidate) scan m; the result T_q_m = (dx, dy, dyaw) is
the map scan's pose in the query frame (x forward, y left, yaw CCW), so a point p_m of the map
scan lies at R(dyaw) p_m + (dx, dy) in the query frame, and the sinograms satisfy

    S_q(theta, l) = S_m(theta - dyaw, l - b(theta)),   b(theta) = dx cos theta + dy sin theta.

Steps (all on spectra S^(theta, k) sampled from one 2-D FFT per image, raplace.descriptor):
1. Rotation modulo pi: circular correlation along theta of the magnitudes |S^| (which ignore the
   translation); the best `rotation_peaks` peaks, sub-bin. Each peak a gives two hypotheses, a
   and a - pi (|S^| repeats every pi). The map spectrum at theta - a is sampled directly from its
   2-D FFT (no interpolation along theta); the pi hypothesis is its complex conjugate.
2. Translation per hypothesis: for each query angle theta_i, the cross-correlation along l of the
   query row and the de-rotated map row (partially whitened cross-power spectrum) peaks at
   b_i; [cos theta_i, sin theta_i] [dx, dy]^T = b_i is solved robustly (orthogonal-pair
   hypotheses scored by truncated squared residuals, then least squares on the inliers).
3. The hypothesis with the smallest truncated residual wins; optionally the rotation is refined by
   maximising the aligned correlation and the translation re-solved.
4. Quality: the normalised correlation of the two band-limited images after alignment,
   computed from the spectra (Parseval; DC excluded), in [-1, 1].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft
from numpy.typing import NDArray

from raplace import RaPlaceError
from raplace.config import PoseConfig
from raplace.descriptor import ImageSpectrum, image_spectrum, sample_spectrum
from raplace.pose_kernels import (
    aligned_correlation_kernel,
    fit_translation_kernel,
    radial_sampling,
    row_peak_positions,
    whitened_cross_power,
)
from raplace.preprocess import CartesianImager
from raplace.scoring import parabolic_vertex
from raplace.se2 import wrap_angle

WHITENING_EPS = 1e-12
"""Guard of the cross-power normalisation |P|^-beta."""
REFINE_STEP_BINS = 0.25
"""Rotation probe offset of the refinement, in theta bins (pi / n_theta)."""
LEAST_SQUARES_ITERATIONS = 3
"""Inlier re-selection rounds after the best orthogonal-pair hypothesis."""


@dataclass(frozen=True)
class RelativePose:
    """Pose of the map (candidate) scan in the query scan's frame, with its support.

    Attributes:
        dx_m, dy_m: translation [m] (x forward, y left of the query scan).
        dyaw_rad: rotation, CCW, in (-pi, pi] [rad].
        quality: normalised correlation of the aligned band-limited images, in [-1, 1]
            (about 1 for the same place, near 0 for unrelated scans).
        residual_m: truncated RMS of the per-angle shift residuals [m]: residuals are capped at
            `inlier_threshold_m`, so it lies in [0, inlier_threshold_m].
        inlier_fraction: fraction of angles whose shift agrees with (dx, dy) within the threshold.
        alternative_residual_m: the truncated residual of the best rejected hypothesis (the pi
            ambiguity's other side, or another rotation peak) [m]; a clear win has
            residual_m well below it.
    """

    dx_m: float
    dy_m: float
    dyaw_rad: float
    quality: float
    residual_m: float
    inlier_fraction: float
    alternative_residual_m: float

    def as_array(self) -> NDArray[np.float64]:
        """(3,) [dx_m, dy_m, dyaw_rad]."""
        return np.array([self.dx_m, self.dy_m, self.dyaw_rad])


@dataclass(frozen=True)
class PoseSpectrum:
    """An image's 2-D spectrum prepared for `relative_pose_of`: made once per image, it serves
    every pair the image takes part in (a query verified against several candidates).

    Attributes:
        fft: the padded 2-D DFT (`raplace.descriptor.image_spectrum`).
        rows: (n_theta, n_freq) complex64 S^(theta_i, k_j) at theta_i = i pi / n_theta and
            k_j = j * fft.freq_step_cpm, j = 0..size/2.
    """

    fft: ImageSpectrum
    rows: NDArray[np.complex64]

    @property
    def nbytes(self) -> int:
        """Bytes the arrays take (for byte-budget caches)."""
        return int(self.fft.grid.nbytes + self.rows.nbytes)


@dataclass(frozen=True)
class _Spectra:
    """Query rows and the sampling context shared by every hypothesis."""

    query: NDArray[np.complex64]  # (n_theta, n_freq) S^_q(theta_i, k_j)
    map_fft: ImageSpectrum
    thetas: NDArray[np.float64]  # (n_theta,) [rad], in [0, pi)
    freqs: NDArray[np.float64]  # (n_freq,) [cycles/m], k_j = j * step, j = 0..size/2
    period_m: float  # shifts along l are found modulo this [m]


@dataclass(frozen=True)
class _Hypothesis:
    yaw: float
    xy: NDArray[np.float64]
    residual: float
    inliers: NDArray[np.bool_]
    rows: NDArray[np.complex64]  # de-rotated map rows at this yaw


def rotation_candidates(
    query_rows: NDArray[np.complex64],
    map_rows: NDArray[np.complex64],
    freqs: NDArray[np.float64],
    n_peaks: int,
) -> NDArray[np.float64]:
    """Rotations a modulo pi [rad] (best first) from magnitude correlation along theta.

    Args:
        query_rows, map_rows: (n_theta, n_freq) spectra at theta_i = i pi / n_theta.
        freqs: (n_freq,) [cycles/m]; magnitudes are weighted by k (flattens the 1/k fall-off).
        n_peaks: local maxima kept.
    """
    n_theta = query_rows.shape[0]
    weight = freqs[None, :]
    q = np.abs(query_rows) * weight
    m = np.abs(map_rows) * weight
    q -= q.mean(axis=0, keepdims=True)
    m -= m.mean(axis=0, keepdims=True)
    # C(s) = sum_theta q(theta) m(theta - s) peaks at s = a.
    spectrum = np.sum(np.fft.rfft(q, axis=0) * np.conj(np.fft.rfft(m, axis=0)), axis=1)
    corr = np.fft.irfft(spectrum, n=n_theta)
    is_peak = (corr >= np.roll(corr, 1)) & (corr >= np.roll(corr, -1))
    peaks = np.flatnonzero(is_peak)
    peaks = peaks[np.argsort(corr[peaks])[::-1][:n_peaks]]
    _, offset = parabolic_vertex(
        corr[(peaks - 1) % n_theta], corr[peaks], corr[(peaks + 1) % n_theta]
    )
    return (peaks + offset) * (np.pi / n_theta)


def per_angle_shifts(
    query_rows: NDArray[np.complex64],
    map_rows: NDArray[np.complex64],
    period_m: float,
    whitening: float,
    upsample: int,
) -> NDArray[np.float64]:
    """Shift b_i [m] along l of each query row relative to the map row (same angle).

    Args:
        query_rows, map_rows: (n_theta, n_freq) spectra at k_j = j / period_m, j = 0..n_freq - 1
            (n_freq - 1 = the grid's Nyquist index).
        period_m: shifts are found modulo this; returned in [-period_m / 2, period_m / 2).
        whitening: exponent beta of |P|^-beta.
        upsample: correlation samples per grid step along l.
    """
    # DC (column 0) zeroed: no shift information.
    cross = whitened_cross_power(
        np.asarray(query_rows, dtype=np.complex64),
        np.asarray(map_rows, dtype=np.complex64),
        float(whitening),
        WHITENING_EPS,
    )
    n_l = 2 * (query_rows.shape[1] - 1) * upsample
    corr = scipy.fft.irfft(cross, n=n_l, axis=1, workers=1)  # peaks at l = b_i
    position = row_peak_positions(corr)
    shifts = position * (period_m / n_l)
    return np.mod(shifts + 0.5 * period_m, period_m) - 0.5 * period_m


def fit_translation(
    thetas: NDArray[np.float64], shifts: NDArray[np.float64], threshold_m: float
) -> tuple[NDArray[np.float64], float, NDArray[np.bool_]]:
    """Robust least squares of b_i = x cos theta_i + y sin theta_i.

    Candidate solutions come from every pair of orthogonal angles (theta_i, theta_i + pi/2);
    the one with the least truncated squared residual is refined by least squares on its inliers.

    Args:
        thetas: (n,) angles [rad] in [0, pi), n even and uniformly spaced.
        shifts: (n,) b_i [m].
        threshold_m: inlier bound on |residual| [m].

    Returns:
        ((x, y) [m], truncated RMS residual [m], inlier mask (n,)).
    """
    thetas = np.asarray(thetas, dtype=np.float64)
    # Orthogonal pair (theta, theta + pi/2): b1 = x c + y s, b2 = -x s + y c (compiled loops).
    x, y, truncated, inliers = fit_translation_kernel(
        np.cos(thetas),
        np.sin(thetas),
        np.asarray(shifts, dtype=np.float64),
        float(threshold_m),
        LEAST_SQUARES_ITERATIONS,
    )
    return np.array([x, y]), float(truncated), inliers


def aligned_correlation(
    query_rows: NDArray[np.complex64],
    map_rows: NDArray[np.complex64],
    thetas: NDArray[np.float64],
    freqs: NDArray[np.float64],
    xy: NDArray[np.float64],
) -> float:
    """Normalised correlation of the query image and the map image moved by (xy, yaw).

    `map_rows` are already de-rotated (sampled at theta - yaw); `freqs` are k_j = j * step
    (`pose_freqs`). Polar Parseval: each sample is weighted by k; the DC column is excluded
    (mean removal). Returns a value in [-1, 1].
    """
    # S^_q = S^_m(theta - yaw) exp(-2 pi i k b): the kernel undoes the translation phase.
    shift = xy[0] * np.cos(thetas) + xy[1] * np.sin(thetas)
    return float(
        aligned_correlation_kernel(
            np.asarray(query_rows, dtype=np.complex64),
            np.asarray(map_rows, dtype=np.complex64),
            np.asarray(shift, dtype=np.float64),
            float(freqs[1] - freqs[0]),
        )
    )


def _solve(spectra: _Spectra, yaw: float, rows: NDArray, cfg: PoseConfig) -> _Hypothesis:
    shifts = per_angle_shifts(
        spectra.query, rows, spectra.period_m, cfg.whitening, cfg.shift_upsample
    )
    xy, residual, inliers = fit_translation(spectra.thetas, shifts, cfg.inlier_threshold_m)
    return _Hypothesis(yaw=yaw, xy=xy, residual=residual, inliers=inliers, rows=rows)


def radial_rows(
    spectrum: ImageSpectrum, thetas_rad: NDArray[np.float64], n_freq: int
) -> NDArray[np.complex64]:
    """`raplace.descriptor.radial_spectrum` at k_j = j * `spectrum.freq_step_cpm`, j < n_freq
    (`pose_freqs`): (n_theta, n_freq) complex64, the sampling maps and the half-pixel phase
    made in one compiled pass."""
    rows, cols, phase = radial_sampling(
        np.asarray(thetas_rad, dtype=np.float64),
        spectrum.freq_step_cpm,
        n_freq,
        spectrum.size,
        spectrum.cell_m,
    )
    values = sample_spectrum(spectrum, rows, cols)
    values *= phase
    return values


def _map_rows(spectra: _Spectra, yaw: float) -> NDArray[np.complex64]:
    return radial_rows(spectra.map_fft, spectra.thetas - yaw, len(spectra.freqs))


def _refine(spectra: _Spectra, best: _Hypothesis, cfg: PoseConfig) -> _Hypothesis:
    """One rotation refinement: parabola through the aligned correlation at yaw +- step."""
    step = REFINE_STEP_BINS * np.pi / cfg.n_theta
    values = [
        aligned_correlation(
            spectra.query,
            _map_rows(spectra, best.yaw + offset),
            spectra.thetas,
            spectra.freqs,
            best.xy,
        )
        for offset in (-step, step)
    ]
    centre = aligned_correlation(spectra.query, best.rows, spectra.thetas, spectra.freqs, best.xy)
    _, offset = parabolic_vertex(values[0], centre, values[1], limit=1.0)
    yaw = best.yaw + float(offset) * step
    refined = _solve(spectra, yaw, _map_rows(spectra, yaw), cfg)
    return refined if refined.residual <= best.residual else best


def pose_angles(n_theta: int) -> NDArray[np.float64]:
    """(n_theta,) angles theta_i = i pi / n_theta [rad] of the pose estimate's radial lines."""
    return np.arange(n_theta, dtype=np.float64) * (np.pi / n_theta)


def pose_freqs(fft: ImageSpectrum) -> NDArray[np.float64]:
    """(size / 2 + 1,) frequencies k_j = j * freq_step [cycles/m] of the radial lines."""
    return np.arange(fft.size // 2 + 1, dtype=np.float64) * fft.freq_step_cpm


def pose_spectrum(cart: NDArray, cell_m: float, cfg: PoseConfig) -> PoseSpectrum:
    """The spectrum of one Cartesian image for `relative_pose_of`.

    Args:
        cart: (n, n) image (raplace.warp convention), e.g. from `PoseEstimator.image`.
        cell_m: pixel size [m].
        cfg: pose settings (n_theta must be even).
    """
    if cfg.n_theta < 4 or cfg.n_theta % 2:
        raise RaPlaceError(f"pose n_theta must be even and >= 4, got {cfg.n_theta}")
    fft = image_spectrum(cart, cell_m, cfg.pad_factor)
    return PoseSpectrum(fft=fft, rows=radial_rows(fft, pose_angles(cfg.n_theta), fft.size // 2 + 1))


def relative_pose(
    query_cart: NDArray, map_cart: NDArray, cell_m: float, cfg: PoseConfig
) -> RelativePose:
    """Pose of the map scan in the query scan's frame from two Cartesian images.

    Args:
        query_cart, map_cart: (n, n) images of the same grid (raplace.warp convention), e.g.
            from `PoseEstimator.image`.
        cell_m: pixel size [m].
        cfg: pose settings (n_theta must be even).

    Returns:
        RelativePose (dx, dy, dyaw) = T_query_map with quality and residuals.
    """
    query_cart = np.asarray(query_cart)
    if query_cart.shape != np.shape(map_cart):
        raise RaPlaceError(f"image shapes differ: {query_cart.shape} vs {np.shape(map_cart)}")
    query = pose_spectrum(query_cart, cell_m, cfg)
    return relative_pose_of(query, pose_spectrum(map_cart, cell_m, cfg), cfg)


def relative_pose_of(query: PoseSpectrum, map_: PoseSpectrum, cfg: PoseConfig) -> RelativePose:
    """`relative_pose` from the two images' `pose_spectrum`s (made with the same `cfg`)."""
    if query.fft.grid.shape != map_.fft.grid.shape or query.fft.cell_m != map_.fft.cell_m:
        raise RaPlaceError(
            f"spectra differ: {query.fft.grid.shape} at {query.fft.cell_m} m vs "
            f"{map_.fft.grid.shape} at {map_.fft.cell_m} m"
        )
    if query.rows.shape[0] != cfg.n_theta or map_.rows.shape[0] != cfg.n_theta:
        raise RaPlaceError(f"spectra were not made with n_theta = {cfg.n_theta}")
    thetas = pose_angles(cfg.n_theta)
    freqs = pose_freqs(query.fft)
    spectra = _Spectra(
        query=query.rows,
        map_fft=map_.fft,
        thetas=thetas,
        freqs=freqs,
        period_m=1.0 / query.fft.freq_step_cpm,
    )
    hypotheses: list[_Hypothesis] = []
    for yaw in rotation_candidates(spectra.query, map_.rows, freqs, cfg.rotation_peaks):
        rows = _map_rows(spectra, float(yaw))
        hypotheses.append(_solve(spectra, float(yaw), rows, cfg))
        # S^(theta - yaw - pi, k) = conj S^(theta - yaw, k) for a real image.
        hypotheses.append(_solve(spectra, float(yaw) + np.pi, np.conj(rows), cfg))
    hypotheses.sort(key=lambda h: h.residual)
    best = hypotheses[0]
    alternative = hypotheses[1].residual if len(hypotheses) > 1 else float("nan")
    for _ in range(cfg.refine_iterations):
        best = _refine(spectra, best, cfg)
    quality = aligned_correlation(spectra.query, best.rows, thetas, freqs, best.xy)
    return RelativePose(
        dx_m=float(best.xy[0]),
        dy_m=float(best.xy[1]),
        dyaw_rad=float(wrap_angle(best.yaw)),
        quality=quality,
        residual_m=best.residual,
        inlier_fraction=float(best.inliers.mean()),
        alternative_residual_m=alternative,
    )


class PoseEstimator:
    """Relative pose between two polar scans; caches the Cartesian warping maps."""

    def __init__(self, cfg: PoseConfig) -> None:
        self.cfg = cfg
        self.imager = CartesianImager(cfg.preprocess, cfg.image)

    def image(
        self, polar: NDArray, azimuths_rad: NDArray[np.float64], range_resolution_m: float
    ) -> NDArray[np.float32]:
        """The pose-resolution Cartesian image of a scan (cache it to verify many candidates)."""
        return self.imager(polar, azimuths_rad, range_resolution_m)

    def spectrum(self, image: NDArray) -> PoseSpectrum:
        """The `pose_spectrum` of an image made by `image` (cache it to verify many pairs)."""
        return pose_spectrum(image, self.cfg.image.cell_m, self.cfg)

    def estimate(self, query_image: NDArray, map_image: NDArray) -> RelativePose:
        """T_query_map from two images made by `image`."""
        return relative_pose(query_image, map_image, self.cfg.image.cell_m, self.cfg)

    def estimate_spectra(self, query: PoseSpectrum, map_: PoseSpectrum) -> RelativePose:
        """T_query_map from two images' `spectrum`s (the same result as `estimate`)."""
        return relative_pose_of(query, map_, self.cfg)
