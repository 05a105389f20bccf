"""Settings of the raplace package: one frozen dataclass per stage, defaults in code.

`RaPlaceConfig` groups the sections; each stage receives only its own section
(`DescriptorExtractor(cfg.descriptor)`, `PlaceRecognizer(cfg.retrieval)`,
`PoseEstimator(cfg.pose)`, `ScanContextRecognizer(cfg.scancontext)`). Mappings are read onto these
defaults by the one strict reader, `raplace.config_io`.
"""

from __future__ import annotations

import typing
from dataclasses import dataclass, field
from typing import Literal

from raplace import checks

IntensityTransform = Literal["linear", "log1p", "square"]
MagnitudeTransform = Literal["linear", "sqrt", "log1p"]
MIN_POSE_N_THETA = 4
"""Fewest sinogram angles of the pose estimate (an even count: angles pair up across pi)."""
MAX_DISTANCE = 2.0
"""Largest RaPlace distance (1 - normalised cross-correlation): the bound of `loop_threshold`."""


@dataclass(frozen=True)
class PreprocessConfig:
    """Clean-up of a polar scan before it is warped to a Cartesian image.

    Applied after range bins are averaged down to the image cell size (which already reduces
    speckle), in this order: per-range-bin median removal, per-azimuth median removal,
    near-range mask, noise floor, intensity transform.

    Attributes:
        ring_noise_removal: subtract each range bin's median over azimuths (removes ring noise
            and the part of the saturated near range that does not depend on azimuth); negative
            values are clipped to 0.
        spoke_removal: then subtract each azimuth's median over range (removes the radial
            streaks of real Navtech scans, bright along whole azimuths: they stay with the
            sensor and pull translation estimates toward zero). Off by default here (the Scan
            Context baseline keeps the plain clean-up); on for the relative pose (`PoseConfig`)
            and for descriptors (`DescriptorConfig`), where it separates real scans a few metres
            apart from those of other places better (docs/decisions.md).
        min_range_m: bins closer than this are zeroed (saturated near range, the vehicle) [m].
        noise_floor: intensity subtracted after the median removal, clipped at 0 (uint8 units).
        intensity: "linear" keeps the (dB-like) uint8 scale, "log1p" compresses it, "square"
            emphasises strong returns.
    """

    ring_noise_removal: bool = True
    spoke_removal: bool = False
    min_range_m: float = 3.0
    noise_floor: float = 0.0
    intensity: IntensityTransform = "linear"

    def __post_init__(self) -> None:
        checks.non_negative("min_range_m", self.min_range_m)
        checks.non_negative("noise_floor", self.noise_floor)
        checks.one_of("intensity", self.intensity, typing.get_args(IntensityTransform))


@dataclass(frozen=True)
class ImageConfig:
    """The Cartesian image a polar scan is warped to (see raplace.warp for the convention).

    Attributes:
        cell_m: pixel size [m]; range bins are first averaged to about this size.
        max_range_m: radius of the disc of the scan kept [m]; everything farther is dropped so
            the image content is a disc (rotation does not move content into square corners).
        taper_fraction: the outer fraction of the disc radius is faded out with a cosine ramp
            (reduces the spectral leakage of the disc rim).
        subtract_mean: subtract the (taper-weighted) mean intensity of the disc before tapering,
            so that the disc itself (identical in every scan) does not dominate the spectrum.
    """

    cell_m: float = 1.0
    max_range_m: float = 80.0
    taper_fraction: float = 0.1
    subtract_mean: bool = True

    def __post_init__(self) -> None:
        checks.positive("cell_m", self.cell_m)
        checks.positive("max_range_m", self.max_range_m)
        checks.less("cell_m", self.cell_m, "max_range_m", self.max_range_m)
        checks.in_range("taper_fraction", self.taper_fraction, 0.0, 1.0)


@dataclass(frozen=True)
class DescriptorConfig:
    """The translation-invariant RaPlace descriptor |DFT_l S(theta, l)|.

    Attributes:
        preprocess: polar clean-up settings.
        image: Cartesian image settings (coarse cells are enough for place recognition).
        n_theta: descriptor rows, angles theta in [0, pi) with spacing pi / n_theta.
        theta_oversample: radial lines sampled per descriptor row; their magnitudes are averaged
            (anti-aliasing along theta for the higher frequencies).
        n_freq: descriptor columns, frequencies k_j = j * max_freq_cpm / n_freq, j = 1..n_freq
            (the DC term carries no rotation information and is dropped).
        max_freq_cpm: highest frequency along l [cycles per metre]; at most 1 / (2 cell_m).
        pad_factor: zero padding of the image before its 2-D FFT (finer frequency grid for the
            radial interpolation).
        magnitude: transform of |S^(theta, k)| before z-normalisation.
    """

    preprocess: PreprocessConfig = field(
        default_factory=lambda: PreprocessConfig(spoke_removal=True)
    )
    image: ImageConfig = field(default_factory=ImageConfig)
    n_theta: int = 120
    theta_oversample: int = 2
    n_freq: int = 32
    max_freq_cpm: float = 0.25
    pad_factor: int = 2
    magnitude: MagnitudeTransform = "sqrt"

    def __post_init__(self) -> None:
        checks.at_least("n_theta", self.n_theta, 1)
        checks.at_least("theta_oversample", self.theta_oversample, 1)
        checks.at_least("n_freq", self.n_freq, 1)
        checks.positive("max_freq_cpm", self.max_freq_cpm)
        checks.in_range("max_freq_cpm", self.max_freq_cpm, 0.0, 0.5 / self.image.cell_m)  # Nyquist
        checks.at_least("pad_factor", self.pad_factor, 1)
        checks.one_of("magnitude", self.magnitude, typing.get_args(MagnitudeTransform))


@dataclass(frozen=True)
class ExclusionConfig:
    """Candidates a query may not match (the recent past of the same session).

    Attributes:
        recent_keyframes: the most recent N database entries are excluded.
        recent_seconds: entries added less than this before the query time are excluded
            (0 disables; entries without a time are subject to `recent_keyframes` only).
    """

    recent_keyframes: int = 50
    recent_seconds: float = 0.0

    def __post_init__(self) -> None:
        checks.at_least("recent_keyframes", self.recent_keyframes, 0)
        checks.non_negative("recent_seconds", self.recent_seconds)


@dataclass(frozen=True)
class RetrievalConfig:
    """RaPlace database search with the mutable-threshold distance.

    Attributes:
        hierarchical: rank the entries by a rotation-invariant bound (raplace.index), score the
            best `coarse_shortlist` on low-resolution descriptors, then re-score the best ones and
            their neighbours at full resolution; False scores all at full resolution.
        coarse_shortlist: entries kept by the invariant bound for the low-resolution scoring
            (0: score every allowed entry at low resolution).
        coarse_index_harmonics: lowest theta harmonics of the low-resolution descriptor kept in
            the invariant bound (raplace.index; the rest is bounded by its norm).
        coarse_theta_pool: descriptor rows averaged into one low-resolution row.
        coarse_n_freq: lowest frequency columns kept in the low-resolution descriptor.
        coarse_candidates: best entries by low-resolution distance that are re-scored.
        neighbour_radius: database neighbours (by insertion index) either side of each of them
            that are re-scored too.
        exclusion: which recent entries are never candidates.
        loop_threshold: a loop is declared when the distance is below this (dimensionless,
            1 - peak normalised cross-correlation; see raplace.scoring).
    """

    hierarchical: bool = True
    coarse_theta_pool: int = 3
    coarse_n_freq: int = 8
    coarse_candidates: int = 25
    coarse_shortlist: int = 400
    coarse_index_harmonics: int = 8
    neighbour_radius: int = 2
    exclusion: ExclusionConfig = field(default_factory=ExclusionConfig)
    loop_threshold: float = 0.2

    def __post_init__(self) -> None:
        checks.at_least("coarse_theta_pool", self.coarse_theta_pool, 1)
        checks.at_least("coarse_n_freq", self.coarse_n_freq, 1)
        checks.at_least("coarse_candidates", self.coarse_candidates, 1)
        checks.at_least("coarse_shortlist", self.coarse_shortlist, 0)
        checks.at_least("coarse_index_harmonics", self.coarse_index_harmonics, 1)
        if 0 < self.coarse_shortlist < self.coarse_candidates:
            raise ValueError(
                f"coarse_shortlist: must be 0 or at least coarse_candidates "
                f"({self.coarse_candidates}), got {self.coarse_shortlist}"
            )
        checks.at_least("neighbour_radius", self.neighbour_radius, 0)
        checks.in_range("loop_threshold", self.loop_threshold, 0.0, MAX_DISTANCE, open_low=True)


@dataclass(frozen=True)
class PoseConfig:
    """Relative pose (dx, dy, dyaw) between two scans from their sinogram spectra.

    Attributes:
        preprocess: polar clean-up settings.
        image: Cartesian image settings (finer cells than the descriptor's).
        n_theta: radial lines over [0, pi) used for rotation and per-angle shifts.
        pad_factor: zero padding before the 2-D FFT; shifts are found modulo
            pad_factor * image side.
        whitening: exponent beta of the cross-power normalisation |P|^-beta along l
            (0 = plain cross-correlation, 1 = phase correlation).
        shift_upsample: upsampling of the per-angle correlation along l before the peak search.
        rotation_peaks: theta-correlation peaks kept; each gives the hypotheses yaw, yaw - pi.
        inlier_threshold_m: per-angle shifts farther than this from the fit are outliers [m].
        refine_iterations: rotation refinements (maximise the aligned correlation around the
            estimate, then re-solve the translation).
    """

    preprocess: PreprocessConfig = field(
        default_factory=lambda: PreprocessConfig(spoke_removal=True)
    )
    image: ImageConfig = field(default_factory=lambda: ImageConfig(cell_m=0.5, max_range_m=64.0))
    n_theta: int = 180
    pad_factor: int = 2
    whitening: float = 0.5
    shift_upsample: int = 2
    rotation_peaks: int = 2
    inlier_threshold_m: float = 1.0
    refine_iterations: int = 1

    def __post_init__(self) -> None:
        checks.at_least("n_theta", self.n_theta, MIN_POSE_N_THETA)
        checks.even("n_theta", self.n_theta)
        checks.at_least("pad_factor", self.pad_factor, 1)
        checks.in_range("whitening", self.whitening, 0.0, 1.0)
        checks.at_least("shift_upsample", self.shift_upsample, 1)
        checks.at_least("rotation_peaks", self.rotation_peaks, 1)
        checks.positive("inlier_threshold_m", self.inlier_threshold_m)
        checks.at_least("refine_iterations", self.refine_iterations, 0)


@dataclass(frozen=True)
class ScanContextConfig:
    """Radar Scan Context baseline (Kim et al.; the MulRan radar version).

    Attributes:
        preprocess: polar clean-up settings.
        range_cell_m: range bins are averaged to about this size before the clean-up [m].
        n_rings: radial bins of the context over [0, max_range_m].
        n_sectors: angular bins over 360 deg (the column-shift resolution).
        max_range_m: radius of the context [m].
        n_candidates: nearest entries by ring key that are compared column-shift-wise.
        exclusion: which recent entries are never candidates.
        loop_threshold: a loop is declared when the distance (mean column cosine distance,
            in [0, 1]) is below this.
    """

    preprocess: PreprocessConfig = field(default_factory=PreprocessConfig)
    range_cell_m: float = 0.5
    n_rings: int = 20
    n_sectors: int = 60
    max_range_m: float = 80.0
    n_candidates: int = 10
    exclusion: ExclusionConfig = field(default_factory=ExclusionConfig)
    loop_threshold: float = 0.2

    def __post_init__(self) -> None:
        checks.positive("range_cell_m", self.range_cell_m)
        checks.at_least("n_rings", self.n_rings, 1)
        checks.at_least("n_sectors", self.n_sectors, 1)
        checks.positive("max_range_m", self.max_range_m)
        checks.at_least("n_candidates", self.n_candidates, 1)
        checks.in_range("loop_threshold", self.loop_threshold, 0.0, 1.0, open_low=True)


@dataclass(frozen=True)
class RaPlaceConfig:
    """All raplace settings, one section per stage."""

    descriptor: DescriptorConfig = field(default_factory=DescriptorConfig)
    retrieval: RetrievalConfig = field(default_factory=RetrievalConfig)
    pose: PoseConfig = field(default_factory=PoseConfig)
    scancontext: ScanContextConfig = field(default_factory=ScanContextConfig)

    def __post_init__(self) -> None:
        n_theta, pool = self.descriptor.n_theta, self.retrieval.coarse_theta_pool
        if n_theta % pool:
            raise ValueError(
                f"retrieval.coarse_theta_pool: must divide descriptor.n_theta ({n_theta}), "
                f"got {pool}"
            )
        if self.retrieval.coarse_n_freq > self.descriptor.n_freq:
            raise ValueError(
                f"retrieval.coarse_n_freq: must be at most descriptor.n_freq "
                f"({self.descriptor.n_freq}), got {self.retrieval.coarse_n_freq}"
            )
