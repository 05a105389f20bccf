"""What the runners report: progress, and the results of a SLAM, odometry-only or graph run."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from odometry import OdometryResult
from radar_slam.evaluation.gt_report import GroundTruthReport
from radar_slam.evaluation.metrics import TrajectoryMetrics
from radar_slam.graph import PoseGraph
from radar_slam.loops import (
    LoopDecision,
)
from radar_slam.maps.keyframes import RecordedKeyframes
from radar_slam.pipeline.config import PipelineConfig
from radar_slam.trajectory import Trajectory

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Progress:
    """State reported to the progress callback after each scan.

    Attributes:
        done: scans processed.
        total: scans to process.
        loops_accepted: loops accepted so far.
        loops_rejected: verified proposals rejected so far.
        elapsed_s: wall time since the start [s].
        step: what the run does after its last scan ("last loops", "optimisation",
            "evaluation"); empty while it processes scans.
    """

    done: int
    total: int
    loops_accepted: int
    loops_rejected: int
    elapsed_s: float
    step: str = ""


ProgressCallback = Callable[[Progress], None]


@dataclass(frozen=True)
class SlamMetrics:
    """The machine-readable summary of a run (metrics.json).

    ATEs are RMSE after SE(2) Umeyama alignment (`ate_*_m`) and after first-pose alignment
    (`ate_origin_*_m`) [m]; drifts are KITTI-style mean translation errors over 100..800 m
    segments [%] and rotation errors [deg/100 m]; `ate_reduction` = 1 - ate_slam / ate_odometry.
    Fields needing ground truth are None without it (drift also below 100 m of path).
    `scans_with_gt` is how many scans the accuracy figures were computed over, and
    `scans_without_gt` how many had no ground truth (outside its time span or in an outage).
    `end_point_*_pct` is the last pose's error after the alignment per path length [%].
    """

    frames: int
    seconds: float
    frames_per_second: float
    odometry_gaps: int
    loops_candidates: int
    loops_proposed: int
    loops_accepted: int
    loops_rejected: int
    loops_accepted_true: int | None
    ate_odometry_m: float | None
    ate_slam_m: float | None
    ate_reduction: float | None
    ate_origin_odometry_m: float | None
    ate_origin_slam_m: float | None
    drift_odometry_pct: float | None
    drift_slam_pct: float | None
    drift_odometry_deg_per_100m: float | None
    drift_slam_deg_per_100m: float | None
    scans_with_gt: int | None = None
    scans_without_gt: int | None = None
    end_point_odometry_pct: float | None = None
    end_point_slam_pct: float | None = None

    def to_dict(self) -> dict[str, float | int | None]:
        return asdict(self)


@dataclass(frozen=True)
class Results:
    """Everything a SLAM run produced.

    Attributes:
        sequence: the sequence's `family/name`.
        config: the settings used.
        odometry: odometry trajectory, one pose per scan (T_world_radar, first scan at origin).
        slam: optimised trajectory, one pose per scan, same timestamps.
        ground_truth: ground truth at the scans with a known pose (NaN rows dropped), or None.
        ground_truth_poses: (frames, 3) ground truth per scan with NaN rows, or None.
        odometry_results: the odometry's per-scan results, revised (the graph's odometry factors).
        loops: every verified loop proposal with its final status and reason.
        true_loops: per loop, whether it is true (`evaluation.truth.is_true_loop`), None without GT.
        graph: the final pose graph (estimates = slam).
        timings_s: wall time per pipeline step [s].
        metrics: the summary metrics.
        odometry_metrics, slam_metrics: full accuracy figures, None without ground truth.
        gt_report: the GT's source and estimated clock offset, with the metrics through that
            offset; None without ground truth.
        map_keyframes: the map keyframes made during the run (`radar_slam.maps.keyframes`), so
            that the map is written without reading a scan again; None unless the run was asked
            to keep them (`Pipeline(record_map=True)`).
    """

    sequence: str
    config: PipelineConfig
    odometry: Trajectory
    slam: Trajectory
    ground_truth: Trajectory | None
    ground_truth_poses: FloatArray | None
    odometry_results: list[OdometryResult]
    loops: list[LoopDecision]
    true_loops: list[bool | None]
    graph: PoseGraph
    timings_s: dict[str, float]
    metrics: SlamMetrics
    odometry_metrics: TrajectoryMetrics | None
    slam_metrics: TrajectoryMetrics | None
    gt_report: GroundTruthReport | None = None
    map_keyframes: RecordedKeyframes | None = None

    @property
    def accepted_loops(self) -> list[LoopDecision]:
        return [d for d in self.loops if d.accepted]


@dataclass(frozen=True)
class OdometryRun:
    """What `run_odometry` produced.

    Attributes:
        sequence: `family/name`.
        config: the settings (only `odometry` was used).
        trajectory: one pose per scan at the scan's timestamp.
        ground_truth: GT trajectory (NaN rows dropped) or None.
        results: the odometry's per-scan results.
        seconds: wall time [s].
        metrics: accuracy against GT, None without it.
        gt_report: the GT's source and estimated clock offset, None without GT.
    """

    sequence: str
    config: PipelineConfig
    trajectory: Trajectory
    ground_truth: Trajectory | None
    results: list[OdometryResult]
    seconds: float
    metrics: TrajectoryMetrics | None
    gt_report: GroundTruthReport | None = None

    def summary(self) -> dict[str, Any]:
        """metrics.json content: counts, speed, and the accuracy fields when there is GT."""
        frames = len(self.trajectory)
        data: dict[str, Any] = {
            "frames": frames,
            "seconds": self.seconds,
            "frames_per_second": frames / self.seconds if self.seconds > 0 else 0.0,
            "odometry_gaps": sum(r.gap for r in self.results),
            "keyframes": sum(r.is_keyframe for r in self.results),
            # image registrations per scan after the first, as the odometry counted them
            "registrations_per_scan": (
                sum(r.registrations for r in self.results[1:]) / (len(self.results) - 1)
                if len(self.results) > 1
                else 0.0
            ),
        }
        if self.metrics is not None:
            data.update(self.metrics.to_dict())
            data["scans_with_gt"] = self.metrics.poses_matched
            data["scans_without_gt"] = frames - self.metrics.poses_matched
        if self.gt_report is not None:
            data["ground_truth"] = self.gt_report.to_dict()
        return data


@dataclass(frozen=True)
class GraphLoopsRun:
    """What `close_loops_on_graph` produced.

    Attributes:
        graph: the input graph with the accepted loops added, optimised.
        loops: every verified proposal with its status.
        seconds: wall time [s].
        input_loops: edges of the input graph between non-consecutive vertices.
        input_loops_left_out: of those, the ones left out as grossly inconsistent with the
            odometry (each named in a warning).
    """

    graph: PoseGraph
    loops: list[LoopDecision]
    seconds: float
    input_loops: int = 0
    input_loops_left_out: int = 0

    @property
    def n_accepted(self) -> int:
        """Number of accepted loops."""
        return sum(d.accepted for d in self.loops)
