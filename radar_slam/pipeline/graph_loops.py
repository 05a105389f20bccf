"""Verified radar loops added to another odometry's pose graph (`radar-slam loops`).

Edges of the input graph between vertices that are not consecutive are the input's own loops.
They are treated like ours: each must agree with the odometry path between its two vertices
(within the drift model of the loop consistency check, `odometry_segment_covariance`) or it is
left out of the optimisation with a warning naming it; the rest enter under the robust loop
kernel, and one that the final pass then finds inconsistent (weight below
`BACKEND_REJECT_WEIGHT`) is named in a warning too.

Each scan is read once: the loop detector verifies a candidate against its record
(`radar_slam.maps.keyframes.KeyframeRecorder`, as a SLAM run does), made once when the scan
entered the place database, with the sweep twist the graph's poses imply.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from odometry import OdometryResult
from radar_slam.datasets.frame import RadarSequence
from radar_slam.errors import RadarSlamError
from radar_slam.g2o import G2oEdge, G2oGraph, g2o_to_pose_graph
from radar_slam.graph import LoopConstraint, PoseGraph
from radar_slam.loops import (
    make_loop_detector,
)
from radar_slam.loops.config import LOOP_RAPLACE
from radar_slam.loops.consistency import odometry_segment_covariance
from radar_slam.maps.keyframes import KeyframeRecorder
from radar_slam.pipeline.config import PipelineConfig
from radar_slam.pipeline.records import (
    GraphLoopsRun,
    Progress,
    ProgressCallback,
)
from radar_slam.pipeline.steps import (
    BACKEND_REJECT_WEIGHT,
    review_loops,
    sequence_label,
)
from raplace import between, wrap_angle

logger = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
GROSS_CHI2 = 100.0
"""An input loop whose squared Mahalanobis distance from the odometry path between its vertices
exceeds this (a ten-sigma error) is grossly inconsistent and left out of the optimisation."""


@dataclass(frozen=True)
class InputLoop:
    """A loop edge of the input graph and its disagreement with the odometry.

    Attributes:
        edge: the g2o edge (vertex ids i, j).
        chi2: squared Mahalanobis distance of its measurement from the odometry's T_i^-1 T_j,
            under the loop's covariance plus the drift of the odometry path between i and j.
        error_m: translation part of that disagreement [m].
    """

    edge: G2oEdge
    chi2: float
    error_m: float

    @property
    def gross(self) -> bool:
        """Grossly inconsistent with the odometry (left out)."""
        return self.chi2 > GROSS_CHI2

    def name(self) -> str:
        return f"EDGE_SE2 {self.edge.i} {self.edge.j}"


def input_loops(record: G2oGraph) -> list[InputLoop]:
    """The input graph's edges between non-consecutive vertices, each checked against the
    odometry path (the vertex poses) between its two vertices."""
    keys = record.keys()
    rank = {key: n for n, key in enumerate(keys)}
    poses = record.poses()
    path_m = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(poses[:, :2], axis=0).T))])
    loops = []
    for edge in record.edges:
        a, b = rank[edge.i], rank[edge.j]
        if abs(a - b) == 1:
            continue
        predicted = between(poses[a], poses[b])
        error = np.asarray(between(predicted, edge.measurement), dtype=np.float64)
        error[2] = wrap_angle(error[2])
        covariance = edge.covariance + odometry_segment_covariance(abs(path_m[b] - path_m[a]))
        chi2 = float(error @ np.linalg.solve(covariance, error))
        loops.append(InputLoop(edge, chi2, float(np.hypot(error[0], error[1]))))
    return loops


def graph_of_input(record: G2oGraph, config: PipelineConfig) -> tuple[PoseGraph, list[InputLoop]]:
    """The input as a `PoseGraph` without its grossly inconsistent loops (each named in a
    warning), and its loops."""
    loops = input_loops(record)
    gross = [loop for loop in loops if loop.gross]
    for loop in gross:
        logger.warning(
            "%s contradicts the odometry between its vertices by %.2f m (chi2 %.0f); left out "
            "of the optimisation",
            loop.name(),
            loop.error_m,
            loop.chi2,
        )
    left_out = {id(loop.edge) for loop in gross}
    kept = [edge for edge in record.edges if id(edge) not in left_out]
    trusted = G2oGraph(record.vertices, kept, record.fixed)
    return g2o_to_pose_graph(trusted, config.graph), loops


def warn_of_rejected_input_loops(graph: PoseGraph, loops: list[InputLoop]) -> None:
    """Name the input loops that the final pass weighted down as inconsistent."""
    weights = graph.loop_weights()
    ids = {(c.i, c.j): n for n, c in graph.constraints() if c.kind == "loop"}
    for loop in loops:
        n = ids.get((loop.edge.i, loop.edge.j))
        weight = weights.get(n, 1.0) if n is not None else 1.0
        if not loop.gross and weight < BACKEND_REJECT_WEIGHT:
            logger.warning(
                "%s is inconsistent with the rest of the graph (weight %.2f after the final "
                "%s pass); it barely acts on the result",
                loop.name(),
                weight,
                graph.config.final_pass,
            )


def vertex_result(
    key: int, timestamp_ns: int, pose: FloatArray, previous: OdometryResult | None
) -> OdometryResult:
    """A vertex of the input graph as an odometry result (what the scan records take of one:
    key, time, pose T_world_scan (3,) and the motion from the previous vertex)."""
    motion = np.zeros(3) if previous is None else between(previous.pose, pose)
    return OdometryResult(
        index=key,
        timestamp_ns=timestamp_ns,
        pose=np.asarray(pose, dtype=np.float64),
        motion=np.asarray(motion, dtype=np.float64),
        covariance=np.zeros((3, 3)),
        keyframe_index=key if previous is None else previous.index,
        keyframe_motion=np.asarray(motion, dtype=np.float64),
        is_keyframe=True,
        ok=True,
        gap=False,
        quality=0.0,
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
    graph, given = graph_of_input(record, config)
    poses = record.poses()
    records = KeyframeRecorder(
        config.maps, config.odometry, LOOP_RAPLACE.descriptor, keep_map=False
    )  # keyed by vertex id
    detector = make_loop_detector(
        config.loop_closure,
        scan_loader=records.scan,
        on_describe=records.offer_descriptor,
        odometry=config.odometry,
    )
    start = time.perf_counter()
    loops: list[LoopConstraint] = []
    previous: OdometryResult | None = None
    for n, key in enumerate(keys):
        frame = sequence[n]
        loops += detector.add(frame, poses[n], key)
        previous = vertex_result(key, int(frame.timestamp_ns), poses[n], previous)
        records.add(frame, None, previous)
        if progress is not None:
            accepted, rejected = detector.tally()
            progress(Progress(n + 1, len(keys), accepted, rejected, time.perf_counter() - start))
    loops += detector.finish()
    records.finish()
    loop_ids = {
        (loop.i, loop.j): graph.add_loop(loop.i, loop.j, loop.measurement, loop.covariance)
        for loop in loops
    }
    graph.update()
    graph.optimize_final()
    review_loops(graph, loop_ids, detector)
    warn_of_rejected_input_loops(graph, given)
    left_out = sum(loop.gross for loop in given)
    return GraphLoopsRun(
        graph, detector.decisions, time.perf_counter() - start, len(given), left_out
    )
