"""Writers of a result folder (`radar-slam run` and `radar-slam odometry`).

A SLAM result folder holds:

    config.yaml      the settings used (readable back with --config)
    odometry.tum     odometry, one pose per scan, scan timestamps (TUM: t x y z qx qy qz qw)
    odometry.kitti   the same poses as 3x4 matrices
    slam.tum/.kitti  the optimised trajectory, same scans
    gt.tum           ground truth at the scans that have it (when the sequence has GT)
    loops.csv        one row per verified loop proposal (LOOPS_CSV_COLUMNS)
    graph.g2o        the final pose graph (VERTEX_SE2 / EDGE_SE2 / FIX)
    metrics.json     counts, speed and accuracy (`SlamMetrics`)
    summary.txt      a short human summary
    trajectory.png   GT, odometry, SLAM and the accepted loops as lines

An odometry result folder holds config.yaml, odometry.tum/.kitti, metrics.json, summary.txt, and
gt.tum and trajectory.png when there is ground truth.
"""

from __future__ import annotations

import csv
import json
import logging
from pathlib import Path
from typing import Any

import numpy as np

from radar_slam.config import write_yaml
from radar_slam.errors import TrajectoryError
from radar_slam.evaluation.metrics import (
    KITTI_SEGMENT_LENGTHS_M,
    TrajectoryMetrics,
    associate,
    umeyama_alignment_se2,
)
from radar_slam.g2o import write_pose_graph
from radar_slam.loops import LoopDecision
from radar_slam.pipeline.records import OdometryRun, Results
from radar_slam.plots import plot_trajectories
from radar_slam.trajectory import Trajectory, write_kitti, write_tum
from raplace import compose

log = logging.getLogger(__name__)

LOOPS_CSV_COLUMNS = (
    "query_ns",
    "match_ns",
    "distance",
    "dx",
    "dy",
    "dyaw",
    "accepted",
    "reason",
    "true_loop",
)
"""loops.csv header: scan times [ns], RaPlace distance, T_query_match (dx, dy [m], dyaw [rad]),
accepted (true/false), reason, true_loop (true/false, empty without ground truth)."""

CONFIG_FILE = "config.yaml"
METRICS_FILE = "metrics.json"
SUMMARY_FILE = "summary.txt"
LOOPS_FILE = "loops.csv"
GRAPH_FILE = "graph.g2o"
PLOT_FILE = "trajectory.png"
GT_FILE = "gt.tum"
SLAM_RESULT_FILES = (
    CONFIG_FILE,
    "odometry.tum",
    "odometry.kitti",
    "slam.tum",
    "slam.kitti",
    LOOPS_FILE,
    GRAPH_FILE,
    METRICS_FILE,
    SUMMARY_FILE,
    PLOT_FILE,
)
"""Files of every SLAM result folder (plus gt.tum with ground truth)."""


def write_trajectory(folder: Path, stem: str, trajectory: Trajectory) -> None:
    """`<stem>.tum` and `<stem>.kitti` of one trajectory."""
    write_tum(folder / f"{stem}.tum", trajectory)
    write_kitti(folder / f"{stem}.kitti", trajectory)


def _flag(value: bool | None) -> str:
    return "" if value is None else str(bool(value)).lower()


def write_loops_csv(path: Path, loops: list[LoopDecision], true_loops: list[bool | None]) -> None:
    """One row per verified loop proposal (columns: `LOOPS_CSV_COLUMNS`); NaN fields empty."""
    with Path(path).open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(LOOPS_CSV_COLUMNS)
        for decision, true_loop in zip(loops, true_loops, strict=True):
            dx, dy, dyaw = (
                "" if not np.isfinite(v) else repr(float(v)) for v in decision.measurement
            )
            writer.writerow(
                [
                    decision.query_ns,
                    decision.match_ns,
                    f"{decision.distance:.6f}",
                    dx,
                    dy,
                    dyaw,
                    _flag(decision.accepted),
                    decision.reason,
                    _flag(true_loop),
                ]
            )


def finite_json(value: Any) -> Any:
    """`value` with every NaN or infinite float (also inside lists and dicts) made None, so that
    it is valid JSON (null) rather than a bare NaN."""
    if isinstance(value, dict):
        return {key: finite_json(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_json(item) for item in value]
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


def json_text(content: Any) -> str:
    """Strict, indented JSON (non-finite numbers as null) with a trailing newline."""
    return json.dumps(finite_json(content), indent=2, allow_nan=False) + "\n"


def write_json(path: Path, content: dict[str, Any]) -> None:
    """Indented strict JSON with a trailing newline (non-finite numbers as null)."""
    Path(path).write_text(json_text(content))


def _fmt(value: float | int | None, spec: str, unit: str = "") -> str:
    return "n/a" if value is None else f"{value:{spec}}{unit}"


def gt_coverage(with_gt: int | None, frames: int) -> str:
    """The summary line saying over how many scans the accuracy figures were computed."""
    if with_gt is None:
        return "ground truth  n/a"
    return (
        f"ground truth  accuracy over {with_gt} of {frames} scans "
        f"({frames - with_gt} without ground truth)"
    )


def _drift_segments(m: TrajectoryMetrics | None) -> str:
    """The KITTI segment lengths the drift averages over, e.g. "400-800 m"."""
    shortest = KITTI_SEGMENT_LENGTHS_M[0] if m is None else m.drift_min_segment_m
    return f"{shortest:.0f}-{KITTI_SEGMENT_LENGTHS_M[-1]:.0f} m"


def slam_summary(results: Results) -> str:
    """A few lines for humans (summary.txt and the terminal)."""
    m = results.metrics
    lines = [
        f"sequence      {results.sequence}: {m.frames} scans in {m.seconds:.1f} s "
        f"({m.frames_per_second:.1f} frames/s), {m.odometry_gaps} odometry gaps",
        f"loops         {m.loops_proposed} verified proposals: {m.loops_accepted} accepted "
        f"({_fmt(m.loops_accepted_true, 'd')} true), {m.loops_rejected} rejected",
    ]
    if m.ate_odometry_m is not None:
        reduction = None if m.ate_reduction is None else 100.0 * m.ate_reduction
        lines += [
            f"ATE           odometry {_fmt(m.ate_odometry_m, '.3f', ' m')}, "
            f"SLAM {_fmt(m.ate_slam_m, '.3f', ' m')} "
            f"(reduction {_fmt(reduction, '.1f', ' %')}; Umeyama-aligned)",
            f"ATE origin    odometry {_fmt(m.ate_origin_odometry_m, '.3f', ' m')}, "
            f"SLAM {_fmt(m.ate_origin_slam_m, '.3f', ' m')} (first pose aligned)",
            f"end point     odometry {_fmt(m.end_point_odometry_pct, '.2f', ' %')}, "
            f"SLAM {_fmt(m.end_point_slam_pct, '.2f', ' %')} of the distance (aligned)",
            f"drift         odometry {_fmt(m.drift_odometry_pct, '.2f', ' %')}, "
            f"SLAM {_fmt(m.drift_slam_pct, '.2f', ' %')} "
            f"(KITTI segments {_drift_segments(results.odometry_metrics)})",
            gt_coverage(m.scans_with_gt, m.frames),
        ]
        if results.gt_report is not None:
            lines += results.gt_report.summary_lines()
    else:
        lines.append("accuracy      n/a (no ground truth, or fewer than 2 scans with it)")
    timings = ", ".join(f"{k} {v:.1f} s" for k, v in results.timings_s.items())
    lines.append(f"time          {timings}")
    return "\n".join(lines) + "\n"


def aligned_to(estimate: Trajectory, ground_truth: Trajectory | None) -> Trajectory:
    """The whole estimate moved by the SE(2) Umeyama transform of its poses associated with the
    ground truth (for plots in the ground truth's frame); unchanged without ground truth."""
    if ground_truth is None:
        return estimate
    try:
        transform = umeyama_alignment_se2(*associate(estimate, ground_truth))
    except TrajectoryError as exc:
        log.warning("plot not aligned to the ground truth: %s", exc)
        return estimate
    return Trajectory(estimate.timestamps_ns, compose(transform, estimate.poses))


def loop_segments(results: Results, slam: Trajectory) -> np.ndarray:
    """(M, 4) (x1, y1, x2, y2) [m] of the accepted loops on the (plotted) SLAM trajectory."""
    poses = slam.poses
    pairs = [(d.query_key, d.match_key) for d in results.accepted_loops]
    if not pairs:
        return np.zeros((0, 4))
    index = np.array(pairs)
    return np.hstack([poses[index[:, 0], :2], poses[index[:, 1], :2]])


def write_results(folder: Path, results: Results) -> list[Path]:
    """Write every file of a SLAM result folder; returns their paths."""
    folder = Path(folder)
    write_yaml(results.config, folder / CONFIG_FILE)
    write_trajectory(folder, "odometry", results.odometry)
    write_trajectory(folder, "slam", results.slam)
    gt = results.ground_truth
    slam = aligned_to(results.slam, gt)
    curves = {"odometry": aligned_to(results.odometry, gt), "slam": slam}
    if gt is not None:
        write_trajectory(folder, "gt", gt)  # gt.tum and gt.kitti
        curves = {"gt": gt, **curves}
    write_loops_csv(folder / LOOPS_FILE, results.loops, results.true_loops)
    write_pose_graph(folder / GRAPH_FILE, results.graph)
    metrics: dict[str, Any] = dict(results.metrics.to_dict())
    if results.gt_report is not None:
        metrics["ground_truth"] = results.gt_report.to_dict()
    write_json(folder / METRICS_FILE, metrics)
    (folder / SUMMARY_FILE).write_text(slam_summary(results))
    plot_trajectories(
        folder / PLOT_FILE,
        curves,
        loops=loop_segments(results, slam),
        title=f"{results.sequence}: {results.metrics.loops_accepted} loops (Umeyama-aligned)",
    )
    log.info("wrote the results of %s into %s", results.sequence, folder)
    return sorted(folder.iterdir())


def odometry_summary(run: OdometryRun) -> str:
    """A few lines for humans about an odometry run."""
    data = run.summary()
    lines = [
        f"sequence      {run.sequence}: {data['frames']} scans in {run.seconds:.1f} s "
        f"({data['frames_per_second']:.1f} frames/s), {data['keyframes']} keyframes, "
        f"{data['odometry_gaps']} gaps"
    ]
    m = run.metrics
    if m is None:
        lines.append("accuracy      n/a (no ground truth, or fewer than 2 scans with it)")
    else:
        lines += [
            f"ATE           {m.ate_rmse_m:.3f} m (Umeyama-aligned), "
            f"{m.ate_origin_rmse_m:.3f} m (first pose aligned)",
            f"end point     {_fmt(m.end_point_error_pct, '.2f', ' %')} of the distance (aligned)",
            f"drift         {_fmt(m.drift_trans_pct, '.2f', ' %')}, "
            f"{_fmt(m.drift_rot_deg_per_100m, '.3f', ' deg/100 m')} "
            f"(KITTI segments {_drift_segments(m)})",
            gt_coverage(m.poses_matched, data["frames"]),
        ]
        if run.gt_report is not None:
            lines += run.gt_report.summary_lines()
    return "\n".join(lines) + "\n"


def write_odometry_results(folder: Path, run: OdometryRun) -> list[Path]:
    """Write an odometry result folder; returns the paths written."""
    folder = Path(folder)
    write_yaml(run.config, folder / CONFIG_FILE)
    write_trajectory(folder, "odometry", run.trajectory)
    write_json(folder / METRICS_FILE, run.summary())
    (folder / SUMMARY_FILE).write_text(odometry_summary(run))
    if run.ground_truth is not None:
        write_trajectory(folder, "gt", run.ground_truth)
        plot_trajectories(
            folder / PLOT_FILE,
            {"gt": run.ground_truth, "odometry": aligned_to(run.trajectory, run.ground_truth)},
            title=f"{run.sequence}: odometry",
        )
    return sorted(folder.iterdir())
