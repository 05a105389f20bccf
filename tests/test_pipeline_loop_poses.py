"""The pipeline hands every scan to the loop detector and to the pose graph with the pose the
odometry gave it, once, in order; without loops the graph is the chain of its odometry factors."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from odometry import PolarScan, Scan
from odometry.odometry import Odometry
from radar_slam.datasets.frame import RadarSequence
from radar_slam.loops import NullLoopDetector
from radar_slam.loops.records import LoopConstraint
from radar_slam.pipeline import Pipeline, PipelineConfig

FRAMES = 24


class PoseRecorder(NullLoopDetector):
    """Records the poses and keys it is given, finds no loop."""

    def __init__(self) -> None:
        super().__init__()
        self.poses: dict[int, np.ndarray] = {}
        self.finished_after = -1

    def add(
        self,
        scan: Scan,
        pose: ArrayLike | None = None,
        key: int | None = None,
        polar: PolarScan | None = None,
    ) -> list[LoopConstraint]:
        assert key is not None and pose is not None and key not in self.poses
        assert polar is not None and polar.timestamp_ns == scan.timestamp_ns
        self.poses[key] = np.asarray(pose, dtype=np.float64)
        return []

    def finish(self) -> list[LoopConstraint]:
        self.finished_after = len(self.poses)
        return []


def test_loop_detector_and_graph_get_every_scan_with_its_odometry_pose(tiny: RadarSequence) -> None:
    recorder = PoseRecorder()
    config = PipelineConfig()
    pipeline = Pipeline(tiny, config, max_frames=FRAMES, loop_detector=recorder)
    results = pipeline.run()
    assert sorted(recorder.poses) == list(range(FRAMES)) and recorder.finished_after == FRAMES
    odometry = Odometry(config.odometry)
    alone = np.array([odometry.register(tiny[k]).pose for k in range(FRAMES)])
    given = np.array([recorder.poses[k] for k in range(FRAMES)])
    assert np.hypot(*(alone[-1, :2] - alone[0, :2])) > 10.0  # the scans moved
    np.testing.assert_allclose(given, alone, atol=1e-12)
    np.testing.assert_allclose(results.odometry.poses, alone, atol=1e-12)
    np.testing.assert_allclose(results.slam.poses, alone, atol=1e-6)
