"""The SLAM pipeline: odometry -> pose graph <- verified loops, and its configuration.

`Pipeline(sequence, config).run()` processes the scans in order and returns a `Results`:

    for each scan:  read -> odometry -> extend graph -> detect loops -> close loops -> progress
    at the end:     resolve pending loops -> final optimisation -> review loops -> evaluate

Graph layout: one node per scan (key = scan index), so the SLAM trajectory has one pose per scan
at the scan's timestamp, and a chain of odometry factors between consecutive scans with the
odometry's motion and covariance (a constant-velocity gap keeps its large covariance). The chain
reproduces the odometry poses exactly, so without loops SLAM equals odometry, and the graph.g2o
written from it is read back with the same meaning (g2o edges between consecutive vertices are
odometry). Tying each scan to its keyframe instead (a tree) was measured too: the same accuracy
within noise (simulator 1.1, an earlier odometry: synthetic/loop ATE 0.367 vs 0.357 m), but g2o
readers would take its keyframe edges for loops. Loop factors join scans that entered the loop
detector's database (every `query_spacing_m`).

ISAM2 is updated whenever loops are added (so later loops are checked and initial guesses are
made against the corrected estimate) and once at the end; a final batch pass (GNC by default)
follows, and accepted loops whose final weight falls below `BACKEND_REJECT_WEIGHT` are recorded as
rejected by the back end.

Library code: no printing, no files (see `radar_slam.outputs` and `radar_slam.commands.run`).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from odometry import Odometry, OdometryConfig, OdometryResult
from radar_slam.config import configs_dir, merge, read_yaml
from radar_slam.datasets import DatasetConfig, open_sequence
from radar_slam.datasets.frame import RadarFrame, Sequence
from radar_slam.errors import ConfigError, RadarSlamError, TrajectoryError
from radar_slam.g2o import G2oGraph, g2o_to_pose_graph
from radar_slam.graph import GraphConfig, LoopConstraint, PoseGraph
from radar_slam.loops import (
    LoopCloser,
    LoopClosureConfig,
    LoopDecision,
    is_true_loop,
    make_loop_detector,
    rotate_covariance,
)
from radar_slam.metrics import TrajectoryMetrics, evaluate
from radar_slam.trajectory import Trajectory

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]

BACKEND_REJECT_WEIGHT = 0.5
"""An accepted loop whose weight after the final pass is below this counts as rejected there."""


# --------------------------------------------------------------------------- configuration


@dataclass(frozen=True)
class PipelineConfig:
    """All settings of a SLAM run, one section per stage (each stage gets only its own)."""

    dataset: DatasetConfig = field(default_factory=DatasetConfig)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    loop_closure: LoopClosureConfig = field(default_factory=LoopClosureConfig)
    graph: GraphConfig = field(default_factory=GraphConfig)


def family_config_path(family: str) -> Path:
    """The shipped YAML overrides of a dataset family (may not exist)."""
    return configs_dir() / f"{family}.yaml"


def load_config(
    family: str | None = None,
    path: Path | None = None,
    overrides: dict[str, Any] | None = None,
) -> PipelineConfig:
    """Defaults in code, then `configs/<family>.yaml` (when shipped), then the file `path`, then
    `overrides` (a nested mapping). Unknown keys and wrong types are `ConfigError`s."""
    config = PipelineConfig()
    if family is not None:
        shipped = family_config_path(family)
        if shipped.is_file():
            config = merge(PipelineConfig, config, read_yaml(shipped), str(shipped))
    if path is not None:
        path = Path(path)
        if not path.is_file():
            raise ConfigError(f"{path}: config file not found")
        config = merge(PipelineConfig, config, read_yaml(path), str(path))
    if overrides:
        config = merge(PipelineConfig, config, overrides, "overrides")
    return config


def open_configured(
    spec: str, data_root: Path | None = None, path: Path | None = None
) -> tuple[Sequence, PipelineConfig]:
    """Open a sequence and load its configuration (defaults, `configs/<family>.yaml`, `path`).

    The family, known only once the sequence is found, selects the shipped overrides; when the
    configuration's `dataset` section changes loader settings, the sequence is opened again
    with them (opening is lazy: no scan is read).
    """
    load_config(None, path)  # a mistake in the user's file fails before any data is generated
    sequence = open_sequence(spec, data_root)
    config = load_config(sequence.family, path)
    if config.dataset.loader_options():
        sequence = open_sequence(spec, data_root, config.dataset)
    _ = sequence.ground_truth  # a malformed GT file fails now, not after the run (issue 12)
    _ = sequence[0]  # ... and so does a first scan of the wrong shape or format
    return sequence, config


# --------------------------------------------------------------------------- results


@dataclass(frozen=True)
class Progress:
    """State reported to the progress callback after each scan.

    Attributes:
        done: scans processed.
        total: scans to process.
        loops_accepted: loops accepted so far.
        loops_rejected: verified proposals rejected so far.
        elapsed_s: wall time since the start [s].
    """

    done: int
    total: int
    loops_accepted: int
    loops_rejected: int
    elapsed_s: float


ProgressCallback = Callable[[Progress], None]


@dataclass(frozen=True)
class SlamMetrics:
    """The machine-readable summary of a run (metrics.json).

    ATEs are RMSE after SE(2) Umeyama alignment (`ate_*_m`) and after first-pose alignment
    (`ate_origin_*_m`) [m]; drifts are KITTI-style mean translation errors over 100..800 m
    segments [%] and rotation errors [deg/100 m]; `ate_reduction` = 1 - ate_slam / ate_odometry.
    Fields needing ground truth are None without it (drift also below 100 m of path).
    `scans_with_gt` is how many scans the accuracy figures were computed over, and
    `scans_without_gt` how many had no ground truth (outside its time span).
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
        odometry_results: the odometry's per-scan results.
        loops: every verified loop proposal with its final status and reason.
        true_loops: per loop, whether it is true (`loops.is_true_loop`), None without GT.
        graph: the final pose graph (estimates = slam).
        timings_s: wall time per pipeline step [s].
        metrics: the summary metrics.
        odometry_metrics, slam_metrics: full accuracy figures, None without ground truth.
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

    @property
    def accepted_loops(self) -> list[LoopDecision]:
        return [d for d in self.loops if d.accepted]


class StepTimer:
    """Accumulated wall time per named step [s]."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}

    @contextmanager
    def __call__(self, step: str) -> Iterator[None]:
        start = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[step] = self.seconds.get(step, 0.0) + time.perf_counter() - start


# --------------------------------------------------------------------------- shared helpers


def frame_count(sequence: Sequence, max_frames: int | None) -> int:
    """Scans to process: all, or the first `max_frames`."""
    if max_frames is not None and max_frames < 1:
        raise RadarSlamError(f"--max-frames must be at least 1, got {max_frames}")
    n = len(sequence)
    return n if max_frames is None else min(n, max_frames)


def sequence_label(sequence: Sequence) -> str:
    return f"{sequence.family}/{sequence.name}"


def ground_truth_of(sequence: Sequence, frames: int) -> tuple[FloatArray | None, Trajectory | None]:
    """((frames, 3) GT with NaN rows, the GT trajectory without them) or (None, None)."""
    gt = sequence.ground_truth
    if gt is None:
        return None, None
    poses = np.asarray(gt, dtype=np.float64)[:frames]
    stamps = np.asarray(sequence.timestamps_ns)[:frames]
    trajectory = Trajectory.from_arrays(stamps, poses, drop_nonfinite=True)
    return poses, (trajectory if len(trajectory) else None)


def accuracy(est: Trajectory, gt: Trajectory | None) -> TrajectoryMetrics | None:
    """`metrics.evaluate` or None when there is no ground truth or too little of it."""
    if gt is None:
        return None
    try:
        return evaluate(est, gt)
    except TrajectoryError as exc:
        log.warning("no accuracy figures: %s", exc)
        return None


def odometry_factor(result: OdometryResult) -> tuple[FloatArray, FloatArray]:
    """(measurement T_previous_scan, covariance in GTSAM's tangent) of a scan's odometry factor.

    The odometry reports the motion from the previous scan with the covariance of the
    registration that produced it (in the previous scan's axes; a gap's is large); GTSAM
    perturbs a between-factor in the frame of its second pose, so the covariance is turned by
    the motion's rotation.
    """
    return result.motion, rotate_covariance(result.covariance, float(result.motion[2]))


# --------------------------------------------------------------------------- the pipeline


class Pipeline:
    """Radar SLAM over one sequence.

    Args:
        sequence: the scans (and ground truth, if any).
        config: settings (defaults when None); each stage gets its own section.
        max_frames: process only the first scans.
        progress: called after each scan with a `Progress` (e.g. to drive a progress bar).
        loop_detector: a detector to use instead of the configured one (e.g. one with another
            place recognizer or verifier); it must not have seen scans yet. Its keys are the scan
            indices.
    """

    def __init__(
        self,
        sequence: Sequence,
        config: PipelineConfig | None = None,
        max_frames: int | None = None,
        progress: ProgressCallback | None = None,
        loop_detector: LoopCloser | None = None,
    ) -> None:
        self.sequence = sequence
        self.config = PipelineConfig() if config is None else config
        self.frames = frame_count(sequence, max_frames)
        self.progress = progress
        self.odometry = Odometry(self.config.odometry)
        self.loop_detector: LoopCloser = (
            make_loop_detector(self.config.loop_closure, scan_loader=self._reread)
            if loop_detector is None
            else loop_detector
        )
        self.graph = PoseGraph(self.config.graph)
        self.timer = StepTimer()
        self._results: list[OdometryResult] = []
        self._loop_ids: dict[tuple[int, int], int] = {}  # (query, match) -> graph loop id
        self._start = 0.0

    def run(self) -> Results:
        """Process every scan, optimise, evaluate; returns the results (call once)."""
        self._start = time.perf_counter()
        for index in range(self.frames):
            frame = self._read(index)
            result = self._track(frame)
            self._extend_graph(result)
            loops = self._detect_loops(frame, result)
            self._close_loops(loops)
            self._report(index + 1)
        self._close_loops(self._resolve_pending())
        self._optimise()
        self._review_loops()
        return self._evaluate(time.perf_counter() - self._start)

    # -- per-scan steps -----------------------------------------------------------------------
    def _read(self, index: int) -> RadarFrame:
        with self.timer("read"):
            return self.sequence[index]

    def _reread(self, index: int) -> RadarFrame:
        """A database scan read again for loop verification (timed as loop detection)."""
        return self.sequence[index]

    def _track(self, frame: RadarFrame) -> OdometryResult:
        with self.timer("odometry"):
            result = self.odometry.register(frame)
        self._results.append(result)
        return result

    def _extend_graph(self, result: OdometryResult) -> None:
        with self.timer("graph"):
            if result.index == 0:
                self.graph.add_keyframe(0, result.pose)
                return
            measurement, covariance = odometry_factor(result)
            previous = result.index - 1
            self.graph.add_keyframe(result.index, self.graph.predict(previous, measurement))
            self.graph.add_odometry(previous, result.index, measurement, covariance)

    def _detect_loops(self, frame: RadarFrame, result: OdometryResult) -> list[LoopConstraint]:
        with self.timer("loop detection"):
            return self.loop_detector.add(frame, result.pose, result.index)

    def _close_loops(self, loops: list[LoopConstraint]) -> None:
        if not loops:
            return
        with self.timer("graph"):
            for loop in loops:
                loop_id = self.graph.add_loop(loop.i, loop.j, loop.measurement, loop.covariance)
                self._loop_ids[(loop.i, loop.j)] = loop_id
            self.graph.update()

    def _report(self, done: int) -> None:
        if self.progress is None:
            return
        accepted, rejected = self.loop_detector.tally()
        elapsed = time.perf_counter() - self._start
        self.progress(Progress(done, self.frames, accepted, rejected, elapsed))

    # -- final steps --------------------------------------------------------------------------
    def _resolve_pending(self) -> list[LoopConstraint]:
        with self.timer("loop detection"):
            return self.loop_detector.finish()

    def _optimise(self) -> None:
        with self.timer("optimisation"):
            if self.frames > 1:
                self.graph.update()
                self.graph.optimize_final()

    def _review_loops(self) -> None:
        """Record the accepted loops the final pass discounted as rejected."""
        review_loops(self.graph, self._loop_ids, self.loop_detector)

    def _evaluate(self, seconds: float) -> Results:
        with self.timer("evaluation"):
            stamps = np.array([r.timestamp_ns for r in self._results], dtype=np.int64)
            odometry = Trajectory(stamps, np.array([r.pose for r in self._results]))
            slam = Trajectory(stamps, self.graph.estimates())
            gt_poses, gt = ground_truth_of(self.sequence, self.frames)
            loops = self.loop_detector.decisions
            true_loops = [
                None
                if gt_poses is None
                else is_true_loop(d.measurement, gt_poses[d.query_key], gt_poses[d.match_key])
                for d in loops
            ]
            odometry_metrics = accuracy(odometry, gt)
            slam_metrics = accuracy(slam, gt)
        metrics = summarise(
            frames=self.frames,
            seconds=seconds,
            gaps=sum(r.gap for r in self._results),
            candidates=self.loop_detector.proposed,
            loops=loops,
            true_loops=true_loops,
            odometry=odometry_metrics,
            slam=slam_metrics,
        )
        return Results(
            sequence=sequence_label(self.sequence),
            config=self.config,
            odometry=odometry,
            slam=slam,
            ground_truth=gt,
            ground_truth_poses=gt_poses,
            odometry_results=list(self._results),
            loops=loops,
            true_loops=true_loops,
            graph=self.graph,
            timings_s=dict(self.timer.seconds),
            metrics=metrics,
            odometry_metrics=odometry_metrics,
            slam_metrics=slam_metrics,
        )


def review_loops(
    graph: PoseGraph,
    loop_ids: dict[tuple[int, int], int],
    detector: LoopCloser,
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
        scans_with_gt=None if odometry is None else odometry.poses_matched,
        scans_without_gt=None if odometry is None else frames - odometry.poses_matched,
    )


# --------------------------------------------------------------------------- odometry only


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
    """

    sequence: str
    config: PipelineConfig
    trajectory: Trajectory
    ground_truth: Trajectory | None
    results: list[OdometryResult]
    seconds: float
    metrics: TrajectoryMetrics | None

    def summary(self) -> dict[str, Any]:
        """metrics.json content: counts, speed, and the accuracy fields when there is GT."""
        frames = len(self.trajectory)
        data: dict[str, Any] = {
            "frames": frames,
            "seconds": self.seconds,
            "frames_per_second": frames / self.seconds if self.seconds > 0 else 0.0,
            "odometry_gaps": sum(r.gap for r in self.results),
            "keyframes": sum(r.is_keyframe for r in self.results),
        }
        if self.metrics is not None:
            data.update(self.metrics.to_dict())
            data["scans_with_gt"] = self.metrics.poses_matched
            data["scans_without_gt"] = frames - self.metrics.poses_matched
        return data


def run_odometry(
    sequence: Sequence,
    config: PipelineConfig | None = None,
    max_frames: int | None = None,
    progress: ProgressCallback | None = None,
) -> OdometryRun:
    """Odometry alone over a sequence: read -> register per scan, then evaluate."""
    config = PipelineConfig() if config is None else config
    frames = frame_count(sequence, max_frames)
    odometry = Odometry(config.odometry)
    start = time.perf_counter()
    results = []
    for index in range(frames):
        results.append(odometry.register(sequence[index]))
        if progress is not None:
            progress(Progress(index + 1, frames, 0, 0, time.perf_counter() - start))
    seconds = time.perf_counter() - start
    stamps = np.array([r.timestamp_ns for r in results], dtype=np.int64)
    trajectory = Trajectory(stamps, np.array([r.pose for r in results]).reshape(-1, 3))
    _, gt = ground_truth_of(sequence, frames)
    return OdometryRun(
        sequence=sequence_label(sequence),
        config=config,
        trajectory=trajectory,
        ground_truth=gt,
        results=results,
        seconds=seconds,
        metrics=accuracy(trajectory, gt),
    )


# --------------------------------------------------------------------------- loops on a graph


@dataclass(frozen=True)
class GraphLoopsRun:
    """What `close_loops_on_graph` produced.

    Attributes:
        graph: the input graph with the accepted loops added, optimised.
        loops: every verified proposal with its status.
        seconds: wall time [s].
    """

    graph: PoseGraph
    loops: list[LoopDecision]
    seconds: float

    @property
    def accepted(self) -> int:
        return sum(d.accepted for d in self.loops)


def close_loops_on_graph(
    record: G2oGraph,
    sequence: Sequence,
    config: PipelineConfig | None = None,
    progress: ProgressCallback | None = None,
) -> GraphLoopsRun:
    """Add verified loops to another odometry's pose graph and optimise it.

    The graph must have one vertex per scan of `sequence`; vertices in increasing id order are
    the scans in time order. Their poses are the odometry poses the loop detector uses.

    Raises:
        RadarSlamError: the vertex count differs from the scan count.
    """
    config = PipelineConfig() if config is None else config
    keys = record.keys()
    if len(keys) != len(sequence):
        raise RadarSlamError(
            f"the graph has {len(keys)} vertices but {sequence_label(sequence)} has "
            f"{len(sequence)} scans; expected one vertex per scan, in scan order"
        )
    graph = g2o_to_pose_graph(record, config.graph)
    poses = record.poses()
    scan_of_key = {key: n for n, key in enumerate(keys)}
    detector = make_loop_detector(
        config.loop_closure, scan_loader=lambda key: sequence[scan_of_key[key]]
    )
    start = time.perf_counter()
    loops: list[LoopConstraint] = []
    for n, key in enumerate(keys):
        loops += detector.add(sequence[n], poses[n], key)
        if progress is not None:
            accepted, rejected = detector.tally()
            progress(Progress(n + 1, len(keys), accepted, rejected, time.perf_counter() - start))
    loops += detector.finish()
    loop_ids = {
        (loop.i, loop.j): graph.add_loop(loop.i, loop.j, loop.measurement, loop.covariance)
        for loop in loops
    }
    graph.update()
    graph.optimize_final()
    review_loops(graph, loop_ids, detector)
    return GraphLoopsRun(graph, detector.decisions, time.perf_counter() - start)
