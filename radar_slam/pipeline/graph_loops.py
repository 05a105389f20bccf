"""Verified radar loops added to another odometry's pose graph (`radar-slam loops`)."""

from __future__ import annotations

import time

from radar_slam.datasets.frame import RadarSequence
from radar_slam.errors import RadarSlamError
from radar_slam.g2o import G2oGraph, g2o_to_pose_graph
from radar_slam.graph import LoopConstraint
from radar_slam.loops import (
    make_loop_detector,
)
from radar_slam.pipeline.config import PipelineConfig
from radar_slam.pipeline.records import (
    GraphLoopsRun,
    Progress,
    ProgressCallback,
)
from radar_slam.pipeline.steps import (
    review_loops,
    sequence_label,
)


def close_loops_on_graph(
    record: G2oGraph,
    sequence: RadarSequence,
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
