"""The pipeline hands each scan to the loop detector with its revised pose (once the next scan
has registered), not the prompt one, so that the detector's de-skew velocities are the odometry's
best: the prompt pose of a scan swept across a yaw-rate step is the least accurate."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

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


def test_loop_detector_gets_every_scan_with_its_revised_pose(tiny: RadarSequence) -> None:
    recorder = PoseRecorder()
    pipeline = Pipeline(tiny, PipelineConfig(), max_frames=FRAMES, loop_detector=recorder)
    results = pipeline.run()
    assert sorted(recorder.poses) == list(range(FRAMES)) and recorder.finished_after == FRAMES
    revised = np.array([r.pose for r in pipeline.odometry.results])
    prompt = np.array([r.pose for r in results.odometry_results])
    given = np.array([recorder.poses[k] for k in range(FRAMES)])
    np.testing.assert_allclose(given, revised, atol=1e-12)
    moved = np.hypot(*(revised[:-1, :2] - prompt[:-1, :2]).T) > MIN_REVISED_M
    assert moved.any()  # the revision did move poses here, so the test tells the two apart
