"""Trajectory accuracy: ATE (aligned and first-pose aligned), RPE, and KITTI-style drift.

ATE and RPE are computed with evo (`evo.core.metrics.APE` / `RPE`, translation part, RMSE);
evo has no KITTI segment drift, so `kitti_drift` implements the KITTI odometry devkit's metric.

Conventions:
- Both trajectories are SE(2) `Trajectory` objects (T_world_radar, x/y [m], yaw [rad]); evo sees
  them as planar SE(3) trajectories (z = 0, rotation about z).
- `associate` pairs estimate and ground-truth poses by timestamp (nearest within a tolerance) or
  by index (KITTI files carry no time); every other metric takes associated trajectories.
- Rigid alignment is Umeyama without scale, and stays in SE(2): evo's 3-D Umeyama may answer a
  mirrored or collinear planar trajectory with a rotation about an in-plane axis (a flip that
  hides the error) or fail; we check its result and otherwise solve the 2-D problem, also with
  evo's `umeyama_alignment`.

evo loads on first use (`EVO_MODULES`), not with this module: a run evaluates at its end only,
and `radar-slam run` loads it on a thread while the scans go by.
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import NDArray

from radar_slam.errors import TrajectoryError
from radar_slam.trajectory import Trajectory
from raplace import NS_PER_MS, between, compose, inverse, wrap_angle

if TYPE_CHECKING:
    from evo.core.trajectory import PoseTrajectory3D

logger = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
Association = Literal["timestamp", "index"]
Alignment = Literal["umeyama", "origin", "none"]
DeltaUnit = Literal["frames", "m"]

DEFAULT_MAX_TIME_DIFF_NS = 1_000_000  # 1 ms: association tolerance by timestamp
EVO_MODULES = ("evo.core.metrics", "evo.core.trajectory", "evo.core.geometry")
"""The evo modules the metrics use (imported on first use)."""
DEFAULT_RPE_DELTA = 1  # frames
KITTI_SEGMENT_LENGTHS_M = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0)
KITTI_START_STEP_FRAMES = 10  # the devkit starts a segment every 10 frames
GT_ERROR_SHARE_OF_DRIFT = 0.005
"""Drift uses only segments long enough that the GT's own error is at most 0.5 % of them: with
metre-level GNSS (2 m) that is 400 m and up; with centimetre GT every KITTI length."""
PERCENT = 100.0
PER_100_M = 100.0
PLANAR_TOLERANCE = 1e-9  # max |off-plane entry| of an alignment rotation/translation
MIN_POSES = 2


# ---------------------------------------------------------------------- association
def associate(
    est: Trajectory,
    gt: Trajectory,
    by: Association = "timestamp",
    max_diff_ns: int = DEFAULT_MAX_TIME_DIFF_NS,
) -> tuple[Trajectory, Trajectory]:
    """Pair estimate and ground-truth poses; returns (est, gt) of equal length.

    by="timestamp": each estimate pose takes the nearest GT timestamp within `max_diff_ns`
    (one-to-one: a GT pose claimed twice keeps its closest estimate); unmatched poses are dropped.
    by="index": pose k with pose k; the counts must match.
    Raises TrajectoryError when nothing matches or the KITTI counts differ.
    """
    if by == "index":
        if len(est) != len(gt):
            raise TrajectoryError(
                f"association by index needs equal pose counts: estimate has {len(est)}, "
                f"ground truth has {len(gt)}"
            )
        return est, gt
    if by != "timestamp":
        raise TrajectoryError(f"unknown association {by!r}; expected 'timestamp' or 'index'")
    if len(est) == 0 or len(gt) == 0:
        raise TrajectoryError("cannot associate an empty trajectory")
    t_est, t_gt = est.timestamps_ns, gt.timestamps_ns
    right = np.clip(np.searchsorted(t_gt, t_est), 1, len(t_gt) - 1) if len(t_gt) > 1 else None
    if right is None:
        nearest = np.zeros(len(t_est), dtype=np.int64)
    else:
        left = right - 1
        take_left = np.abs(t_est - t_gt[left]) <= np.abs(t_gt[right] - t_est)
        nearest = np.where(take_left, left, right)
    diff = np.abs(t_gt[nearest] - t_est)
    est_idx = np.flatnonzero(diff <= max_diff_ns)
    # one-to-one: for each GT index keep the estimate with the smallest time difference
    order = est_idx[np.lexsort((diff[est_idx], nearest[est_idx]))]
    _, first = np.unique(nearest[order], return_index=True)
    est_idx = np.sort(order[first])
    if len(est_idx) == 0:
        raise TrajectoryError(
            f"no common poses: no estimate timestamp is within {max_diff_ns / NS_PER_MS:g} ms of a "
            f"ground-truth timestamp (estimate {t_est[0]}..{t_est[-1]} ns, "
            f"ground truth {t_gt[0]}..{t_gt[-1]} ns)"
        )
    if len(est_idx) < len(est):
        logger.info("associated %d of %d estimate poses with GT", len(est_idx), len(est))
    return est[est_idx], gt[nearest[est_idx]]


# ---------------------------------------------------------------------- evo bridge
def to_evo(traj: Trajectory) -> PoseTrajectory3D:
    """The trajectory as an evo planar PoseTrajectory3D (z = 0, timestamps in float seconds).

    Built from SE(3) matrices, vectorised (evo converting quaternions one by one is slow).
    """
    from evo.core.trajectory import PoseTrajectory3D

    x, y, yaw = traj.poses.T
    c, s = np.cos(yaw), np.sin(yaw)
    mats = np.zeros((len(traj), 4, 4))
    mats[:, 0, 0], mats[:, 0, 1], mats[:, 0, 3] = c, -s, x
    mats[:, 1, 0], mats[:, 1, 1], mats[:, 1, 3] = s, c, y
    mats[:, 2, 2] = mats[:, 3, 3] = 1.0
    return PoseTrajectory3D(poses_se3=list(mats), timestamps=traj.timestamps_s)


def _se2_from_rotation_translation(rotation: FloatArray, translation: FloatArray) -> FloatArray:
    """(x, y, yaw) of a planar transform given as a 3x3 (or 2x2) rotation and a translation."""
    return np.array([translation[0], translation[1], np.arctan2(rotation[1, 0], rotation[0, 0])])


def _is_planar(rotation: FloatArray, translation: FloatArray) -> bool:
    """True when a 3-D rigid transform is a rotation about z plus an in-plane translation."""
    off_plane = np.concatenate([rotation[:2, 2], rotation[2, :2], [translation[2]]])
    return bool(
        np.max(np.abs(off_plane)) < PLANAR_TOLERANCE
        and abs(rotation[2, 2] - 1.0) < PLANAR_TOLERANCE
    )


# ---------------------------------------------------------------------- alignment
def umeyama_alignment_se2(est: Trajectory, gt: Trajectory) -> FloatArray:
    """The SE(2) transform T_gt_est (x, y, yaw) minimising the position error, without scale.

    First evo's `traj.align(ref, correct_scale=False)`; if its 3-D rotation leaves the plane
    (a mirrored trajectory is "fixed" by flipping it over) or evo reports a degenerate problem
    (collinear points), the 2-D Umeyama problem is solved with evo's `umeyama_alignment` on the
    (x, y) rows, whose reflection guard keeps a proper rotation about z. If even that is
    degenerate (all positions equal), only the centroids are aligned.
    """
    from evo import EvoException
    from evo.core import geometry

    if len(est) != len(gt):
        raise TrajectoryError("alignment needs associated trajectories of equal length")
    evo_est = to_evo(est)
    try:
        rotation, translation, _ = evo_est.align(to_evo(gt), correct_scale=False)
        if _is_planar(rotation, translation):
            return _se2_from_rotation_translation(rotation, translation)
        logger.info("evo's 3-D Umeyama left the plane; solving the 2-D alignment instead")
    except EvoException as exc:
        logger.info("evo's 3-D Umeyama failed (%s); solving the 2-D alignment instead", exc)
    try:
        rotation, translation, _ = geometry.umeyama_alignment(
            est.positions.T.copy(), gt.positions.T.copy(), False
        )
    except EvoException:
        logger.warning("degenerate alignment (positions all equal); aligning centroids only")
        shift = gt.positions.mean(axis=0) - est.positions.mean(axis=0)
        return np.array([shift[0], shift[1], 0.0])
    return _se2_from_rotation_translation(rotation, translation)


def align(est: Trajectory, gt: Trajectory, method: Alignment = "umeyama") -> Trajectory:
    """The estimate moved rigidly onto associated `gt`: Umeyama (SE(2), no scale), first pose
    (`est[0]` onto `gt[0]`), or unchanged ("none")."""
    if method == "none":
        return est
    if method == "umeyama":
        transform = umeyama_alignment_se2(est, gt)
    elif method == "origin":
        if len(est) == 0 or len(gt) == 0:
            raise TrajectoryError("cannot align an empty trajectory")
        transform = compose(gt.poses[0], inverse(est.poses[0]))
    else:
        raise TrajectoryError(f"unknown alignment {method!r}")
    return Trajectory(est.timestamps_ns, compose(transform, est.poses))


# ---------------------------------------------------------------------- metrics
def _require_pairs(est: Trajectory, gt: Trajectory, minimum: int = MIN_POSES) -> None:
    if len(est) != len(gt):
        raise TrajectoryError(
            f"trajectories are not associated ({len(est)} vs {len(gt)} poses); call associate()"
        )
    if len(est) < minimum:
        raise TrajectoryError(f"need at least {minimum} associated poses, got {len(est)}")


def ate_rmse(est: Trajectory, gt: Trajectory, alignment: Alignment = "umeyama") -> float:
    """Absolute trajectory error RMSE [m] of the translation after `alignment` (evo APE)."""
    from evo.core.metrics import APE, PoseRelation, StatisticsType

    _require_pairs(est, gt, minimum=1)
    aligned = align(est, gt, alignment)
    ape = APE(PoseRelation.translation_part)
    ape.process_data((to_evo(gt), to_evo(aligned)))
    return float(ape.get_statistic(StatisticsType.rmse))


def ate_origin_rmse(est: Trajectory, gt: Trajectory) -> float:
    """ATE RMSE [m] after aligning only the first pose, with evo's `align_origin`.

    This is the convention of the radar odometry papers, so our numbers compare with theirs.
    """
    from evo.core.metrics import APE, PoseRelation, StatisticsType

    _require_pairs(est, gt, minimum=1)
    evo_est, evo_gt = to_evo(est), to_evo(gt)
    evo_est.align_origin(evo_gt)
    ape = APE(PoseRelation.translation_part)
    ape.process_data((evo_gt, evo_est))
    return float(ape.get_statistic(StatisticsType.rmse))


def rpe_trans_rmse(
    est: Trajectory,
    gt: Trajectory,
    delta: float = DEFAULT_RPE_DELTA,
    unit: DeltaUnit = "frames",
) -> float:
    """Relative pose error RMSE [m] of the translation part over pose pairs `delta` apart (evo).

    unit="frames": pairs (i, i + delta) for every i. unit="m": consecutive pairs about `delta`
    metres apart along the ground-truth path (evo's default 10 % tolerance).
    """
    from evo import EvoException
    from evo.core.metrics import RPE, PoseRelation, StatisticsType, Unit

    _require_pairs(est, gt)
    delta_unit = Unit.frames if unit == "frames" else Unit.meters
    try:
        rpe = RPE(
            PoseRelation.translation_part,
            delta=delta,
            delta_unit=delta_unit,
            pairs_from_reference=True,
        )
        rpe.process_data((to_evo(gt), to_evo(est)))
        if rpe.error.size == 0:
            raise TrajectoryError(f"no pose pairs {delta:g} {unit} apart for the RPE")
        return float(rpe.get_statistic(StatisticsType.rmse))
    except EvoException as exc:
        raise TrajectoryError(f"RPE with delta {delta:g} {unit}: {exc}") from exc


@dataclass(frozen=True)
class KittiDrift:
    """KITTI odometry drift averaged over all segments.

    trans_pct: mean translation error per segment length [%].
    rot_deg_per_100m: mean rotation error per segment length [deg / 100 m].
    segments: number of (start frame, length) segments averaged.
    """

    trans_pct: float
    rot_deg_per_100m: float
    segments: int


def drift_lengths_m(gt_accuracy_m: float = 0.0) -> tuple[float, ...]:
    """The KITTI segment lengths a GT of this accuracy [m] can score (see
    `GT_ERROR_SHARE_OF_DRIFT`); at least the longest one."""
    shortest = gt_accuracy_m / GT_ERROR_SHARE_OF_DRIFT
    kept = tuple(length for length in KITTI_SEGMENT_LENGTHS_M if length >= shortest)
    return kept or KITTI_SEGMENT_LENGTHS_M[-1:]


def kitti_drift(
    est: Trajectory,
    gt: Trajectory,
    lengths_m: tuple[float, ...] = KITTI_SEGMENT_LENGTHS_M,
    start_step: int = KITTI_START_STEP_FRAMES,
) -> KittiDrift | None:
    """KITTI devkit drift of associated trajectories, or None when no segment fits.

    For each start frame s in 0, start_step, 2 start_step, ... and each length L, the segment ends
    at the first frame e whose ground-truth path distance from s is >= L. The error pose is
    (T_est_s^-1 T_est_e)^-1 (T_gt_s^-1 T_gt_e); its translation norm / L and its rotation angle / L
    are averaged over all segments of all lengths (the devkit's overall figure). Path distances
    come from the ground truth. (The devkit's C++ tests dist > L; >= makes a segment of exactly
    L metres count, which only matters for synthetic trajectories with round step lengths.)
    """
    _require_pairs(est, gt)
    dist = gt.path_distances_m()
    starts = np.arange(0, len(gt), start_step)
    trans_errors: list[FloatArray] = []
    rot_errors: list[FloatArray] = []
    for length in lengths_m:
        ends = np.searchsorted(dist, dist[starts] + length, side="left")
        valid = ends < len(gt)
        if not valid.any():
            continue
        s, e = starts[valid], ends[valid]
        rel_gt = between(gt.poses[s], gt.poses[e])
        rel_est = between(est.poses[s], est.poses[e])
        error = between(rel_est, rel_gt)
        trans_errors.append(np.linalg.norm(error[:, :2], axis=1) / length)
        rot_errors.append(np.abs(wrap_angle(error[:, 2])) / length)
    if not trans_errors:
        logger.info(
            "KITTI drift undefined: the ground-truth path is %.1f m, shorter than the shortest "
            "segment (%.0f m)",
            dist[-1],
            min(lengths_m),
        )
        return None
    t_err, r_err = np.concatenate(trans_errors), np.concatenate(rot_errors)
    return KittiDrift(
        trans_pct=float(np.mean(t_err) * PERCENT),
        rot_deg_per_100m=float(np.degrees(np.mean(r_err)) * PER_100_M),
        segments=len(t_err),
    )


@dataclass(frozen=True)
class TrajectoryMetrics:
    """Accuracy of one estimate against ground truth.

    ate_rmse_m: ATE RMSE after SE(2) Umeyama alignment (no scale) [m].
    ate_origin_rmse_m: ATE RMSE after first-pose alignment [m] (radar odometry papers).
    rpe_trans_rmse_m: RPE translation RMSE [m] over the chosen delta (1 frame by default).
    drift_trans_pct, drift_rot_deg_per_100m: KITTI drift [%], [deg/100 m] over segments of
        `drift_min_segment_m` and longer; None when the path is shorter.
    poses_matched: number of associated poses.
    end_point_error_pct: distance between the last associated poses after the Umeyama
        alignment, per path length of the GT [%].
    drift_min_segment_m: the shortest KITTI segment the drift averages over [m] (longer for
        a less accurate GT, see `drift_lengths_m`).
    """

    ate_rmse_m: float
    ate_origin_rmse_m: float
    rpe_trans_rmse_m: float
    drift_trans_pct: float | None
    drift_rot_deg_per_100m: float | None
    poses_matched: int
    end_point_error_pct: float | None = None
    drift_min_segment_m: float = KITTI_SEGMENT_LENGTHS_M[0]

    def to_dict(self) -> dict[str, float | int | None]:
        """Flat JSON-ready dict with exactly the field names as keys."""
        return asdict(self)


def evaluate(
    est: Trajectory,
    gt: Trajectory,
    by: Association = "timestamp",
    max_diff_ns: int = DEFAULT_MAX_TIME_DIFF_NS,
    rpe_delta: float = DEFAULT_RPE_DELTA,
    rpe_unit: DeltaUnit = "frames",
    gt_accuracy_m: float = 0.0,
) -> TrajectoryMetrics:
    """Associate `est` with `gt` and compute every metric.

    A ground truth with NaN rows (scans outside the GT span) should be built with
    `Trajectory.from_arrays(t, poses, drop_nonfinite=True)`, which drops them. `gt_accuracy_m`
    (the GT's stated position accuracy) sets the shortest drift segment.
    """
    est_a, gt_a = associate(est, gt, by=by, max_diff_ns=max_diff_ns)
    _require_pairs(est_a, gt_a)
    lengths = drift_lengths_m(gt_accuracy_m)
    drift = kitti_drift(est_a, gt_a, lengths)
    return TrajectoryMetrics(
        ate_rmse_m=ate_rmse(est_a, gt_a, "umeyama"),
        ate_origin_rmse_m=ate_origin_rmse(est_a, gt_a),
        rpe_trans_rmse_m=rpe_trans_rmse(est_a, gt_a, rpe_delta, rpe_unit),
        drift_trans_pct=None if drift is None else drift.trans_pct,
        drift_rot_deg_per_100m=None if drift is None else drift.rot_deg_per_100m,
        poses_matched=len(est_a),
        end_point_error_pct=end_point_error_pct(est_a, gt_a),
        drift_min_segment_m=lengths[0],
    )


def end_point_error_pct(est: Trajectory, gt: Trajectory) -> float | None:
    """Distance between the last poses of associated trajectories after the SE(2) Umeyama
    alignment, per path length of the GT [%]; None for a GT path of zero length."""
    length = gt.length_m()
    if length <= 0:
        return None
    aligned = align(est, gt, "umeyama")
    gap = aligned.poses[-1, :2] - gt.poses[-1, :2]
    return float(np.hypot(gap[0], gap[1]) / length * PERCENT)
