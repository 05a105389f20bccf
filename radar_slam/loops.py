"""Loop closing: RaPlace candidates, two-stage geometric verification, pairwise consistency.

For every database scan (one every `query_spacing_m` of travel when poses are given, else every
scan) the `LoopDetector`

1. describes the scan (RaPlace descriptor) and queries the place database, which excludes the
   most recent entries (`raplace.retrieval.exclusion`), for `candidates` matches; those with a
   descriptor distance below `max_descriptor_distance` are *proposed*, then the scan is added to
   the database;
2. verifies each proposal, best first, until one passes (`GeometricVerifier`):
   a. the relative pose from the two sinogram spectra (`raplace.pose`: rotation by correlation
      along theta with both pi hypotheses, translation by robust least squares of the per-angle
      shifts), moved from the scans' mean acquisition times to their reference times
      (`motion_compensated`: without it, scans driven in opposite directions disagree by about
      speed x sweep, 2.5-3.7 m on a reverse revisit); rejected when the aligned correlation,
      the inlier fraction or the translation is implausible;
   b. refinement by phase correlation (`odometry.registration`): the map scan is first turned by
      the sinogram rotation (an azimuth offset: no resampling), so phase correlation only has to
      find the translation and a small residual rotation; rejected when its peak is weak or when
      it disagrees with the sinogram estimate by more than `max_disagreement_m` / `_deg`;
   c. the loop's covariance comes from the phase-correlation peak (width over height, already a
      covariance in `MotionEstimate`), inflated by the disagreement of the two estimates, floored
      (`loop_covariance`);
3. checks the verified loop for consistency with the other verified loops nearby
   (`ConsistencyGate`, when poses are given): two loops (qa, ma, za) and (qb, mb, zb) must close
   the cycle za * T_ma_mb = T_qa_qb * zb, the odometry segments between the two queries and
   between the two matches having a covariance that grows with their length. A loop is accepted
   once `min_support` other loops agree with it; until then it is pending, and it is rejected
   when it contradicts every accepted loop nearby or when the query has moved `window_m` on
   without support.

Why pairwise consistency rather than a Mahalanobis gate against the graph: after a long drift
the first true loop lies far outside any chi-square gate of the current estimate (measured by the
graph's engineer: d^2 = 14.6 for a moderate, 73 for a strong drift versus 11.3 at 99 %), whereas
the odometry between two nearby loops drifts little, so the cycle test is tight for wrong loops
and loose for none, and it does not depend on how well the odometry's covariance is calibrated
(an early odometry version's factors had squared Mahalanobis errors of 8-11 instead of 3; after
its recalibration they average about 2.7, but a real sensor will not be calibrated as well as the
simulator). With 2 % drift per metre and a 60 m window, random false loops (30 % of all) never
formed a consistent pair in 12 simulated trials (5 %: 8 pairs). The graph's robust kernel and its
final GNC pass handle what slips through.

Every verified proposal becomes a `LoopDecision` with its reason, accepted or not. Measurements
follow the graph convention: a loop (i = query, j = match) measures T_i^-1 T_j, the match scan's
pose in the query scan's frame (x forward, y left [m], yaw CCW [rad]).

`NullLoopDetector` has the same interface and does nothing (loop closing disabled).
"""

from __future__ import annotations

import dataclasses
import logging
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from odometry import OdometryConfig
from odometry.deskew import motion_from_twist, twist_from_motion
from odometry.registration import PreparedScan, prepare, register
from odometry.scan import Scan
from odometry.se2 import between, compose, wrap_angle
from radar_slam.datasets.frame import RadarFrame
from radar_slam.errors import RadarSlamError
from radar_slam.graph import LoopConstraint
from raplace import checks
from raplace.config import RaPlaceConfig
from raplace.descriptor import DescriptorExtractor
from raplace.pose import PoseEstimator, RelativePose
from raplace.retrieval import Candidate, PlaceRecognizer

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
LoopStatus = Literal["accepted", "rejected", "pending"]

NS_PER_S = 1e9
POSE_DIM = 3
CHI2_3DOF_99 = 11.345
"""Chi-square quantile at 99 % for 3 degrees of freedom (x, y, yaw)."""
REVISIT_CRITERION_M = 20.0
"""Two scans less than this apart (ground truth) see the same place (RaPlace's criterion)."""
TRUE_LOOP_MAX_ERROR_M = 1.0
"""A true loop's measured translation is within this of the ground-truth relative pose [m]."""
TRUE_LOOP_MAX_ERROR_DEG = 2.0
"""... and its rotation within this [deg]."""


class LoopClosureError(RadarSlamError):
    """Loop-closing input is inconsistent (poses given for some scans only, keys reused, ...)."""


# --------------------------------------------------------------------------- configuration


@dataclass(frozen=True)
class VerificationConfig:
    """When a proposed loop passes the geometric verification.

    Attributes:
        min_sinogram_quality: minimum normalised correlation of the two images aligned by the
            sinogram estimate (`RelativePose.quality`, about 1 for the same place, 0 unrelated).
        min_inlier_fraction: minimum fraction of sinogram angles whose shift fits the translation.
        max_translation_m: the two scans may be at most this far apart [m] (beyond, too little
            overlap for a reliable registration).
        min_refined_quality: minimum peak-to-noise ratio of the phase-correlation refinement
            (the odometry's own registrations fail below `odometry.quality.min_peak_quality`).
        max_disagreement_m: the sinogram and phase-correlation translations may differ by this
            much [m].
        max_disagreement_deg: ... and their rotations by this much [deg].
    """

    min_sinogram_quality: float = 0.25
    min_inlier_fraction: float = 0.5
    max_translation_m: float = 15.0
    min_refined_quality: float = 12.0
    max_disagreement_m: float = 1.5
    max_disagreement_deg: float = 3.0

    def __post_init__(self) -> None:  # value ranges (issue 12)
        checks.finite("min_sinogram_quality", self.min_sinogram_quality)
        checks.in_range("min_inlier_fraction", self.min_inlier_fraction, 0.0, 1.0)
        checks.positive("max_translation_m", self.max_translation_m, allow_inf=True)
        checks.non_negative("min_refined_quality", self.min_refined_quality)
        checks.positive("max_disagreement_m", self.max_disagreement_m, allow_inf=True)
        checks.positive("max_disagreement_deg", self.max_disagreement_deg, allow_inf=True)


@dataclass(frozen=True)
class LoopCovarianceConfig:
    """Covariance of a verified loop from its verification.

    cov = sigma_scale^2 * C_peak + diag(d_xy^2, d_xy^2, d_yaw^2) * disagreement_weight^2
          + diag(min_sigma_xy^2, min_sigma_xy^2, min_sigma_yaw^2),
    C_peak the phase-correlation covariance (peak width squared over peak-to-noise squared,
    `odometry.registration`), (d_xy, d_yaw) the sinogram / phase-correlation disagreement.

    Attributes:
        sigma_scale: multiplies the peak-derived standard deviations.
        disagreement_weight: weight of the disagreement term.
        min_sigma_xy_m: floor of the translation standard deviation [m].
        min_sigma_yaw_deg: floor of the rotation standard deviation [deg].
    """

    sigma_scale: float = 1.0
    disagreement_weight: float = 0.2
    min_sigma_xy_m: float = 0.05
    min_sigma_yaw_deg: float = 0.1

    def __post_init__(self) -> None:  # value ranges (issue 12)
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

    def __post_init__(self) -> None:  # value ranges (issue 12)
        checks.at_least("min_support", self.min_support, 0)
        checks.positive("window_m", self.window_m)
        checks.positive("chi2_threshold", self.chi2_threshold)
        checks.non_negative("drift_fraction", self.drift_fraction)
        checks.non_negative("drift_deg_per_m", self.drift_deg_per_m)
        checks.positive("min_sigma_xy_m", self.min_sigma_xy_m)
        checks.positive("min_sigma_yaw_deg", self.min_sigma_yaw_deg)


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
        verification: geometric verification thresholds.
        covariance: covariance model of verified loops.
        consistency: pairwise consistency of verified loops.
    """

    enabled: bool = True
    raplace: RaPlaceConfig = field(default_factory=_raplace_defaults)
    refinement: OdometryConfig = field(default_factory=OdometryConfig)
    candidates: int = 2
    loops_per_query: int = 1
    max_descriptor_distance: float = 0.25
    query_spacing_m: float = 4.0
    verification: VerificationConfig = field(default_factory=VerificationConfig)
    covariance: LoopCovarianceConfig = field(default_factory=LoopCovarianceConfig)
    consistency: ConsistencyConfig = field(default_factory=ConsistencyConfig)

    def __post_init__(self) -> None:  # value ranges (issue 12)
        checks.at_least("candidates", self.candidates, 1)
        checks.at_least("loops_per_query", self.loops_per_query, 1)
        checks.positive("max_descriptor_distance", self.max_descriptor_distance)
        checks.non_negative("query_spacing_m", self.query_spacing_m)


# --------------------------------------------------------------------------- records


@dataclass(frozen=True)
class Verification:
    """Outcome of the geometric verification of one proposal.

    Attributes:
        ok: every check passed.
        reason: why it failed ("" when ok).
        measurement: (3,) T_query_match, the refined estimate when available, else the sinogram
            estimate (NaN before any estimate).
        covariance: (3, 3) of `measurement` (GTSAM tangent order x, y, yaw; NaN unless ok).
        sinogram: (3,) the sinogram estimate of T_query_match.
        sinogram_quality: its aligned normalised correlation.
        refined_quality: peak-to-noise ratio of the phase-correlation refinement (0 if not run).
    """

    ok: bool
    reason: str
    measurement: FloatArray
    covariance: FloatArray
    sinogram: FloatArray
    sinogram_quality: float
    refined_quality: float = 0.0


@dataclass(frozen=True)
class LoopDecision:
    """What happened to one verified proposal (a row of loops.csv).

    Attributes:
        query_key, match_key: keys of the two scans (scan indices in the pipeline).
        query_ns, match_ns: their timestamps [ns].
        distance: RaPlace descriptor distance.
        measurement: (3,) T_query_match (dx, dy [m], dyaw [rad]); NaN when no estimate exists.
        covariance: (3, 3) of the measurement (NaN unless verified).
        sinogram_quality: normalised correlation after the sinogram alignment.
        refined_quality: phase-correlation peak-to-noise ratio (0 if not run).
        status: "accepted", "rejected" or "pending" (waiting for consistent support).
        reason: why (accepted or not), one line.
    """

    query_key: int
    match_key: int
    query_ns: int
    match_ns: int
    distance: float
    measurement: FloatArray
    covariance: FloatArray
    sinogram_quality: float
    refined_quality: float
    status: LoopStatus
    reason: str

    @property
    def accepted(self) -> bool:
        return self.status == "accepted"

    def constraint(self) -> LoopConstraint:
        """The loop as a graph constraint (i = query, j = match)."""
        return LoopConstraint(self.query_key, self.match_key, self.measurement, self.covariance)


@dataclass(frozen=True)
class KeyScan:
    """A database scan as the verifier sees it.

    Attributes:
        key: the caller's key (scan index).
        timestamp_ns: scan time [ns].
        scan: the scan itself.
        twist: (3,) body velocity (vx, vy [m/s], yaw rate [rad/s]) for de-skewing, or None.
    """

    key: int
    timestamp_ns: int
    scan: Scan
    twist: FloatArray | None = None


@dataclass(frozen=True)
class VerifiedLoop:
    """A verified loop as the consistency gate sees it.

    Attributes:
        decision: index of its `LoopDecision`.
        query_key, match_key: scan keys.
        measurement: (3,) T_query_match; covariance: (3, 3).
        query_pose, match_pose: (3,) odometry poses T_world_scan of the two scans.
        query_path_m, match_path_m: odometry path length from the first scan [m].
    """

    decision: int
    query_key: int
    match_key: int
    measurement: FloatArray
    covariance: FloatArray
    query_pose: FloatArray
    match_pose: FloatArray
    query_path_m: float
    match_path_m: float


# --------------------------------------------------------------------------- pure functions


def adjoint(pose: ArrayLike) -> FloatArray:
    """SE(2) adjoint (..., 3, 3) of poses (..., 3) in GTSAM's tangent order (x, y, yaw):
    Exp(Ad(T) xi) = T Exp(xi) T^-1."""
    p = np.asarray(pose, dtype=np.float64)
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    ad = np.zeros(p.shape[:-1] + (POSE_DIM, POSE_DIM))
    ad[..., 0, 0], ad[..., 0, 1], ad[..., 0, 2] = c, -s, p[..., 1]
    ad[..., 1, 0], ad[..., 1, 1], ad[..., 1, 2] = s, c, -p[..., 0]
    ad[..., 2, 2] = 1.0
    return ad


def rotate_covariance(covariance: ArrayLike, yaw_rad: float) -> FloatArray:
    """A (3, 3) covariance whose translation block is in one frame, expressed in a frame turned
    by `yaw_rad` relative to it (the translation block is rotated by -yaw_rad)."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    out = rot @ np.asarray(covariance, dtype=np.float64) @ rot.T
    return 0.5 * (out + out.T)


def loop_covariance(
    peak_covariance: ArrayLike,
    disagreement: ArrayLike,
    yaw_rad: float,
    cfg: LoopCovarianceConfig,
) -> FloatArray:
    """Covariance (3, 3) of a verified loop measurement in GTSAM's tangent space.

    Args:
        peak_covariance: (3, 3) covariance of the phase-correlation estimate, translation in the
            query frame (`MotionEstimate.covariance`) [m^2, m rad, rad^2].
        disagreement: (3,) sinogram estimate expressed relative to the refined one (dx, dy [m],
            dyaw [rad]).
        yaw_rad: the loop's rotation (the match frame is turned by it from the query frame);
            GTSAM perturbs a between-factor on the right, i.e. in the match frame.
        cfg: the covariance model (see `LoopCovarianceConfig`).
    """
    d = np.asarray(disagreement, dtype=np.float64)
    d_xy = float(np.hypot(d[0], d[1]))
    d_yaw = abs(float(wrap_angle(d[2])))
    w = cfg.disagreement_weight
    floor_yaw = np.deg2rad(cfg.min_sigma_yaw_deg)
    cov = cfg.sigma_scale**2 * np.asarray(peak_covariance, dtype=np.float64)
    cov = cov + np.diag([(w * d_xy) ** 2, (w * d_xy) ** 2, (w * d_yaw) ** 2])
    cov = cov + np.diag([cfg.min_sigma_xy_m**2, cfg.min_sigma_xy_m**2, floor_yaw**2])
    return rotate_covariance(cov, yaw_rad)


def odometry_segment_covariance(path_m: ArrayLike, cfg: ConsistencyConfig) -> FloatArray:
    """(..., 3, 3) diagonal covariance of odometry segments `path_m` (...) metres long."""
    length = np.abs(np.asarray(path_m, dtype=np.float64))
    sigma_xy = cfg.drift_fraction * length + cfg.min_sigma_xy_m
    sigma_yaw = np.deg2rad(cfg.drift_deg_per_m * length + cfg.min_sigma_yaw_deg)
    cov = np.zeros(length.shape + (POSE_DIM, POSE_DIM))
    cov[..., 0, 0] = cov[..., 1, 1] = sigma_xy**2
    cov[..., 2, 2] = sigma_yaw**2
    return cov


def cycle_mahalanobis(
    loop: VerifiedLoop, others: list[VerifiedLoop], cfg: ConsistencyConfig
) -> FloatArray:
    """Squared Mahalanobis distances (n,) of the cycles closed by `loop` with each of `others`.

    For loops a (qa, ma, za) and b (qb, mb, zb) the cycle error is
    e = Log((za T_ma_mb)^-1 (T_qa_qb zb)) with T_ma_mb, T_qa_qb from the odometry poses. To first
    order its covariance is Ad(T_ma_mb^-1) S_za Ad^T + S_ma_mb + Ad(zb^-1) S_qa_qb Ad^T + S_zb,
    the odometry segments' covariances from `odometry_segment_covariance`. Vectorised over
    `others`; Log is taken as (x, y, wrapped yaw) (the cycle is near the identity when it
    matters).
    """
    if not others:
        return np.zeros(0)
    za = np.stack([o.measurement for o in others])  # (n, 3)
    sa = np.stack([o.covariance for o in others])
    qa = np.stack([o.query_pose for o in others])
    ma = np.stack([o.match_pose for o in others])
    path_q = loop.query_path_m - np.array([o.query_path_m for o in others])
    path_m = loop.match_path_m - np.array([o.match_path_m for o in others])
    zb = np.asarray(loop.measurement, dtype=np.float64)
    sb = np.asarray(loop.covariance, dtype=np.float64)
    t_ma_mb = between(ma, loop.match_pose)  # (n, 3)
    t_qa_qb = between(qa, loop.query_pose)
    error = between(compose(za, t_ma_mb), compose(t_qa_qb, zb))  # (n, 3)
    error[:, 2] = wrap_angle(error[:, 2])
    ad_m = adjoint(between(t_ma_mb, np.zeros(3)))  # Ad(T_ma_mb^-1)
    ad_zb = adjoint(between(zb, np.zeros(3)))  # Ad(zb^-1)
    cov = (
        ad_m @ sa @ np.swapaxes(ad_m, -1, -2)
        + odometry_segment_covariance(path_m, cfg)
        + ad_zb @ odometry_segment_covariance(path_q, cfg) @ ad_zb.T
        + sb
    )
    solved = np.linalg.solve(cov, error[..., None])[..., 0]
    return np.einsum("ni,ni->n", error, solved)


def is_true_loop(
    measurement: ArrayLike,
    gt_query: ArrayLike,
    gt_match: ArrayLike,
    criterion_m: float = REVISIT_CRITERION_M,
    max_error_m: float = TRUE_LOOP_MAX_ERROR_M,
    max_error_deg: float = TRUE_LOOP_MAX_ERROR_DEG,
) -> bool | None:
    """Whether a loop is true: the scans lie within `criterion_m` (ground truth) AND the measured
    T_query_match is within `max_error_m` / `max_error_deg` of the ground-truth relative pose.

    Args:
        measurement: (3,) measured T_query_match (NaN: no estimate).
        gt_query, gt_match: (3,) ground-truth T_world_radar of the two scans (NaN: unknown).

    Returns:
        None when a ground-truth pose is unknown, else the verdict.
    """
    q = np.asarray(gt_query, dtype=np.float64)
    m = np.asarray(gt_match, dtype=np.float64)
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(m))):
        return None
    z = np.asarray(measurement, dtype=np.float64)
    if np.hypot(*(m[:2] - q[:2])) > criterion_m or not np.all(np.isfinite(z)):
        return False
    error = between(between(q, m), z)
    return bool(
        np.hypot(error[0], error[1]) <= max_error_m
        and abs(float(wrap_angle(error[2]))) <= np.deg2rad(max_error_deg)
    )


# --------------------------------------------------------------------------- verification


def turned(scan: Scan, turn_rad: float) -> RadarFrame:
    """`scan` seen from a frame whose x axis is turned by -`turn_rad` from the scan's: a point at
    azimuth a in the scan's frame lies at a + turn_rad in the new one (azimuths offset)."""
    return RadarFrame(
        timestamp_ns=int(scan.timestamp_ns),
        polar=scan.polar,
        azimuths_rad=np.asarray(scan.azimuths_rad, dtype=np.float64) + turn_rad,
        range_resolution_m=float(scan.range_resolution_m),
        sensor=scan.sensor,
        azimuth_times_ns=scan.azimuth_times_ns,
    )


def turned_twist(twist: FloatArray | None, turn_rad: float) -> FloatArray | None:
    """A body twist (vx, vy, yaw rate) expressed in a frame turned like `turned`."""
    if twist is None:
        return None
    c, s = np.cos(turn_rad), np.sin(turn_rad)
    vx, vy, w = (float(v) for v in twist)
    return np.array([c * vx - s * vy, s * vx + c * vy, w])


def mean_acquisition_offset_s(scan: Scan) -> float | None:
    """Mean azimuth time minus the scan's reference time [s] (None without azimuth times)."""
    times = scan.azimuth_times_ns
    if times is None or len(times) == 0:
        return None
    return float(np.mean(np.asarray(times, dtype=np.float64) - float(scan.timestamp_ns))) / NS_PER_S


def motion_compensated(estimate: FloatArray, query: KeyScan, match: KeyScan) -> FloatArray:
    """A T_query_match estimated from images that are not de-skewed, moved to the scans'
    reference times.

    Without de-skewing, a scan's image is on average the scene seen from the pose at its mean
    acquisition time. With P = the pose at that time in the reference-time frame (constant body
    twist), the image estimate is P_q^-1 T_qm P_m, so T_qm = P_q * estimate * P_m^-1. For two
    scans driving in opposite directions the correction is about speed x sweep (2.5 m at 10 m/s
    over 250 ms); in the same direction at the same speed it cancels. Scans without twist or
    azimuth times are left as they are.
    """
    poses = []
    for scan in (query, match):
        offset = mean_acquisition_offset_s(scan.scan)
        if scan.twist is None or offset is None:
            poses.append(np.zeros(3))
        else:
            poses.append(motion_from_twist(scan.twist, offset))
    return compose(compose(poses[0], estimate), between(poses[1], np.zeros(3)))


class Verifier(Protocol):
    """Verifies a proposed loop between a query scan and a database (match) scan."""

    def __call__(self, query: KeyScan, match: KeyScan) -> Verification: ...


class GeometricVerifier:
    """Sinogram relative pose, refined by phase correlation (see the module docstring).

    Caches the current query's pose image and prepared scan, so verifying several candidates of
    one query conditions the query scan once.
    """

    def __init__(self, cfg: LoopClosureConfig) -> None:
        self.cfg = cfg
        self.pose_estimator = PoseEstimator(cfg.raplace.pose)
        self._query_key: int | None = None
        self._query_image: NDArray[np.float32] | None = None
        self._query_prepared: PreparedScan | None = None

    def _query(self, query: KeyScan) -> NDArray[np.float32]:
        if self._query_key != query.key or self._query_image is None:
            s = query.scan
            self._query_key = query.key
            self._query_image = self.pose_estimator.image(
                s.polar, s.azimuths_rad, s.range_resolution_m
            )
            self._query_prepared = None
        return self._query_image

    def _prepared_query(self, query: KeyScan) -> PreparedScan:
        if self._query_prepared is None:
            self._query_prepared = prepare(query.scan, self.cfg.refinement, query.twist)
        return self._query_prepared

    def __call__(self, query: KeyScan, match: KeyScan) -> Verification:
        """Verify T_query_match; never raises for a bad match (the reason says why)."""
        vcfg = self.cfg.verification
        query_image = self._query(query)
        m = match.scan
        map_image = self.pose_estimator.image(m.polar, m.azimuths_rad, m.range_resolution_m)
        rel: RelativePose = self.pose_estimator.estimate(query_image, map_image)
        sinogram = motion_compensated(rel.as_array(), query, match)
        nan3 = np.full(3, np.nan)
        nan33 = np.full((3, 3), np.nan)

        def failed(
            reason: str, measurement: FloatArray = sinogram, quality: float = 0.0
        ) -> Verification:
            return Verification(
                False, reason, measurement, nan33, sinogram, float(rel.quality), quality
            )

        if not np.isfinite(rel.quality) or rel.quality < vcfg.min_sinogram_quality:
            return failed(
                f"weak sinogram alignment (correlation {rel.quality:.2f} < "
                f"{vcfg.min_sinogram_quality:.2f})"
            )
        if rel.inlier_fraction < vcfg.min_inlier_fraction:
            return failed(
                f"sinogram shifts inconsistent (inliers {rel.inlier_fraction:.2f} < "
                f"{vcfg.min_inlier_fraction:.2f})"
            )
        distance_m = float(np.hypot(sinogram[0], sinogram[1]))
        if distance_m > vcfg.max_translation_m:
            return failed(
                f"scans {distance_m:.1f} m apart (more than {vcfg.max_translation_m:.1f} m)"
            )

        # Phase correlation of the query and the match turned by the sinogram rotation.
        turn = float(sinogram[2])
        aligned = prepare(
            turned(match.scan, turn), self.cfg.refinement, turned_twist(match.twist, turn)
        )
        estimate = register(self._prepared_query(query), aligned, self.cfg.refinement)
        refined = compose(estimate.motion, np.array([0.0, 0.0, turn]))
        if not estimate.ok:
            return failed(f"phase correlation failed: {estimate.reason}", nan3, estimate.quality)
        if estimate.quality < vcfg.min_refined_quality:
            return failed(
                f"weak phase-correlation peak (quality {estimate.quality:.1f} < "
                f"{vcfg.min_refined_quality:.1f})",
                refined,
                estimate.quality,
            )
        disagreement = between(refined, sinogram)
        off_m = float(np.hypot(disagreement[0], disagreement[1]))
        off_deg = float(np.rad2deg(abs(wrap_angle(disagreement[2]))))
        if off_m > vcfg.max_disagreement_m or off_deg > vcfg.max_disagreement_deg:
            return failed(
                f"sinogram and phase correlation disagree by {off_m:.2f} m / {off_deg:.2f} deg "
                f"(max {vcfg.max_disagreement_m:.2f} m / {vcfg.max_disagreement_deg:.2f} deg)",
                refined,
                estimate.quality,
            )
        covariance = loop_covariance(
            estimate.covariance, disagreement, float(refined[2]), self.cfg.covariance
        )
        return Verification(
            True, "", refined, covariance, sinogram, float(rel.quality), float(estimate.quality)
        )


# --------------------------------------------------------------------------- consistency


class ConsistencyGate:
    """Accepts verified loops once enough nearby loops agree with them (see the module docstring).

    `add(loop)` returns the decisions (indices) resolved by that loop: accepted (it and any
    pending loop it supports) or rejected; `expire(path_m)` rejects pending loops left behind;
    `finish()` rejects every pending loop.
    """

    def __init__(self, cfg: ConsistencyConfig) -> None:
        self.cfg = cfg
        self._loops: list[VerifiedLoop] = []
        self._status: list[LoopStatus] = []
        self._support: list[set[int]] = []  # per loop: decisions of the loops agreeing with it
        self._pending: list[int] = []  # positions of the pending loops
        self.reasons: dict[int, str] = {}  # decision -> reason of its latest status

    def __len__(self) -> int:
        return len(self._loops)

    def add(self, loop: VerifiedLoop) -> dict[int, LoopStatus]:
        """Check a verified loop against the pending and accepted ones nearby.

        Returns:
            decision -> new status of every loop whose status this call set (`loop` included).
        """
        cfg = self.cfg
        live = [
            n
            for n, other in enumerate(self._loops)
            if self._status[n] != "rejected"
            and other.query_key != loop.query_key
            and abs(loop.query_path_m - other.query_path_m) <= cfg.window_m
            and abs(loop.match_path_m - other.match_path_m) <= cfg.window_m
        ]
        d2 = cycle_mahalanobis(loop, [self._loops[n] for n in live], cfg)
        agree = [n for n, d in zip(live, d2, strict=True) if d <= cfg.chi2_threshold]
        accepted_near = [n for n in live if self._status[n] == "accepted"]
        accepted_agree = [n for n in agree if self._status[n] == "accepted"]

        index = len(self._loops)
        self._loops.append(loop)
        self._support.append({self._loops[n].decision for n in agree})
        changes: dict[int, LoopStatus] = {}
        if accepted_near and not accepted_agree:
            worst = float(np.min(d2[[live.index(n) for n in accepted_near]]))
            self._set(
                index,
                "rejected",
                f"inconsistent with {len(accepted_near)} accepted loop(s) nearby "
                f"(best cycle d2 {worst:.1f} > {cfg.chi2_threshold:.1f})",
                changes,
            )
            return changes
        if len(agree) >= cfg.min_support:
            self._set(index, "accepted", f"consistent with {len(agree)} loop(s)", changes)
            for n in agree:
                self._support[n].add(loop.decision)
                if self._status[n] == "pending" and len(self._support[n]) >= cfg.min_support:
                    self._set(
                        n, "accepted", f"consistent with {len(self._support[n])} loop(s)", changes
                    )
        else:
            self._set(
                index,
                "pending",
                f"waiting for support ({len(agree)} of {cfg.min_support} consistent loops)",
                changes,
            )
            for n in agree:
                self._support[n].add(loop.decision)
        return changes

    def expire(self, path_m: float) -> dict[int, LoopStatus]:
        """Reject the pending loops whose query lies more than `window_m` behind `path_m`."""
        changes: dict[int, LoopStatus] = {}
        for n in list(self._pending):
            if path_m - self._loops[n].query_path_m > self.cfg.window_m:
                self._set(n, "rejected", self._unsupported(n), changes)
        return changes

    def finish(self) -> dict[int, LoopStatus]:
        """Reject every loop still pending (end of the sequence)."""
        changes: dict[int, LoopStatus] = {}
        for n in list(self._pending):
            self._set(n, "rejected", self._unsupported(n) + " by the end", changes)
        return changes

    def _unsupported(self, n: int) -> str:
        return (
            f"unsupported: {len(self._support[n])} of {self.cfg.min_support} consistent loops "
            f"within {self.cfg.window_m:.0f} m"
        )

    def _set(self, n: int, status: LoopStatus, reason: str, changes: dict[int, LoopStatus]) -> None:
        if n == len(self._status):
            self._status.append(status)
        else:
            if self._status[n] == "pending":
                self._pending.remove(n)
            self._status[n] = status
        if status == "pending":
            self._pending.append(n)
        decision = self._loops[n].decision
        self.reasons[decision] = reason
        changes[decision] = status


# --------------------------------------------------------------------------- detector


class LoopCloser(Protocol):
    """What the pipeline needs from a loop detector (real or do-nothing)."""

    def add(
        self, scan: Scan, pose: ArrayLike | None = None, key: int | None = None
    ) -> list[LoopConstraint]: ...

    def finish(self) -> list[LoopConstraint]: ...

    def reject(self, decision: int, reason: str) -> None: ...

    def tally(self) -> tuple[int, int]: ...

    @property
    def decisions(self) -> list[LoopDecision]: ...

    @property
    def proposed(self) -> int: ...


class Recognizer(Protocol):
    """The place database interface the detector uses (`raplace.retrieval.PlaceRecognizer`)."""

    def add(self, descriptor: NDArray, key: int, time_s: float | None = None) -> None: ...

    def query(
        self, descriptor: NDArray, k: int = 1, time_s: float | None = None
    ) -> list[Candidate]: ...


@dataclass
class _Track:
    """The detector's running state over the scans fed so far."""

    count: int = 0
    last_key: int | None = None
    last_time_ns: int | None = None
    last_pose: FloatArray | None = None
    path_m: float = 0.0
    path_at_last_entry_m: float = -np.inf
    with_poses: bool | None = None


@dataclass(frozen=True)
class _Entry:
    """What the detector keeps per database scan (the scan itself only without a loader)."""

    key: int
    timestamp_ns: int
    pose: FloatArray | None
    path_m: float
    twist: FloatArray | None
    scan: Scan | None


class LoopDetector:
    """Verified radar loop closures from a stream of scans (and optionally their poses).

    Usable on its own (no radar_slam graph needed): feed every scan in time order with `add`;
    each call returns the loop constraints accepted by it (T_query_match with covariance, keys
    = the scans' keys), ready for `radar_slam.graph.add_loop_factors` or any back end. Call
    `finish()` after the last scan.

    Args:
        config: loop-closing settings (defaults when None).
        scan_loader: returns the scan of a key again when it is needed for verification; without
            it the detector keeps every database scan in memory (about 1.3 MB per MulRan scan).
        recognizer: the place database (default: RaPlace `PlaceRecognizer`).
        verifier: the geometric verifier (default: `GeometricVerifier`).

    Poses are the caller's odometry T_world_scan (3,) of each scan: with them, database entries
    are spaced by travelled distance, scans are de-skewed with the velocity they imply, and
    verified loops must be consistent with each other (`ConsistencyGate`); without them every
    verified loop is accepted. Give poses for every scan or for none.
    """

    def __init__(
        self,
        config: LoopClosureConfig | None = None,
        scan_loader: Callable[[int], Scan] | None = None,
        *,
        recognizer: Recognizer | None = None,
        verifier: Verifier | None = None,
    ) -> None:
        self.config = LoopClosureConfig() if config is None else config
        cfg = self.config
        self.scan_loader = scan_loader
        self.describe = DescriptorExtractor(cfg.raplace.descriptor)
        self.recognizer: Recognizer = (
            PlaceRecognizer(cfg.raplace.retrieval) if recognizer is None else recognizer
        )
        self.verifier: Verifier = GeometricVerifier(cfg) if verifier is None else verifier
        self.gate = ConsistencyGate(cfg.consistency)
        self._entries: dict[int, _Entry] = {}
        self._decisions: list[LoopDecision] = []
        self._tally: Counter[str] = Counter()
        self._track = _Track()
        self.proposed = 0

    # -- results ------------------------------------------------------------------------------
    @property
    def decisions(self) -> list[LoopDecision]:
        """Every verified proposal so far, in the order verified, with its current status."""
        return list(self._decisions)

    def tally(self) -> tuple[int, int]:
        """(accepted, rejected) decisions so far (cheap: kept up to date)."""
        return self._tally["accepted"], self._tally["rejected"]

    @property
    def accepted(self) -> list[LoopConstraint]:
        """The accepted loops as constraints."""
        return [d.constraint() for d in self._decisions if d.accepted]

    def __len__(self) -> int:
        """Number of database scans."""
        return len(self._entries)

    # -- the per-scan step --------------------------------------------------------------------
    def add(
        self, scan: Scan, pose: ArrayLike | None = None, key: int | None = None
    ) -> list[LoopConstraint]:
        """Feed the next scan (time order); returns the loops accepted by this call.

        Args:
            scan: the scan (any object with the `odometry.Scan` attributes).
            pose: (3,) odometry pose T_world_scan, or None (then for every scan).
            key: the scan's key in the loop constraints (default: number of scans fed before).

        Raises:
            LoopClosureError: poses given for some scans only, a key reused, or time going back.
        """
        track = self._track
        key = track.count if key is None else int(key)
        pose_arr = self._check(scan, pose, key)
        twist = self._advance(scan, pose_arr, key)
        changes: dict[int, LoopStatus] = {}
        if pose_arr is not None:
            changes.update(self.gate.expire(track.path_m))
        if track.path_m - track.path_at_last_entry_m >= self.config.query_spacing_m or (
            pose_arr is None
        ):
            track.path_at_last_entry_m = track.path_m
            changes.update(self._query_and_insert(scan, pose_arr, key, twist))
        return self._apply(changes)

    def finish(self) -> list[LoopConstraint]:
        """Resolve the loops still pending (rejected: no support); returns [] (for symmetry)."""
        return self._apply(self.gate.finish())

    def reject(self, decision: int, reason: str) -> None:
        """Mark an accepted loop as rejected afterwards (e.g. by the back end's GNC pass)."""
        self._record(decision, status="rejected", reason=reason)

    def _record(self, decision: int, **changes: object) -> LoopDecision:
        """Replace fields of decision `decision` (appended when new), keeping the tally."""
        if decision == len(self._decisions):
            new = LoopDecision(**changes)  # type: ignore[arg-type]
            self._decisions.append(new)
        else:
            self._tally[self._decisions[decision].status] -= 1
            new = dataclasses.replace(self._decisions[decision], **changes)  # type: ignore[arg-type]
            self._decisions[decision] = new
        self._tally[new.status] += 1
        return new

    # -- helpers ------------------------------------------------------------------------------
    def _check(self, scan: Scan, pose: ArrayLike | None, key: int) -> FloatArray | None:
        track = self._track
        with_pose = pose is not None
        if track.with_poses is not None and with_pose != track.with_poses:
            raise LoopClosureError(
                f"scan {key}: give a pose for every scan or for none (the first scan "
                f"{'had' if track.with_poses else 'had no'} pose)"
            )
        if track.last_key is not None and key <= track.last_key:
            raise LoopClosureError(
                f"scan key {key} does not follow the previous key {track.last_key} (keys increase)"
            )
        if track.last_time_ns is not None and int(scan.timestamp_ns) <= track.last_time_ns:
            raise LoopClosureError(
                f"scan {key} at {scan.timestamp_ns} ns is not later than the previous scan"
            )
        if pose is None:
            return None
        arr = np.asarray(pose, dtype=np.float64).reshape(-1)
        if arr.shape != (POSE_DIM,) or not np.all(np.isfinite(arr)):
            raise LoopClosureError(f"scan {key}: pose must be 3 finite numbers, got {pose!r}")
        return arr

    def _advance(self, scan: Scan, pose: FloatArray | None, key: int) -> FloatArray | None:
        """Update the running path and return the scan's body twist (None without poses)."""
        track = self._track
        twist = None
        if pose is not None and track.last_pose is not None and track.last_time_ns is not None:
            motion = between(track.last_pose, pose)
            track.path_m += float(np.hypot(motion[0], motion[1]))
            dt_s = (int(scan.timestamp_ns) - track.last_time_ns) / NS_PER_S
            twist = twist_from_motion(motion, dt_s)
        previous = self._entries.get(track.last_key) if track.last_key is not None else None
        if twist is not None and previous is not None and previous.twist is None:
            # The first scan had no velocity yet: de-skew it with the one that follows.
            self._entries[previous.key] = dataclasses.replace(previous, twist=twist)
        track.with_poses = pose is not None
        track.last_pose = pose
        track.last_time_ns = int(scan.timestamp_ns)
        track.last_key = key
        track.count += 1
        return twist

    def _scan_of(self, entry: _Entry) -> Scan:
        if entry.scan is not None:
            return entry.scan
        assert self.scan_loader is not None
        return self.scan_loader(entry.key)

    def _query_and_insert(
        self, scan: Scan, pose: FloatArray | None, key: int, twist: FloatArray | None
    ) -> dict[int, LoopStatus]:
        cfg = self.config
        time_s = int(scan.timestamp_ns) / NS_PER_S
        descriptor = self.describe(scan.polar, scan.azimuths_rad, scan.range_resolution_m)
        candidates = [
            c
            for c in self.recognizer.query(descriptor, cfg.candidates, time_s)
            if c.distance < cfg.max_descriptor_distance and c.key in self._entries
        ]
        self.recognizer.add(descriptor, key, time_s)
        entry = _Entry(
            key=key,
            timestamp_ns=int(scan.timestamp_ns),
            pose=pose,
            path_m=self._track.path_m,
            twist=twist,
            scan=None if self.scan_loader is not None else scan,
        )
        self._entries[key] = entry
        self.proposed += len(candidates)
        query = KeyScan(key, entry.timestamp_ns, scan, twist)
        changes: dict[int, LoopStatus] = {}
        passed = 0
        for candidate in candidates:  # at most `candidates` (k), best first
            match = self._entries[candidate.key]
            result = self.verifier(
                query, KeyScan(match.key, match.timestamp_ns, self._scan_of(match), match.twist)
            )
            decision = len(self._decisions)
            self._record(
                decision,
                query_key=key,
                match_key=match.key,
                query_ns=entry.timestamp_ns,
                match_ns=match.timestamp_ns,
                distance=candidate.distance,
                measurement=np.asarray(result.measurement, dtype=np.float64),
                covariance=np.asarray(result.covariance, dtype=np.float64),
                sinogram_quality=result.sinogram_quality,
                refined_quality=result.refined_quality,
                status="rejected" if not result.ok else "pending",
                reason=result.reason,
            )
            log.debug(
                "loop %d -> %d (distance %.3f): %s",
                key,
                match.key,
                candidate.distance,
                result.reason or "verified",
            )
            if not result.ok:
                continue
            passed += 1
            if pose is None or match.pose is None:
                changes[decision] = "accepted"
                self.gate.reasons[decision] = "accepted (no poses: consistency not checked)"
            else:
                changes.update(
                    self.gate.add(
                        VerifiedLoop(
                            decision=decision,
                            query_key=key,
                            match_key=match.key,
                            measurement=result.measurement,
                            covariance=result.covariance,
                            query_pose=pose,
                            match_pose=match.pose,
                            query_path_m=entry.path_m,
                            match_path_m=match.path_m,
                        )
                    )
                )
            if passed >= cfg.loops_per_query:
                break
        return changes

    def _apply(self, changes: dict[int, LoopStatus]) -> list[LoopConstraint]:
        """Record status changes; return the newly accepted loops as constraints."""
        accepted = []
        for decision, status in sorted(changes.items()):
            new = self._record(decision, status=status, reason=self.gate.reasons[decision])
            if status == "accepted":
                accepted.append(new.constraint())
        return accepted


class NullLoopDetector:
    """A loop detector that never finds a loop (loop closing disabled)."""

    def __init__(self, config: LoopClosureConfig | None = None) -> None:
        self.config = LoopClosureConfig(enabled=False) if config is None else config
        self.proposed = 0

    @property
    def decisions(self) -> list[LoopDecision]:
        return []

    def tally(self) -> tuple[int, int]:
        return 0, 0

    def add(
        self, scan: Scan, pose: ArrayLike | None = None, key: int | None = None
    ) -> list[LoopConstraint]:
        return []

    def finish(self) -> list[LoopConstraint]:
        return []

    def reject(self, decision: int, reason: str) -> None:
        raise LoopClosureError(f"no loop decision {decision}: loop closing is disabled")


def make_loop_detector(
    config: LoopClosureConfig, scan_loader: Callable[[int], Scan] | None = None
) -> LoopDetector | NullLoopDetector:
    """The configured detector: `LoopDetector`, or `NullLoopDetector` when disabled."""
    if not config.enabled:
        return NullLoopDetector(config)
    return LoopDetector(config, scan_loader)
