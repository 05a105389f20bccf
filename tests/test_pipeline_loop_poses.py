"""The pipeline hands each scan to the loop detector and to the pose graph with its revised pose
(once the next scan has registered), not the prompt one, so that the detector's de-skew
velocities and the graph's odometry factors are the odometry's best: the prompt pose of a scan
swept across a yaw-rate step is the least accurate."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from odometry.odometry import Odometry
from radar_slam.datasets.frame import RadarSequence
from radar_slam.loops import NullLoopDetector
from radar_slam.loops.records import LoopConstraint
from radar_slam.pipeline import Pipeline, PipelineConfig

FRAMES = 24
MIN_REVISED_M = 1e-4  # a revision that counts as moving a pose [m]


class PoseRecorder(NullLoopDetector):
    """Records the poses and keys it is given, finds no loop."""

    def __init__(self) -> None:
        super().__init__()
        self.poses: dict[int, np.ndarray] = {}
        self.finished_after = -1

    def add(
        self, scan: object, pose: ArrayLike | None = None, key: int | None = None
    ) -> list[LoopConstraint]:
        assert key is not None and pose is not None and key not in self.poses
        self.poses[key] = np.asarray(pose, dtype=np.float64)
        return []

    def finish(self) -> list[LoopConstraint]:
        self.finished_after = len(self.poses)
        return []


def test_loop_detector_and_graph_get_every_scan_with_its_revised_pose(tiny: RadarSequence) -> None:
    recorder = PoseRecorder()
    config = PipelineConfig()
    pipeline = Pipeline(tiny, config, max_frames=FRAMES, loop_detector=recorder)
    results = pipeline.run()
    assert sorted(recorder.poses) == list(range(FRAMES)) and recorder.finished_after == FRAMES
    revised = np.array([r.pose for r in pipeline.odometry.results])
    odometry = Odometry(config.odometry)
    prompt = np.array([odometry.register(tiny[k]).pose for k in range(FRAMES)])
    given = np.array([recorder.poses[k] for k in range(FRAMES)])
    np.testing.assert_allclose(given, revised, atol=1e-12)
    np.testing.assert_allclose(results.odometry.poses, revised, atol=1e-12)
    # Without loops the graph is the chain of its odometry factors: the revised poses.
    np.testing.assert_allclose(results.slam.poses, revised, atol=1e-6)
    moved = np.hypot(*(revised[:-1, :2] - prompt[:-1, :2]).T) > MIN_REVISED_M
    assert moved.any()  # the revision did move poses here, so the test tells the two apart
