"""The SLAM runner: odometry -> pose graph <- verified loops.

`Pipeline(sequence, config).run()` processes the scans in order and returns a `Results`:

    for each scan:  read -> odometry -> extend graph -> detect loops -> close loops -> progress
    at the end:     resolve pending loops -> final optimisation -> review loops -> evaluate

Graph layout: one node per scan (key = scan index), so the SLAM trajectory has one pose per scan
at the scan's timestamp, and a chain of odometry factors between consecutive scans with the
odometry's motion and covariance (a constant-velocity gap keeps its large covariance). The chain
reproduces the odometry poses exactly, so without loops SLAM equals odometry, and the graph.g2o
written from it is read back with the same meaning (g2o edges between consecutive vertices are
odometry). Loop factors join scans that entered the loop detector's database (every
`query_spacing_m`).

Concurrency (`PipelineConfig.concurrency`): scans are read ahead on a reader thread, and the loop
detector, which needs only the odometry poses, runs on a worker thread; the loops found for scan
k enter the graph when the run reaches scan k + `loop_lag_scans`, with or without the thread, so
the results do not depend on timing (`radar_slam.pipeline.concurrency`). With the thread, the step
time "loop detection" is the worker's (it overlaps the others) and "loop wait" the main thread's
waiting for it; a loop detector given to the pipeline is then called from the worker thread only.

ISAM2 is updated after loops are added (so that initial guesses are made against the corrected
estimate), at most every `LOOP_UPDATE_INTERVAL` scans, or every `SETTLED_UPDATE_INTERVAL` scans
while every loop added since the last update agrees with the current estimate (`SETTLED_CHI2`: a
stretch already closed), and once at the end; a
final batch pass (GNC by default)
follows, and accepted loops whose final weight falls below `BACKEND_REJECT_WEIGHT` are recorded as
rejected by the back end.

Library code: no printing, no files (see `radar_slam.outputs` and `radar_slam.commands.run`).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from threadpoolctl import threadpool_limits

from odometry import (
    Odometry,
    OdometryResult,
    PolarScan,
    PreparedScan,
    Scan,
    preprocess_polar,
)
from radar_slam.datasets.frame import RadarFrame, RadarSequence
from radar_slam.errors import RadarSlamError
from radar_slam.evaluation.truth import is_true_loop
from radar_slam.graph import LoopConstraint, PoseGraph
from radar_slam.loops import (
    LoopDetectorProtocol,
    make_loop_detector,
)
from radar_slam.loops.config import CHI2_3DOF_99, LOOP_RAPLACE
from radar_slam.loops.detector import DescriptorListener
from radar_slam.maps.keyframes import (
    KeyframeListener,
    KeyframeRecorder,
    KeyframeStage,
    NullKeyframeRecorder,
    RecordedKeyframes,
)
from radar_slam.pipeline.concurrency import (
    InlineLoopRunner,
    ScanReader,
    make_loop_runner,
    usable_cpus,
)
from radar_slam.pipeline.config import PipelineConfig
from radar_slam.pipeline.observer import PipelineObserver
from radar_slam.pipeline.records import (
    Progress,
    ProgressCallback,
    Results,
)
from radar_slam.pipeline.steps import (
    StepTimer,
    accuracy,
    frame_count,
    ground_truth_of,
    gt_accuracy_m,
    gt_report_of,
    odometry_factor,
    review_loops,
    sequence_label,
    summarise,
)
from radar_slam.trajectory import Trajectory

MEMORY_BUDGET_BYTES = 1536 * 2**20
"""Peak resident memory (RSS) of a whole `radar-slam run` over `MEMORY_BUDGET_SCANS` scans at
MulRan resolution (400 x 3360) with the default configuration: a run keeps no scan, only what it
needs of each (records, descriptors, odometry results, graph). Stated in the README (Limits);
its breakdown is in docs/benchmarks.md (Memory budget)."""
MEMORY_BUDGET_SCANS = 10_000
"""The drive length `MEMORY_BUDGET_BYTES` is stated for [scans]."""
LOOP_UPDATE_INTERVAL = 10
"""Scans between ISAM2 updates that carry loops (each loop update re-eliminates the path back to
the loop's older end; the final pass refines the result)."""
SETTLED_UPDATE_INTERVAL = 100
"""... and while every loop added since the last update agrees with the current estimate (a
stretch already closed: an update would barely move it; its loops enter the graph all the
same)."""
LoopDetectorFactory = Callable[[Callable[[int], Scan], DescriptorListener], LoopDetectorProtocol]
"""Makes a run's loop detector from the run's scan records: called with the loader of a
database scan's record and the listener of the descriptors the detector makes (the
`scan_loader` and `on_describe` of `radar_slam.loops.LoopDetector`)."""
SETTLED_CHI2 = CHI2_3DOF_99
"""A loop agrees with the current estimate when its squared Mahalanobis distance from it
(`PoseGraph.residual_chi2`) is below this (chi-square 99 % for 3 degrees of freedom)."""


class Pipeline:
    """Radar SLAM over one sequence.

    Args:
        sequence: the scans (and ground truth, if any).
        config: settings (defaults when None); each stage gets its own section.
        max_frames: process only the first scans.
        progress: called after each scan with a `Progress` (e.g. to drive a progress bar).
        loop_detector: a detector to use instead of the configured one (e.g. one with another
            place recognizer or verifier); it must not have seen scans yet. Its keys are the scan
            indices; it keeps or loads its database scans itself (the configured one verifies
            them from the run's records, `radar_slam.maps.keyframes`).
        loop_detector_factory: makes a detector to use instead of the configured one from the
            run's scan records (e.g. one with another recognizer or verifier that verifies
            from the records as the configured one does, reading no scan twice); not with
            `loop_detector`.
        observer: watches the run scan by scan (e.g. the live viewer); see
            `radar_slam.pipeline.observer.PipelineObserver`.
        record_map: keep each map keyframe's descriptor and image as the run goes
            (`Results.map_keyframes`: `radar_slam.maps.build_map` then reads no scan again);
            the database scans of the loop detector are recorded either way.
        on_keyframe: receives each map keyframe as its record is made, with its raw scan,
            conditioned form, sweep twist and descriptor
            (`radar_slam.maps.keyframes.KeyframeListener`; e.g. the inter-session queries of
            `radar-slam run --map`); implies `record_map`.
    """

    def __init__(
        self,
        sequence: RadarSequence,
        config: PipelineConfig | None = None,
        max_frames: int | None = None,
        progress: ProgressCallback | None = None,
        loop_detector: LoopDetectorProtocol | None = None,
        observer: PipelineObserver | None = None,
        record_map: bool = False,
        on_keyframe: KeyframeListener | None = None,
        loop_detector_factory: LoopDetectorFactory | None = None,
    ) -> None:
        self.sequence = sequence
        self.observer = observer
        self.config = PipelineConfig() if config is None else config
        self.frames = frame_count(sequence, max_frames)
        self.progress = progress
        self.odometry = Odometry(self.config.odometry)
        self.record_map = record_map or on_keyframe is not None
        if loop_detector is not None and loop_detector_factory is not None:
            raise RadarSlamError("give a loop detector or a loop detector factory, not both")
        self.keyframes = self._keyframe_stage(self.record_map, loop_detector is None, on_keyframe)
        self.loop_detector: LoopDetectorProtocol
        if loop_detector is not None:
            self.loop_detector = loop_detector
        elif loop_detector_factory is not None:
            scans, descriptors = self.keyframes.scan, self.keyframes.offer_descriptor
            self.loop_detector = loop_detector_factory(scans, descriptors)
        else:
            self.loop_detector = make_loop_detector(
                self.config.loop_closure,
                scan_loader=self.keyframes.scan,
                on_describe=self.keyframes.offer_descriptor,
                odometry=self.config.odometry,
            )
        self.graph = PoseGraph(self.config.graph)
        self.timer = StepTimer()
        self._loop_ids: dict[tuple[int, int], int] = {}  # (query, match) -> graph loop id
        self._loops_pending = False  # loops added to the graph since its last ISAM2 update
        self._loops_correct = False  # ... one of which disagrees with the current estimate
        self._last_update = 0  # scan index of that update
        self._start = 0.0
        concurrency = self.config.concurrency
        threads = usable_cpus() > 1  # on one CPU threads only contend (same results either way)
        self._read_ahead = concurrency.read_ahead_scans if threads else 0
        self.loops: InlineLoopRunner = make_loop_runner(
            self.loop_detector,
            concurrency.loop_lag_scans,
            concurrency.loop_thread and threads,
            self.timer,
            self.keyframes,
        )
        self._map_keyframes: RecordedKeyframes | None = None
        """The loop detector as the graph has seen it: `loops.tally()` and `loops.decisions`
        are those of the loops added to the graph so far (read these, not the detector's, while
        the run goes on: the detector may be ahead on its thread)."""

    def run(self) -> Results:
        """Process every scan, optimise, evaluate; returns the results (call once).

        On an error or an interruption the threads are stopped before it propagates. BLAS runs
        single-threaded meanwhile: the run's own threads are its parallelism, and BLAS threads,
        which wait for work spinning, only took CPU from them.
        """
        with threadpool_limits(limits=1, user_api="blas"):
            return self._run()

    def _run(self) -> Results:
        self._start = time.perf_counter()
        reader = ScanReader(self._read_conditioned, self.frames, self._read_ahead)
        try:
            held: tuple[RadarFrame, PreparedScan | None] | None = None
            for index in range(self.frames):
                frame, polar = self._read(reader)
                result = self._track(frame, polar)
                if held is not None:
                    self._extend_graph(self.odometry.result(index - 1))
                    self._submit(*held, index - 1)
                held = (frame, self.odometry.prepared)  # its conditioned form
                self._close_loops(self.loops.due(index), index)
                self._report(index + 1)
                if self.observer is not None:
                    self.observer.on_scan(self, frame, result)
            if held is not None:
                self._extend_graph(self.odometry.result(self.frames - 1))
                self._submit(*held, self.frames - 1)
            self._report(self.frames, "last loops")
            self._close_loops(self.loops.finish(), None)
            with self.timer("map keyframes"):
                recorded = self.keyframes.finish()
                self._map_keyframes = recorded if self.record_map else None
        finally:
            reader.close()
            self.loops.close()
        self._report(self.frames, "optimisation")
        self._optimise()
        self._review_loops()
        self._report(self.frames, "evaluation")
        results = self._evaluate(time.perf_counter() - self._start)
        if self.observer is not None:
            self.observer.on_finish(results)
        return results

    def _keyframe_stage(
        self, record_map: bool, own_detector: bool, on_keyframe: KeyframeListener | None
    ) -> KeyframeStage:
        """The scan records of the run (`radar_slam.maps.keyframes`): the map keyframes when
        `record_map` (each handed to `on_keyframe` too), and the loop database's scans when the
        run's own detector closes loops (it verifies them from their records); else nothing is
        kept."""
        cfg = self.config
        loops = own_detector and cfg.loop_closure.enabled
        if not (record_map or loops):
            return NullKeyframeRecorder()
        return KeyframeRecorder(
            cfg.maps, cfg.odometry, LOOP_RAPLACE.descriptor, record_map, on_keyframe
        )

    # -- per-scan steps -----------------------------------------------------------------------
    def _read_conditioned(self, index: int) -> tuple[RadarFrame, PolarScan]:
        """Scan `index` and its conditioned form for the odometry, made where the scan is read:
        on the reader thread when scans are read ahead (conditioning, like decoding, runs
        mostly outside the GIL), which takes it off the odometry's thread."""
        frame = self.sequence[index]
        return frame, preprocess_polar(frame, self.config.odometry.preprocess)

    def _read(
        self, reader: ScanReader[tuple[RadarFrame, PolarScan]]
    ) -> tuple[RadarFrame, PolarScan]:
        with self.timer("read"):
            return reader.next()

    def _track(self, frame: RadarFrame, polar: PolarScan) -> OdometryResult:
        with self.timer("odometry"):
            return self.odometry.register(frame, polar)

    def _submit(self, frame: RadarFrame, prepared: PreparedScan | None, index: int) -> None:
        """Hand scan `index` to the loop detector with its odometry result (one scan after it
        registered; the odometry no longer revises a result, so the delay only shifts when loops
        are handed out)."""
        self.loops.submit(frame, self.odometry.result(index), index, prepared)

    def _extend_graph(self, result: OdometryResult) -> None:
        """Add a scan to the graph with its odometry factor from the previous scan (one scan
        after it registered, as `_submit`)."""
        with self.timer("graph"):
            if result.index == 0:
                self.graph.add_keyframe(0, result.pose)
                return
            measurement, covariance = odometry_factor(result)
            previous = result.index - 1
            self.graph.add_keyframe(result.index, self.graph.predict(previous, measurement))
            self.graph.add_odometry(previous, result.index, measurement, covariance)

    def _close_loops(self, loops: list[LoopConstraint], index: int | None) -> None:
        """Add `loops` to the graph; run ISAM2 once `LOOP_UPDATE_INTERVAL` scans have passed
        since its last update, or `SETTLED_UPDATE_INTERVAL` while every loop added since agrees
        with the current estimate (`index` None: the end of the run, where `_optimise`
        updates)."""
        with self.timer("graph"):
            for loop in loops:
                loop_id = self.graph.add_loop(loop.i, loop.j, loop.measurement, loop.covariance)
                self._loop_ids[(loop.i, loop.j)] = loop_id
                if not self._loops_correct:
                    self._loops_correct = self.graph.residual_chi2(loop_id) > SETTLED_CHI2
            self._loops_pending |= bool(loops)
            interval = LOOP_UPDATE_INTERVAL
            if not self._loops_correct:
                interval = max(interval, SETTLED_UPDATE_INTERVAL)
            if index is not None and self._loops_pending and index - self._last_update >= interval:
                self.graph.update()
                self._loops_pending = self._loops_correct = False
                self._last_update = index

    def _report(self, done: int, step: str = "") -> None:
        """Report `done` scans to the progress callback (`step`: what follows the last scan)."""
        if self.progress is None:
            return
        accepted, rejected = self.loops.tally()
        elapsed = time.perf_counter() - self._start
        self.progress(Progress(done, self.frames, accepted, rejected, elapsed, step))

    # -- final steps --------------------------------------------------------------------------
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
            revised = self.odometry.results
            stamps = np.array([r.timestamp_ns for r in revised], dtype=np.int64)
            odometry = Trajectory(stamps, np.array([r.pose for r in revised]))
            slam = Trajectory(stamps, self.graph.estimates())
            gt_poses, gt = ground_truth_of(self.sequence, self.frames)
            loops = self.loop_detector.decisions
            true_loops = [
                None
                if gt_poses is None
                else is_true_loop(d.measurement, gt_poses[d.query_key], gt_poses[d.match_key])
                for d in loops
            ]
            gt_accuracy = gt_accuracy_m(self.sequence)
            odometry_metrics = accuracy(odometry, gt, gt_accuracy)
            slam_metrics = accuracy(slam, gt, gt_accuracy)
            report = gt_report_of(self.sequence, gt, {"odometry": odometry, "slam": slam})
        metrics = summarise(
            frames=self.frames,
            seconds=seconds,
            gaps=sum(r.gap for r in revised),
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
            odometry_results=revised,
            loops=loops,
            true_loops=true_loops,
            graph=self.graph,
            timings_s=dict(self.timer.seconds),
            metrics=metrics,
            odometry_metrics=odometry_metrics,
            slam_metrics=slam_metrics,
            gt_report=report,
            map_keyframes=self._map_keyframes,
        )
