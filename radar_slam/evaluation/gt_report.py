"""What a run's accuracy figures rest on: the GT's source and accuracy, and its clock offset.

A run scores its trajectories against the GT as stamped (the figures of `metrics.json`). This
report adds what a user needs to judge them: where the GT comes from and how accurate it is,
the clock offset estimated from the odometry's speed profile (`time_offset`), and the same
metrics with that offset applied, labelled as such.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np

from radar_slam.datasets.frame import GroundTruthSource
from radar_slam.errors import TrajectoryError
from radar_slam.evaluation.metrics import TrajectoryMetrics, evaluate
from radar_slam.evaluation.time_offset import (
    TimeOffset,
    estimate_time_offset,
    ground_truth_with_offset,
)
from radar_slam.trajectory import Trajectory

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class GroundTruthReport:
    """The GT behind a run's metrics.

    Attributes:
        source: what the GT is and its stated accuracy (None: not stated by the loader).
        time_offset: GT clock minus radar clock estimated from the odometry, None when the
            drive gives no speed profile to match (short, or constant speed).
        offset_applied: per trajectory name ("odometry", "slam"), the metrics against the GT
            read through `time_offset` (empty without an estimate).
    """

    source: GroundTruthSource | None
    time_offset: TimeOffset | None
    offset_applied: dict[str, TrajectoryMetrics]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: {"source", "accuracy_m", "notes", "time_offset", "offset_applied"}."""
        data: dict[str, Any] = {}
        if self.source is not None:
            data.update(
                source=self.source.description,
                accuracy_m=self.source.accuracy_m,
                notes=dict(self.source.notes),
            )
        data["time_offset"] = None if self.time_offset is None else self.time_offset.to_dict()
        data["offset_applied"] = {k: v.to_dict() for k, v in self.offset_applied.items()}
        return data

    def summary_lines(self) -> list[str]:
        """Lines for summary.txt."""
        lines = []
        if self.source is not None:
            lines.append(
                f"GT source     {self.source.description} (accuracy {self.source.accuracy_m:g} m)"
            )
        offset = self.time_offset
        if offset is None:
            lines.append("GT clock      offset not estimated (too little speed variation)")
            return lines
        lines.append(
            f"GT clock      offset {offset.offset_s:+.3f} +- {offset.sigma_s:.3f} s "
            f"(GT minus radar, from the speed profiles; correlation {offset.correlation:.2f})"
        )
        for name, m in self.offset_applied.items():
            end = "n/a" if m.end_point_error_pct is None else f"{m.end_point_error_pct:.2f} %"
            lines.append(
                f"  offset applied: {name} ATE {m.ate_rmse_m:.3f} m, end point {end} "
                f"of the distance, over {m.poses_matched} scans"
            )
        return lines


def ground_truth_report(
    source: GroundTruthSource | None,
    ground_truth: Trajectory,
    trajectories: dict[str, Trajectory],
) -> GroundTruthReport:
    """Estimate the GT's clock offset from `trajectories["odometry"]` and score every
    trajectory through it.

    Args:
        source: the sequence's `ground_truth_source`.
        ground_truth: GT at the scans (NaN rows dropped), as stamped.
        trajectories: by name; "odometry" (the first one, if absent) gives the speed profile.
    """
    if not trajectories:
        return GroundTruthReport(source, None, {})
    reference = trajectories.get("odometry", next(iter(trajectories.values())))
    offset = estimate_time_offset(reference, ground_truth)
    scored: dict[str, TrajectoryMetrics] = {}
    if offset is not None:
        accuracy_m = 0.0 if source is None else source.accuracy_m
        for name, trajectory in trajectories.items():
            shifted = ground_truth_with_offset(
                ground_truth, np.asarray(trajectory.timestamps_ns), offset.offset_s
            )
            try:
                scored[name] = evaluate(trajectory, shifted, gt_accuracy_m=accuracy_m)
            except TrajectoryError as exc:
                log.warning("no metrics with the GT time offset for %s: %s", name, exc)
    return GroundTruthReport(source, offset, scored)
