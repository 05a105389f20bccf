"""Known-answer tests of association, alignment, ATE, RPE and KITTI drift."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from radar_slam.errors import TrajectoryError
from radar_slam.evaluation.metrics import (
    TrajectoryMetrics,
    align,
    associate,
    ate_origin_rmse,
    ate_rmse,
    evaluate,
    kitti_drift,
    rpe_trans_rmse,
    to_evo,
    umeyama_alignment_se2,
)
from radar_slam.trajectory import Trajectory
from raplace.se2 import compose, inverse

EXACT = 1e-9
STEP_NS = 100_000_000  # 10 Hz
RIGID = np.array([12.0, -7.0, 0.8])  # an arbitrary SE(2) transform (x, y, yaw)


def drive(motions: np.ndarray, start: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> Trajectory:
    """Chain (N - 1, 3) motions into a 10 Hz trajectory."""
    stamps = np.arange(len(motions) + 1, dtype=np.int64) * STEP_NS
    return Trajectory.from_relative_motions(stamps, motions, start)


def curved(n: int = 120, seed: int = 1) -> Trajectory:
    """A winding drive with 1 m steps."""
    rng = np.random.default_rng(seed)
    return drive(np.column_stack([np.ones(n - 1), np.zeros(n - 1), rng.uniform(-0.2, 0.2, n - 1)]))


def straight(n: int, step_m: float = 1.0, yaw_rate: float = 0.0) -> Trajectory:
    """n poses along x, `step_m` apart, turning `yaw_rate` [rad] after each step."""
    return drive(np.tile([step_m, 0.0, yaw_rate], (n - 1, 1)))


def moved(traj: Trajectory, transform: np.ndarray) -> Trajectory:
    return Trajectory(traj.timestamps_ns, compose(transform, traj.poses))


# ---------------------------------------------------------------------- alignment and ATE
def test_rigid_copy_has_zero_aligned_ate_but_origin_ate_sees_first_pose() -> None:
    gt = curved()
    est_poses = compose(RIGID, gt.poses)
    est_poses[0, 2] += 0.05  # positions still rigid; only the first heading differs
    est = Trajectory(gt.timestamps_ns, est_poses)
    assert ate_rmse(est, gt) < EXACT
    np.testing.assert_allclose(umeyama_alignment_se2(est, gt), inverse(RIGID), atol=1e-9)
    assert ate_origin_rmse(est, gt) > 1.0
    # without the perturbed heading, first-pose alignment is exact too
    assert ate_origin_rmse(moved(gt, RIGID), gt) < EXACT


def test_evo_alignment_of_planar_trajectories_is_a_rotation_about_z() -> None:
    gt = curved()
    est = moved(gt, RIGID)
    rotation, translation, scale = to_evo(est).align(to_evo(gt), correct_scale=False)
    assert scale == 1.0
    np.testing.assert_allclose(rotation[2], [0.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(rotation[:, 2], [0.0, 0.0, 1.0], atol=1e-12)
    assert abs(translation[2]) < 1e-12
    aligned = align(est, gt)
    np.testing.assert_allclose(aligned.poses, gt.poses, atol=1e-9)


def test_mirrored_trajectory_is_not_flipped_out_of_the_plane() -> None:
    gt = curved()
    mirrored = Trajectory(gt.timestamps_ns, gt.poses * [1.0, -1.0, -1.0])
    # evo's 3-D Umeyama "fixes" a mirror image by turning it over (rotation pi about x) ...
    evo_est = to_evo(mirrored)
    rotation, _, _ = evo_est.align(to_evo(gt))
    assert rotation[2, 2] == pytest.approx(-1.0)
    # ... which SE(2) forbids: our alignment stays about z and the error stays visible
    expected = _kabsch_2d_rmse(mirrored.positions, gt.positions)
    assert ate_rmse(mirrored, gt) == pytest.approx(expected, rel=1e-9)
    assert expected > 1.0


def _kabsch_2d_rmse(src: np.ndarray, dst: np.ndarray) -> float:
    """Reference: best proper 2-D rotation + translation of src onto dst, by brute force."""
    angles = np.linspace(-np.pi, np.pi, 200_001)
    a, b = src - src.mean(0), dst - dst.mean(0)
    # residual of rotating a by theta: |a|^2 + |b|^2 - 2 (cos C + sin S)
    c_term = np.sum(a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1])
    s_term = np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
    best = angles[np.argmax(np.cos(angles) * c_term + np.sin(angles) * s_term)]
    theta = np.arctan2(s_term, c_term)
    assert abs(best - theta) < 1e-4
    rot = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    return float(np.sqrt(np.mean(np.sum((a @ rot.T - b) ** 2, axis=1))))


def test_collinear_trajectory_aligns() -> None:
    gt = straight(20)
    est = moved(gt, RIGID)  # evo's 3-D Umeyama calls a straight line degenerate
    assert ate_rmse(est, gt) < EXACT


# ---------------------------------------------------------------------- RPE
def test_rpe_of_exact_copy_is_zero_and_scale_error_is_seen() -> None:
    gt = curved()
    assert rpe_trans_rmse(moved(gt, RIGID), gt) < EXACT
    long = straight(50, step_m=1.01)
    line = straight(50)
    assert rpe_trans_rmse(long, line) == pytest.approx(0.01, abs=EXACT)
    assert rpe_trans_rmse(long, line, delta=5) == pytest.approx(0.05, abs=EXACT)
    assert rpe_trans_rmse(long, line, delta=10, unit="m") == pytest.approx(0.10, abs=EXACT)
    with pytest.raises(TrajectoryError, match="RPE"):
        rpe_trans_rmse(long, line, delta=100)


# ---------------------------------------------------------------------- KITTI drift
def test_straight_line_with_one_percent_scale_error() -> None:
    drift = kitti_drift(straight(901, step_m=1.01), straight(901))
    assert drift is not None
    assert drift.trans_pct == pytest.approx(1.0, abs=1e-9)
    assert drift.rot_deg_per_100m == pytest.approx(0.0, abs=1e-12)
    # segments: length L fits from the starts 0, 10, ..., 900 - L: 81 of 100 m, 71 of 200 m, ...,
    # 11 of 800 m
    assert drift.segments == 81 + 71 + 61 + 51 + 41 + 31 + 21 + 11


def test_constant_yaw_rate_drift_by_hand() -> None:
    yaw_rate = 0.001  # rad per 1 m step
    gt, est = straight(151), straight(151, yaw_rate=yaw_rate)
    # 150 m of GT: only 100 m segments fit, from starts 0, 10, ..., 50, each 100 steps long.
    # Over k = 100 steps the estimate, turning after each step, ends at
    # sum_j (cos j w, sin j w), j = 0..k-1, with heading k w; GT ends at (k, 0) heading 0.
    k = 100
    j = np.arange(k)
    end_est = np.array([np.sum(np.cos(j * yaw_rate)), np.sum(np.sin(j * yaw_rate))])
    trans_error_m = np.hypot(k - end_est[0], end_est[1])
    drift = kitti_drift(est, gt)
    assert drift is not None
    assert drift.segments == 6
    assert drift.trans_pct == pytest.approx(trans_error_m / k * 100, rel=1e-9)
    assert drift.rot_deg_per_100m == pytest.approx(np.degrees(k * yaw_rate) / k * 100, rel=1e-9)


def test_drift_undefined_below_100_m(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.INFO, logger="radar_slam.evaluation.metrics"):
        assert kitti_drift(straight(90), straight(90)) is None
    assert "shorter than the shortest segment" in caplog.text
    metrics = evaluate(straight(90), straight(90))
    assert metrics.drift_trans_pct is None and metrics.drift_rot_deg_per_100m is None


# ---------------------------------------------------------------------- association
def test_association_by_timestamp_with_a_missing_pose_and_jitter() -> None:
    gt = curved(40)
    keep = np.delete(np.arange(len(gt)), 7)
    jitter = np.where(np.arange(len(keep)) % 2 == 0, 900_000, -900_000)  # within 1 ms
    est = Trajectory(gt.timestamps_ns[keep] + jitter, gt.poses[keep])
    est_a, gt_a = associate(est, gt)
    assert len(est_a) == len(gt) - 1
    np.testing.assert_array_equal(gt_a.timestamps_ns, gt.timestamps_ns[keep])
    metrics = evaluate(est, gt)
    assert metrics.poses_matched == len(gt) - 1
    assert metrics.ate_rmse_m < EXACT
    # a tighter tolerance leaves nothing in common
    with pytest.raises(TrajectoryError, match="no common poses"):
        associate(est, gt, max_diff_ns=100_000)


def test_association_is_one_to_one() -> None:
    gt = Trajectory(np.array([0, 100]), np.zeros((2, 3)))
    est = Trajectory(np.array([98, 99, 100, 101]), np.zeros((4, 3)))
    est_a, gt_a = associate(est, gt, max_diff_ns=5)
    assert est_a.timestamps_ns.tolist() == [100]
    assert gt_a.timestamps_ns.tolist() == [100]


def test_association_by_index_needs_equal_counts() -> None:
    gt = curved(30)
    est = Trajectory(np.arange(30), gt.poses)  # KITTI: frame indices as stamps
    assert evaluate(est, gt, by="index").poses_matched == 30
    with pytest.raises(TrajectoryError, match="estimate has 29, ground truth has 30"):
        evaluate(est[:29], gt, by="index")


def test_ground_truth_nan_rows_are_dropped() -> None:
    gt = curved(30)
    poses = gt.poses.copy()
    poses[:3] = np.nan  # scans before the GT span
    gt_nan = Trajectory.from_arrays(gt.timestamps_ns, poses, drop_nonfinite=True)
    metrics = evaluate(gt, gt_nan)
    assert metrics.poses_matched == 27
    assert metrics.ate_rmse_m < EXACT


def test_metrics_dict_has_exactly_the_keys(metric_keys: frozenset[str]) -> None:
    gt = straight(150)
    metrics = evaluate(straight(150, step_m=1.01), gt)
    assert isinstance(metrics, TrajectoryMetrics)
    assert set(metrics.to_dict()) == metric_keys
    assert metrics.drift_trans_pct == pytest.approx(1.0, abs=1e-9)
    assert metrics.rpe_trans_rmse_m == pytest.approx(0.01, abs=1e-9)
