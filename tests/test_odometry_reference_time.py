"""A scan's pose at its reference time: its mid-sweep image pose moved by the velocity
(`odometry.velocity`), and results that chain in those poses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from odometry import Odometry, OdometryResult
from odometry.preprocess import motion_from_twist
from odometry.velocity import Velocity, interpolated_twist, pose_at_reference
from radar_slam.datasets import open_sequence
from radar_slam.datasets.stride import strided
from raplace import se2


@pytest.fixture(scope="module")
def reversals(synthetic_root: Path) -> tuple[Odometry, list[OdometryResult]]:
    """The odometry over tiny_roundabouts at --stride 2 and the results `register` returned."""
    sequence = strided(open_sequence("synthetic/tiny_roundabouts", synthetic_root), 2)
    odometry = Odometry()
    returned = [odometry.register(sequence[k]) for k in range(len(sequence))]
    return odometry, returned


def test_results_chain(reversals: tuple[Odometry, list[OdometryResult]]) -> None:
    """Each result's motion chains the poses, and its motion from the scan it registered
    against chains that scan's pose; `results` holds what `register` returned."""
    odometry, returned = reversals
    results = odometry.results
    assert odometry.gaps == []
    for a, b in zip(results, returned, strict=True):
        np.testing.assert_array_equal(a.pose, b.pose)
    poses = np.array([r.pose for r in results])
    motions = np.array([r.motion for r in results[1:]])
    np.testing.assert_allclose(se2.compose(poses[:-1], motions), poses[1:], atol=1e-9)
    for r in results[1:]:
        chained = se2.compose(results[r.keyframe_index].pose, r.keyframe_motion)
        np.testing.assert_allclose(chained, r.pose, atol=1e-9)
        assert np.allclose(r.covariance, r.covariance.T) and np.linalg.eigvalsh(r.covariance)[0] > 0


def test_interpolated_twist_is_linear_between_the_measurements() -> None:
    before = Velocity(twist=np.array([10.0, 0.0, 0.4]), time_ns=1_000_000_000)
    after = Velocity(twist=np.array([12.0, 1.0, -0.4]), time_ns=1_250_000_000)
    np.testing.assert_allclose(
        interpolated_twist(before, after, 1_187_500_000), [11.5, 0.75, -0.2], atol=1e-12
    )
    np.testing.assert_allclose(interpolated_twist(before, after, 0), before.twist)
    np.testing.assert_allclose(interpolated_twist(before, after, 2_000_000_000), after.twist)


def test_pose_at_reference_follows_the_arc() -> None:
    """An image 0.125 s before the reference time, on a 10 m/s, 40 deg/s arc."""
    twist = np.array([10.0, 0.0, np.deg2rad(40.0)])
    image_pose = np.array([5.0, -2.0, 0.3])
    pose = pose_at_reference(image_pose, twist, -0.125)
    np.testing.assert_allclose(
        pose, se2.compose(image_pose, motion_from_twist(twist, 0.125)), atol=1e-12
    )
    assert np.rad2deg(pose[2] - image_pose[2]) == pytest.approx(5.0)
