"""Steps shared by the runners: frame counts, ground truth, accuracy, odometry factors, loops."""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
from numpy.typing import NDArray

from odometry import OdometryResult
from radar_slam.datasets.frame import RadarSequence
from radar_slam.errors import RadarSlamError, TrajectoryError
from radar_slam.evaluation.gt_report import GroundTruthReport, ground_truth_report
from radar_slam.evaluation.metrics import TrajectoryMetrics, evaluate
from radar_slam.graph import PoseGraph
from radar_slam.loops import (
    LoopDecision,
    LoopDetectorProtocol,
)
from radar_slam.pipeline.records import (
    SlamMetrics,
)
from radar_slam.trajectory import Trajectory
from raplace import rotate_covariance

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]


BACKEND_REJECT_WEIGHT = 0.5
"""An accepted loop whose weight after the final pass is below this counts as rejected there."""


class StepTimer:
    """Accumulated wall time per named step [s], and the CPU time of the thread that ran it
    (`cpu_seconds` [s]: what a shared, busy machine distorts least)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self.cpu_seconds: dict[str, float] = {}

    @contextmanager
    def __call__(self, step: str) -> Iterator[None]:
        start, start_cpu = time.perf_counter(), time.thread_time()
        try:
            yield
        finally:
            self.seconds[step] = self.seconds.get(step, 0.0) + time.perf_counter() - start
            cpu = time.thread_time() - start_cpu
            self.cpu_seconds[step] = self.cpu_seconds.get(step, 0.0) + cpu


def frame_count(sequence: RadarSequence, max_frames: int | None) -> int:
    """Scans to process: all, or the first `max_frames`."""
    if max_frames is not None and max_frames < 1:
        raise RadarSlamError(f"max_frames must be at least 1, got {max_frames}")
    n = len(sequence)
    return n if max_frames is None else min(n, max_frames)


def sequence_label(sequence: RadarSequence) -> str:
    return f"{sequence.family}/{sequence.name}"


def ground_truth_of(
    sequence: RadarSequence, frames: int
) -> tuple[FloatArray | None, Trajectory | None]:
    """((frames, 3) GT with NaN rows, the GT trajectory without them) or (None, None)."""
    gt = sequence.ground_truth
    if gt is None:
        return None, None
    poses = np.asarray(gt, dtype=np.float64)[:frames]
    stamps = np.asarray(sequence.timestamps_ns)[:frames]
    trajectory = Trajectory.from_arrays(stamps, poses, drop_nonfinite=True)
    return poses, (trajectory if len(trajectory) else None)


def gt_accuracy_m(sequence: RadarSequence) -> float:
    """The stated accuracy of the sequence's GT [m] (0 when not stated)."""
    source = sequence.ground_truth_source
    return 0.0 if source is None else source.accuracy_m


def accuracy(
    est: Trajectory, gt: Trajectory | None, gt_accuracy: float = 0.0
) -> TrajectoryMetrics | None:
    """`metrics.evaluate` or None when there is no ground truth or too little of it."""
    if gt is None:
        return None
    try:
        return evaluate(est, gt, gt_accuracy_m=gt_accuracy)
    except TrajectoryError as exc:
        log.warning("no accuracy figures: %s", exc)
        return None


def gt_report_of(
    sequence: RadarSequence, gt: Trajectory | None, trajectories: dict[str, Trajectory]
) -> GroundTruthReport | None:
    """The GT's source and clock offset behind a run's metrics; None without GT."""
    if gt is None:
        return None
    return ground_truth_report(sequence.ground_truth_source, gt, trajectories)


def odometry_factor(result: OdometryResult) -> tuple[FloatArray, FloatArray]:
    """(measurement T_previous_scan, covariance in GTSAM's tangent) of a scan's odometry factor.

    The odometry reports the motion from the previous scan with the covariance of the
    registration that produced it (in the previous scan's axes; a gap's is large); GTSAM
    perturbs a between-factor in the frame of its second pose, so the covariance is turned by
    the motion's rotation.
    """
    return result.motion, rotate_covariance(result.covariance, -float(result.motion[2]))


def review_loops(
    graph: PoseGraph,
    loop_ids: dict[tuple[int, int], int],
    detector: LoopDetectorProtocol,
) -> int:
    """Mark the accepted loops whose weight after the final pass is below
    `BACKEND_REJECT_WEIGHT` as rejected by it; returns how many.

    Args:
        graph: the optimised graph.
        loop_ids: (query key, match key) -> the loop's id in `graph`.
        detector: the detector whose decisions are updated.
    """
    weights = graph.loop_weights()
    rejected = 0
    for n, decision in enumerate(detector.decisions):
        loop_id = loop_ids.get((decision.query_key, decision.match_key))
        weight = weights.get(loop_id, 1.0) if loop_id is not None else 1.0
        if decision.accepted and weight < BACKEND_REJECT_WEIGHT:
            detector.reject(
                n, f"rejected by the final {graph.config.final_pass} pass (weight {weight:.2f})"
            )
            rejected += 1
    return rejected


def summarise(
    *,
    frames: int,
    seconds: float,
    gaps: int,
    candidates: int,
    loops: list[LoopDecision],
    true_loops: list[bool | None],
    odometry: TrajectoryMetrics | None,
    slam: TrajectoryMetrics | None,
) -> SlamMetrics:
    """The `SlamMetrics` of a run (pure)."""
    accepted = [n for n, d in enumerate(loops) if d.accepted]
    known = [true_loops[n] for n in accepted]
    accepted_true = None if any(t is None for t in known) else sum(bool(t) for t in known)
    if not loops:
        accepted_true = 0 if odometry is not None else None
    reduction = None
    if odometry is not None and slam is not None and odometry.ate_rmse_m > 0:
        reduction = 1.0 - slam.ate_rmse_m / odometry.ate_rmse_m
    return SlamMetrics(
        frames=frames,
        seconds=seconds,
        frames_per_second=frames / seconds if seconds > 0 else 0.0,
        odometry_gaps=gaps,
        loops_candidates=candidates,
        loops_proposed=len(loops),
        loops_accepted=len(accepted),
        loops_rejected=len(loops) - len(accepted),
        loops_accepted_true=accepted_true,
        ate_odometry_m=None if odometry is None else odometry.ate_rmse_m,
        ate_slam_m=None if slam is None else slam.ate_rmse_m,
        ate_reduction=reduction,
        ate_origin_odometry_m=None if odometry is None else odometry.ate_origin_rmse_m,
        ate_origin_slam_m=None if slam is None else slam.ate_origin_rmse_m,
        drift_odometry_pct=None if odometry is None else odometry.drift_trans_pct,
        drift_slam_pct=None if slam is None else slam.drift_trans_pct,
        drift_odometry_deg_per_100m=None if odometry is None else odometry.drift_rot_deg_per_100m,
        drift_slam_deg_per_100m=None if slam is None else slam.drift_rot_deg_per_100m,
        end_point_odometry_pct=None if odometry is None else odometry.end_point_error_pct,
        end_point_slam_pct=None if slam is None else slam.end_point_error_pct,
        scans_with_gt=None if odometry is None else odometry.poses_matched,
        scans_without_gt=None if odometry is None else frames - odometry.poses_matched,
    )
