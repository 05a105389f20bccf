"""Settings of the loop-closing stage (the `loop_closure` section of a radar-slam config)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import ClassVar

from raplace import RaPlaceConfig, checks
from raplace.config_io import replaced_by_constant, replaced_by_constants

CHI2_3DOF_99 = 11.345
"""Chi-square quantile at 99 % for 3 degrees of freedom (x, y, yaw)."""


@dataclass(frozen=True)
class VerificationConfig:
    """When a proposed loop passes the geometric verification (the other thresholds are
    constants of `radar_slam.loops.verification`, with their reasons).

    Attributes:
        max_translation_m: the two scans may be at most this far apart [m] (beyond, too little
            overlap for a reliable registration). Lower it for a radar that sees less far.
        min_refined_quality: minimum peak-to-noise ratio of the phase-correlation refinement
            (the odometry's own registrations fail below `odometry.quality.min_peak_quality`).
            Raise it for a noisier sensor whose false loops reach it; lower it only with
            ground truth to check the loops it adds.
    """

    REMOVED_KEYS: ClassVar[dict[str, str]] = replaced_by_constants(
        "radar_slam.loops.verification",
        "min_sinogram_quality",
        "min_inlier_fraction",
        "max_disagreement_m",
        "max_disagreement_deg",
        "max_sigma_yaw_deg",
        "yaw_rate_search",
    )
    max_translation_m: float = 15.0
    min_refined_quality: float = 12.0

    def __post_init__(self) -> None:  # value ranges
        checks.positive("max_translation_m", self.max_translation_m, allow_inf=True)
        checks.non_negative("min_refined_quality", self.min_refined_quality)


@dataclass(frozen=True)
class LoopCovarianceConfig:
    """Covariance of a verified loop from its verification (not a config section: the loop
    closer uses the constant `radar_slam.loops.verification.LOOP_COVARIANCE`).

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
    """Pairwise consistency of verified loops (used when the detector is given poses; the
    odometry drift model and the window are constants of `radar_slam.loops.consistency`).

    Attributes:
        min_support: other consistent loops a loop needs before it is accepted. 0 accepts every
            verified loop that does not contradict the accepted ones nearby: for short drives
            whose loops come one at a time; more for a sensor or a place with false loops that
            pass verification.
    """

    REMOVED_KEYS: ClassVar[dict[str, str]] = replaced_by_constants(
        "radar_slam.loops.consistency",
        "window_m",
        "chi2_threshold",
        "drift_fraction",
        "drift_deg_per_m",
        "min_sigma_xy_m",
        "min_sigma_yaw_deg",
    )
    min_support: int = 1

    def __post_init__(self) -> None:  # value ranges
        checks.at_least("min_support", self.min_support, 0)


@dataclass(frozen=True)
class ThrottleConfig:
    """Fewer verifications along stretches already closed (`radar_slam.loops.throttle`; used
    when the detector is given poses; how a stretch is followed is constants there).

    Attributes:
        closed_spacing_m: on a closed stretch, a query whose candidate lies on it is verified
            at most once per this much travel [m] (the others are skipped). 0 verifies every
            query: more loops on long revisits, at the cost of one verification per query.
    """

    REMOVED_KEYS: ClassVar[dict[str, str]] = {
        "closed_after": replaced_by_constant("radar_slam.loops.throttle.CLOSED_AFTER"),
        "stretch_tolerance_m": replaced_by_constant(
            "radar_slam.loops.throttle.STRETCH_TOLERANCE_M"
        ),
        "stretch_drift_fraction": (
            replaced_by_constant("radar_slam.loops.throttle.STRETCH_DRIFT_FRACTION")
        ),
        "max_gap_m": replaced_by_constant("radar_slam.loops.throttle.MAX_GAP_M"),
        "max_stretches": replaced_by_constant("radar_slam.loops.throttle.MAX_STRETCHES"),
        "predicted_checks": replaced_by_constant("radar_slam.loops.detector.PREDICTED_CHECKS"),
    }
    closed_spacing_m: float = 20.0

    def __post_init__(self) -> None:  # value ranges
        checks.non_negative("closed_spacing_m", self.closed_spacing_m)


LOOP_POSE_N_THETA = 120
"""Sinogram angles of the loop verifier's pose estimate (RaPlace's default 180 is 1.6x slower for
the same result once phase correlation refines it)."""
LOOP_POSE_PAD_FACTOR = 1
"""Zero padding of its spectra: shifts are found modulo 128 m, ample for loops under
`VerificationConfig.max_translation_m` (2 is about twice as slow)."""


CONDITIONED = dataclasses.replace(
    RaPlaceConfig().descriptor.preprocess,
    ring_noise_removal=False,
    spoke_removal=False,
    min_range_m=0.0,
)
"""RaPlace's own clean-up, off: the loop closer describes and images the odometry's conditioned
scan (`radar_slam.loops.records.raplace_input`), which RaPlace averages to its cells and warps."""


def _raplace_defaults() -> RaPlaceConfig:
    base = RaPlaceConfig()
    pose = dataclasses.replace(
        base.pose,
        preprocess=CONDITIONED,
        n_theta=LOOP_POSE_N_THETA,
        pad_factor=LOOP_POSE_PAD_FACTOR,
    )
    descriptor = dataclasses.replace(base.descriptor, preprocess=CONDITIONED)
    return dataclasses.replace(base, descriptor=descriptor, pose=pose)


LOOP_RAPLACE = _raplace_defaults()
"""RaPlace settings of the loop closer and of map localisation: descriptor, database (exclusion
of recent entries) and sinogram pose. RaPlace's own defaults (measured on MulRan and Oxford,
`raplace.config`) on the odometry's conditioned scans (`CONDITIONED`), with the verifier's
cheaper pose spectra above. RaPlace's own
`retrieval.loop_threshold` (for precision-recall) is not used here: `max_descriptor_distance`
decides. A map keeps the descriptor settings it was made with (`radar_slam.maps`)."""

LOOP_CLOSURE_REMOVED_KEYS = {
    "raplace": replaced_by_constant("radar_slam.loops.config.LOOP_RAPLACE, RaPlace's own defaults"),
    "refinement": (
        "the loop verifier's phase-correlation refinement now uses the odometry: section (whose "
        "defaults it had)"
    ),
    "loops_per_query": replaced_by_constant("radar_slam.loops.detector.LOOPS_PER_QUERY"),
    "covariance": replaced_by_constant("radar_slam.loops.verification.LOOP_COVARIANCE"),
    "scan_cache_mb": (
        "a run keeps no scans: it verifies a database scan from its record "
        "(radar_slam.maps.keyframes)"
    ),
    "pose_image_cache_mb": (
        "a database scan's pose spectrum is made each time it is a candidate (keeping them "
        "saved nothing measurable)"
    ),
}


@dataclass(frozen=True)
class LoopClosureConfig:
    """The loop-closing stage's settings (the `loop_closure` section of a radar-slam config).

    The verifier's phase-correlation refinement uses the run's `odometry` section (the same
    registration, conditioning and de-skew as the odometry; `odometry.quality.sigma_scale` scales
    the loops' peak covariance too); the RaPlace settings are `LOOP_RAPLACE`.

    Attributes:
        enabled: False replaces the detector by one that does nothing (`--no-loops`).
        candidates: database matches requested per query (k). More finds loops the first
            candidate misses (a place seen from another lane) at one verification each.
        max_descriptor_distance: a match is proposed for verification below this RaPlace
            distance (looser than a precision-oriented threshold: verification rejects the
            wrong ones). Raise it when true revisits are missed (changed scenes, another
            sensor); lower it to spend fewer verifications.
        query_spacing_m: with poses, a scan enters the database and queries it once the path
            since the previous entry reaches this [m] (0: every scan); without poses, every
            scan. Lower means more loops and more work.
        recent_path_m: a scan joins the database once the vehicle has driven this far past it
            [m] (with poses; without, after RaPlace's exclusion of recent entries), so the
            stretch just driven is never a candidate at any frame rate or speed
            (`radar_slam.loops.recent`); 0: at once. Raise it for a sensor that sees farther.
        odometry_drift_fraction: with poses, a candidate the odometry places farther from the
            query than `verification.max_translation_m` plus this fraction of the path between
            them is not verified (inf: every candidate is; the odometry is not trusted across
            a step beyond the vehicle's limits, so candidates before one are always verified).
            Raise it when the odometry drifts more (a weaker sensor, long drives).
        verification: geometric verification thresholds a sensor may need to change.
        consistency: pairwise consistency of verified loops.
        throttle: fewer verifications along stretches already closed (with poses).
    """

    REMOVED_KEYS: ClassVar[dict[str, str]] = LOOP_CLOSURE_REMOVED_KEYS
    enabled: bool = True
    candidates: int = 2
    max_descriptor_distance: float = 0.25
    query_spacing_m: float = 4.0
    recent_path_m: float = 50.0
    odometry_drift_fraction: float = 0.05
    verification: VerificationConfig = field(default_factory=VerificationConfig)
    consistency: ConsistencyConfig = field(default_factory=ConsistencyConfig)
    throttle: ThrottleConfig = field(default_factory=ThrottleConfig)

    def __post_init__(self) -> None:  # value ranges
        checks.at_least("candidates", self.candidates, 1)
        checks.positive("max_descriptor_distance", self.max_descriptor_distance)
        checks.non_negative("query_spacing_m", self.query_spacing_m)
        checks.non_negative("recent_path_m", self.recent_path_m)
        checks.non_negative("odometry_drift_fraction", self.odometry_drift_fraction, allow_inf=True)
