"""The stateful `Odometry` over the real Oxford scans: keyframes, gaps, errors."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from odometry import OdometryError
from odometry.odometry import Odometry
from radar_slam.datasets import OxfordSequence
from radar_slam.datasets.frame import RadarFrame
from raplace import se2

pytestmark = pytest.mark.realdata

MAX_PAIR_ERROR_M = 0.15
MAX_PAIR_ERROR_DEG = 0.3
MAX_END_ERROR_M = 0.4  # after 12.5 m, mostly the GT's lateral offset (README, Limits)


@pytest.fixture(scope="module")
def frames(oxford_dir: Path) -> list[RadarFrame]:
    sequence = OxfordSequence(oxford_dir)
    return [sequence[k] for k in range(len(sequence))]


@pytest.fixture(scope="module")
def ground_truth(oxford_dir: Path) -> np.ndarray:
    gt = OxfordSequence(oxford_dir).ground_truth
    assert gt is not None
    return gt


def test_odometry_follows_ground_truth(frames: list[RadarFrame], ground_truth: np.ndarray) -> None:
    odometry = Odometry()
    results = [odometry.register(frame) for frame in frames]
    assert all(r.ok and not r.gap for r in results)
    assert [r.timestamp_ns for r in results] == [f.timestamp_ns for f in frames]
    assert results[0].is_keyframe and results[0].keyframe_index == 0
    np.testing.assert_array_equal(results[0].pose, np.zeros(3))
    assert odometry.keyframes[0] == 0 and odometry.gaps == []
    # The odometry counts its own registrations: none for the first scan, one or more after.
    assert results[0].registrations == 0
    assert all(r.registrations >= 1 for r in results[1:])
    assert odometry.registrations_per_scan == np.mean([r.registrations for r in results[1:]])
    for r in results[1:]:
        # Each scan is registered against an earlier keyframe; its motion chains the poses.
        assert r.keyframe_index < r.index
        np.testing.assert_allclose(
            se2.compose(results[r.index - 1].pose, r.motion), r.pose, atol=1e-9
        )
        assert np.all(np.linalg.eigvalsh(r.covariance) > 0)

    relative = se2.relative_motions(odometry.poses)
    truth = se2.relative_motions(ground_truth)
    diff = se2.between(truth, relative)
    assert np.hypot(diff[:, 0], diff[:, 1]).max() <= MAX_PAIR_ERROR_M
    assert np.rad2deg(np.abs(diff[:, 2])).max() <= MAX_PAIR_ERROR_DEG
    end = se2.between(ground_truth[-1], odometry.poses[-1])
    assert np.hypot(end[0], end[1]) <= MAX_END_ERROR_M
    assert odometry.velocity is not None and 6.0 < odometry.velocity[0] < 10.0


def test_failed_registration_is_a_flagged_constant_velocity_gap(
    frames: list[RadarFrame], ground_truth: np.ndarray
) -> None:
    blank = dataclasses.replace(frames[3], polar=np.zeros_like(frames[3].polar))
    odometry = Odometry()
    results = [odometry.register(f) for f in frames[:3] + [blank] + frames[4:]]
    gap = results[3]
    assert gap.gap and not gap.ok and gap.reason and not gap.is_keyframe
    # The prediction continues the previous motion: never a silent zero.
    np.testing.assert_allclose(gap.motion, results[2].motion, atol=0.05)
    assert gap.covariance[0, 0] > 100 * results[2].covariance[0, 0]
    assert odometry.gaps == [3]
    # The next scan goes back to the keyframe and recovers an accurate pose.
    assert all(r.ok for r in results[4:])
    end = se2.between(ground_truth[-1], odometry.poses[-1])
    assert np.hypot(end[0], end[1]) <= MAX_END_ERROR_M


def test_time_must_increase(frames: list[RadarFrame]) -> None:
    odometry = Odometry()
    odometry.register(frames[1])
    with pytest.raises(OdometryError):
        odometry.register(frames[0])


def test_start_pose_sets_the_world_frame(frames: list[RadarFrame]) -> None:
    start = np.array([10.0, -5.0, 0.5])
    odometry = Odometry(start_pose=start)
    first = odometry.register(frames[0])
    second = odometry.register(frames[1])
    np.testing.assert_allclose(first.pose, start)
    np.testing.assert_allclose(se2.between(start, second.pose), second.motion, atol=1e-9)
