"""Settings of the loop-closing stage (the `loop_closure` section of a radar-slam config)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import ClassVar

from odometry import OdometryConfig
from raplace import RaPlaceConfig, checks

CHI2_3DOF_99 = 11.345
"""Chi-square quantile at 99 % for 3 degrees of freedom (x, y, yaw)."""


@dataclass(frozen=True)
class VerificationConfig:
    """When a proposed loop passes the geometric verification.

    Attributes:
        min_sinogram_quality: minimum normalised correlation of the two images aligned by the
            sinogram estimate (`RelativePose.quality`, about 1 for the same place, 0 unrelated).
        min_inlier_fraction: minimum fraction of sinogram angles whose shift fits the translation.
            It falls with the distance between the scans, faster on real streets than in the
            simulator (real Oxford scans 12.5 m apart: 0.56 with the radial streaks removed,
            `raplace.config.PreprocessConfig.spoke_removal`, 0.31 without); the default leaves
            margin for revisits whose scene changed, and the phase-correlation checks decide.
        max_translation_m: the two scans may be at most this far apart [m] (beyond, too little
            overlap for a reliable registration).
        min_refined_quality: minimum peak-to-noise ratio of the phase-correlation refinement
            (the odometry's own registrations fail below `odometry.quality.min_peak_quality`).
        max_disagreement_m: the sinogram and phase-correlation translations may differ by this
            much [m].
        max_disagreement_deg: ... and their rotations by this much [deg].
        max_sigma_yaw_deg: the loop's rotation standard deviation (`LoopCovarianceConfig`) may
            be at most this [deg]. It is large when a scan was swept across a yaw-rate change
            (a curvature step at a junction, the end of a turn), which no constant de-skew twist
            represents: such loops' rotations are off by degrees. The default, 1 deg, puts the
            2 deg error bound of a true loop (`radar_slam.evaluation.truth`) at two sigmas.
        yaw_rate_search: at low frame rates (a query twist interpolated between odometry steps
            far apart), the query's de-skew yaw rate is searched by peak quality against the
            match (`odometry.searched_registration`): in a turn at 1 Hz the interpolated yaw
            rate can be tens of deg/s off the sweep's.
    """

    min_sinogram_quality: float = 0.25
    min_inlier_fraction: float = 0.2
    max_translation_m: float = 15.0
    min_refined_quality: float = 12.0
    max_disagreement_m: float = 1.5
    max_disagreement_deg: float = 3.0
    max_sigma_yaw_deg: float = 1.0
    yaw_rate_search: bool = True

    def __post_init__(self) -> None:  # value ranges
        checks.finite("min_sinogram_quality", self.min_sinogram_quality)
        checks.in_range("min_inlier_fraction", self.min_inlier_fraction, 0.0, 1.0)
        checks.positive("max_translation_m", self.max_translation_m, allow_inf=True)
        checks.non_negative("min_refined_quality", self.min_refined_quality)
        checks.positive("max_disagreement_m", self.max_disagreement_m, allow_inf=True)
        checks.positive("max_disagreement_deg", self.max_disagreement_deg, allow_inf=True)
        checks.positive("max_sigma_yaw_deg", self.max_sigma_yaw_deg, allow_inf=True)


@dataclass(frozen=True)
class LoopCovarianceConfig:
    """Covariance of a verified loop from its verification.

    cov = sigma_scale^2 * C_peak + diag(d_xy^2, d_xy^2, d_yaw^2) * disagreement_weight^2
          + diag(min_sigma_xy^2, min_sigma_xy^2, min_sigma_yaw^2),
    C_peak the phase-correlation covariance (peak width squared over peak-to-noise squared,
    `odometry.registration`), (d_xy, d_yaw) the sinogram / phase-correlation disagreement.

    cov += deskew_error_fraction^2 * (b_query^2 + b_match^2) per axis, b a scan's de-skew bend.
    The de-skew terms (on by default) cover the loops of scans swept while turning or across a
    velocity change at low frame rates, which were far too tight without them; the floors stay
    conservative (the loops' errors on real data are not measured), so at 4 Hz on the simulator
    the covariances are wider than the errors. docs/decisions.md gives
    the settings calibrated against the simulator's ground truth (mean NEES,
    `scripts/bench_nees.py`) and what the choices cost and gain in SLAM accuracy.

    Attributes:
        sigma_scale: multiplies the peak-derived standard deviations.
        disagreement_weight: weight of the disagreement term.
        min_sigma_xy_m: floor of the translation standard deviation [m].
        min_sigma_yaw_deg: floor of the rotation standard deviation [deg].
        deskew_error_fraction: each scan is de-skewed with the odometry's twist interpolated to
            mid-sweep, off by up to its change across the scan (a yaw-rate step inside a 1 s
            interval at 1 Hz); this fraction of the bend that change makes over half a sweep is
            added as a standard deviation for each scan (translation [m], rotation [rad];
            `verification.deskew_variance`).
        swept_turn_fraction: a scan swept while turning is de-skewed with a yaw rate whose
            error grows with it (the odometry's rotation bias per deg/s of de-skew error, see
            docs/decisions.md); this fraction of the rotation over half a sweep at the
            scan's yaw rate is added as a rotation standard deviation for each scan [rad]
            (`verification.swept_turn_variance`).
    """

    sigma_scale: float = 1.0
    disagreement_weight: float = 0.2
    min_sigma_xy_m: float = 0.05
    min_sigma_yaw_deg: float = 0.1
    deskew_error_fraction: float = 0.5
    swept_turn_fraction: float = 0.1

    def __post_init__(self) -> None:  # value ranges
        checks.non_negative("deskew_error_fraction", self.deskew_error_fraction)
        checks.non_negative("swept_turn_fraction", self.swept_turn_fraction)
        checks.positive("sigma_scale", self.sigma_scale)
        checks.non_negative("disagreement_weight", self.disagreement_weight)
        checks.positive("min_sigma_xy_m", self.min_sigma_xy_m)
        checks.positive("min_sigma_yaw_deg", self.min_sigma_yaw_deg)


@dataclass(frozen=True)
class ConsistencyConfig:
    """Pairwise consistency of verified loops (used when the detector is given poses).

    The odometry between two scans a path length P apart is modelled with standard deviations
    drift_fraction * P + min_sigma_xy_m (x and y) and drift_deg_per_m * P + min_sigma_yaw_deg.

    Attributes:
        min_support: other consistent loops a loop needs before it is accepted (0 accepts every
            verified loop that does not contradict the accepted ones nearby).
        window_m: loops support each other when their queries and their matches each lie within
            this path distance [m]; a pending loop is rejected once the query has travelled this
            far past it without support.
        chi2_threshold: two loops agree when the squared Mahalanobis distance of their cycle is
            below this (3 dof; 11.345 is the 99 % quantile).
        drift_fraction: odometry translation error per metre travelled (2 %: twice a typical
            radar odometry drift; 5 % let pairs of random false loops agree by chance).
        drift_deg_per_m: odometry rotation error per metre travelled [deg/m].
        min_sigma_xy_m: translation standard deviation of a zero-length segment [m].
        min_sigma_yaw_deg: rotation standard deviation of a zero-length segment [deg].
    """

    min_support: int = 1
    window_m: float = 60.0
    chi2_threshold: float = CHI2_3DOF_99
    drift_fraction: float = 0.02
    drift_deg_per_m: float = 0.05
    min_sigma_xy_m: float = 0.1
    min_sigma_yaw_deg: float = 0.2

    def __post_init__(self) -> None:  # value ranges
        checks.at_least("min_support", self.min_support, 0)
        checks.positive("window_m", self.window_m)
        checks.positive("chi2_threshold", self.chi2_threshold)
        checks.non_negative("drift_fraction", self.drift_fraction)
        checks.non_negative("drift_deg_per_m", self.drift_deg_per_m)
        checks.positive("min_sigma_xy_m", self.min_sigma_xy_m)
        checks.positive("min_sigma_yaw_deg", self.min_sigma_yaw_deg)


@dataclass(frozen=True)
class ThrottleConfig:
    """Fewer verifications along stretches already closed (`radar_slam.loops.throttle`; used
    when the detector is given poses).

    Attributes:
        closed_after: consecutive accepted loops along one stretch (matches advancing with the
            queries, the same or the opposite way) that mark it closed.
        closed_spacing_m: on a closed stretch, a query whose candidate lies on it is verified
            at most once per this much travel [m] (the others are skipped); 0 verifies every
            query (no throttling).
        stretch_tolerance_m: a match is on a stretch when it lies within this path distance
            [m] of where the stretch predicts it ...
        stretch_drift_fraction: ... plus this fraction of the travel since the stretch's
            latest loop (the two drives' odometry path lengths differ by the drift).
        max_gap_m: a stretch without an accepted loop over this much travel [m] is forgotten.
        max_stretches: stretches tracked at once (a place driven several times aligns with
            each earlier drive); the oldest is dropped beyond.
        predicted_checks: a candidate on a closed stretch is checked by the phase-correlation
            refinement alone, from the loop the stretch's latest one predicts
            (`radar_slam.loops.tracking`; verified in full when that fails); False verifies it
            in full.
    """

    closed_after: int = 3
    closed_spacing_m: float = 20.0
    stretch_tolerance_m: float = 12.0
    stretch_drift_fraction: float = 0.05
    max_gap_m: float = 100.0
    max_stretches: int = 8
    predicted_checks: bool = True

    def __post_init__(self) -> None:  # value ranges
        checks.at_least("closed_after", self.closed_after, 1)
        checks.non_negative("closed_spacing_m", self.closed_spacing_m)
        checks.non_negative("stretch_tolerance_m", self.stretch_tolerance_m)
        checks.non_negative("stretch_drift_fraction", self.stretch_drift_fraction)
        checks.positive("max_gap_m", self.max_gap_m)
        checks.at_least("max_stretches", self.max_stretches, 1)


LOOP_POSE_N_THETA = 120
"""Sinogram angles of the loop verifier's pose estimate (RaPlace's default 180 is 1.6x slower for
the same result once phase correlation refines it)."""
LOOP_POSE_PAD_FACTOR = 1
"""Zero padding of its spectra: shifts are found modulo 128 m, ample for loops under
`VerificationConfig.max_translation_m` (2 is about twice as slow)."""


def _raplace_defaults() -> RaPlaceConfig:
    base = RaPlaceConfig()
    pose = dataclasses.replace(
        base.pose, n_theta=LOOP_POSE_N_THETA, pad_factor=LOOP_POSE_PAD_FACTOR
    )
    return dataclasses.replace(base, pose=pose)


@dataclass(frozen=True)
class LoopClosureConfig:
    """The loop-closing stage's settings (the `loop_closure` section of a radar-slam config).

    Attributes:
        enabled: False replaces the detector by one that does nothing (`--no-loops`).
        raplace: descriptor, database (exclusion of recent entries), and sinogram-pose settings.
            RaPlace's own `retrieval.loop_threshold` (for precision-recall) is not used here.
        refinement: phase-correlation settings of the refinement (`odometry.registration`).
        candidates: database matches requested per query (k).
        loops_per_query: verification of a query's candidates stops once this many passed.
        max_descriptor_distance: a match is proposed for verification below this RaPlace distance
            (looser than a precision-oriented threshold: verification rejects the wrong ones).
        query_spacing_m: with poses, a scan enters the database and queries it once the path
            since the previous entry reaches this [m] (0: every scan); without poses, every scan.
        recent_path_m: a scan joins the database once the vehicle has driven this far past it
            [m] (with poses; without, after `raplace.retrieval.exclusion`'s entries and
            seconds), so the stretch just driven is never a candidate at any frame rate or
            speed (`radar_slam.loops.recent`); 0: at once, and the database's own exclusion
            window decides what is recent.
        odometry_drift_fraction: with poses, a candidate the odometry places farther from the
            query than `verification.max_translation_m` plus this fraction of the path between
            them is not verified (inf: every candidate is; the odometry is not trusted across
            a step beyond the vehicle's limits, so candidates before one are always verified).
        verification: geometric verification thresholds.
        covariance: covariance model of verified loops.
        consistency: pairwise consistency of verified loops.
        throttle: fewer verifications along stretches already closed (with poses).
    """

    enabled: bool = True
    raplace: RaPlaceConfig = field(default_factory=_raplace_defaults)
    refinement: OdometryConfig = field(default_factory=OdometryConfig)
    candidates: int = 2
    loops_per_query: int = 1
    max_descriptor_distance: float = 0.25
    query_spacing_m: float = 4.0
    recent_path_m: float = 50.0
    odometry_drift_fraction: float = 0.05
    verification: VerificationConfig = field(default_factory=VerificationConfig)
    covariance: LoopCovarianceConfig = field(default_factory=LoopCovarianceConfig)
    consistency: ConsistencyConfig = field(default_factory=ConsistencyConfig)
    throttle: ThrottleConfig = field(default_factory=ThrottleConfig)

    REMOVED_KEYS: ClassVar[dict[str, str]] = {
        "scan_cache_mb": "a run keeps no scans: it verifies a database scan from its record "
        "(radar_slam.maps.keyframes)",
        "pose_image_cache_mb": "a database scan's pose spectrum is made each time it is a "
        "candidate (keeping them saved nothing measurable)",
    }

    def __post_init__(self) -> None:  # value ranges
        checks.at_least("candidates", self.candidates, 1)
        checks.at_least("loops_per_query", self.loops_per_query, 1)
        checks.positive("max_descriptor_distance", self.max_descriptor_distance)
        checks.non_negative("query_spacing_m", self.query_spacing_m)
        checks.non_negative("recent_path_m", self.recent_path_m)
        checks.non_negative("odometry_drift_fraction", self.odometry_drift_fraction, allow_inf=True)
