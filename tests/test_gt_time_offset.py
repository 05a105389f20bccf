"""The GT clock offset from speed profiles (known answers, one on the real GNSS of the Edinburgh
drive against our real odometry), and the metrics that fit a metre-level GT."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from radar_slam.cli import main
from radar_slam.datasets import DatasetConfig, open_sequence
from radar_slam.evaluation.gt_report import ground_truth_report
from radar_slam.evaluation.metrics import drift_lengths_m, evaluate
from radar_slam.evaluation.time_offset import (
    estimate_time_offset,
    ground_truth_at,
    ground_truth_with_offset,
)
from radar_slam.trajectory import Trajectory, read_tum, write_tum
from raplace import se2
from raplace.units import NS_PER_S

REAL_ODOMETRY = Path(__file__).parent / "data" / "radiate_edinburgh_odometry.tum"


def _stop_and_go(rate_hz: float, start_s: float = 0.0, duration_s: float = 120.0) -> Trajectory:
    """A straight drive whose speed swings between 2 and 12 m/s; positions sampled at `rate_hz`
    from `start_s` on the drive's own clock, stamped as if that were time zero's clock."""
    fine_t = np.arange(0.0, 200.0, 0.001)
    speed = 7.0 + 5.0 * np.sin(2 * np.pi * fine_t / 23.0) * np.sin(2 * np.pi * fine_t / 61.0)
    distance = np.cumsum(speed) * 0.001
    t = np.arange(start_s, start_s + duration_s, 1.0 / rate_hz)
    x = np.interp(t, fine_t, distance)
    poses = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=-1)
    return Trajectory(np.round((t - start_s) * NS_PER_S).astype(np.int64), poses)


def test_an_offset_between_two_clocks_is_recovered_from_speeds_alone() -> None:
    estimate = _stop_and_go(4.0, start_s=10.0)
    # The GT sees the same drive 1.3 s later on its clock, sampled at 16 Hz, turned and moved.
    gt = _stop_and_go(16.0, start_s=10.0 - 1.3, duration_s=125.0)
    gt = Trajectory(gt.timestamps_ns, se2.compose([500.0, -20.0, 1.0], gt.poses))
    offset = estimate_time_offset(estimate, gt)
    assert offset is not None
    assert offset.offset_s == pytest.approx(1.3, abs=0.01)
    assert offset.sigma_s < 0.02 and offset.correlation > 0.99
    assert offset.halves_s == pytest.approx((1.3, 1.3), abs=0.02)


def test_an_estimate_at_one_hertz_still_has_a_speed_profile() -> None:
    estimate = _stop_and_go(1.0, start_s=10.0)
    gt = _stop_and_go(4.0, start_s=10.0 + 0.4, duration_s=125.0)
    offset = estimate_time_offset(estimate, gt)
    assert offset is not None and offset.offset_s == pytest.approx(-0.4, abs=0.03)


def test_a_drive_at_constant_speed_gives_no_offset() -> None:
    t = np.arange(0, 60 * NS_PER_S, NS_PER_S // 4, dtype=np.int64)
    poses = np.stack([10.0 * t / NS_PER_S, 0 * t, 0 * t], axis=-1).astype(np.float64)
    assert estimate_time_offset(Trajectory(t, poses), Trajectory(t, poses)) is None


def test_gt_read_through_an_offset_skips_outages_instead_of_bridging_them() -> None:
    t = np.array([0, 1, 2, 5, 6], dtype=np.int64) * (NS_PER_S // 4)  # a gap of 0.75 s
    poses = np.stack([np.arange(5.0), np.zeros(5), np.zeros(5)], axis=-1)
    gt = Trajectory(t, poses)
    at = ground_truth_at(gt, np.array([NS_PER_S // 8, NS_PER_S * 3 // 4]))
    assert at[0] == pytest.approx([0.5, 0, 0]) and np.isnan(at[1]).all()
    shifted = ground_truth_with_offset(gt, np.array([0, NS_PER_S // 4]), 0.125)
    assert shifted.poses[:, 0] == pytest.approx([0.5, 1.5])


@pytest.mark.realdata
def test_an_offset_injected_into_the_real_gnss_is_recovered_against_real_odometry(
    shared_data: Path,
) -> None:
    folder = shared_data / "radiate" / "edinburgh_2019-02-12-15-33"
    odometry = read_tum(REAL_ODOMETRY)
    found = {}
    for injected in (0.0, 0.7):
        sequence = open_sequence(folder, options=DatasetConfig(gt_time_offset_s=injected))
        assert sequence.ground_truth is not None
        gt = Trajectory.from_arrays(
            sequence.timestamps_ns, sequence.ground_truth, drop_nonfinite=True
        )
        offset = estimate_time_offset(odometry, gt)
        assert offset is not None
        found[injected] = offset
    # The GNSS lags the radar stamps by well over a second; its two halves agree.
    assert 1.0 < found[0.0].offset_s < 3.0
    assert abs(found[0.0].halves_s[0] - found[0.0].halves_s[1]) < 0.2
    assert found[0.0].offset_s - found[0.7].offset_s == pytest.approx(0.7, abs=0.05)
    # Read through the estimate, the odometry meets the bars a 4 Hz radar odometry should.
    report = ground_truth_report(open_sequence(folder).ground_truth_source, gt, {})
    assert report.time_offset is None  # nothing to score
    sequence = open_sequence(folder)
    assert sequence.ground_truth is not None
    gt = Trajectory.from_arrays(sequence.timestamps_ns, sequence.ground_truth, drop_nonfinite=True)
    report = ground_truth_report(sequence.ground_truth_source, gt, {"odometry": odometry})
    scored = report.offset_applied["odometry"]
    as_stamped = evaluate(odometry, gt, gt_accuracy_m=2.0)
    assert scored.ate_rmse_m < 2.0 < as_stamped.ate_rmse_m
    assert scored.end_point_error_pct is not None and scored.end_point_error_pct < 1.5
    assert scored.drift_min_segment_m == 400.0


def test_drift_uses_only_segments_long_enough_for_the_gt() -> None:
    assert drift_lengths_m(0.0)[0] == 100.0
    assert drift_lengths_m(0.05)[0] == 100.0
    assert drift_lengths_m(2.0) == (400.0, 500.0, 600.0, 700.0, 800.0)
    assert drift_lengths_m(50.0) == (800.0,)


def test_end_point_error_is_the_last_pose_after_alignment_per_distance() -> None:
    t = np.arange(101, dtype=np.int64) * NS_PER_S
    gt_poses = np.stack([np.arange(101.0) * 2, np.zeros(101), np.zeros(101)], axis=-1)
    est_poses = gt_poses.copy()
    est_poses[-1, 1] = 4.0  # the last pose 4 m off a 200 m path
    metrics = evaluate(Trajectory(t, est_poses), Trajectory(t, gt_poses))
    # The alignment spreads part of it over the path; what is left at the end is most of it.
    assert 1.5 < metrics.end_point_error_pct < 2.0


def test_eval_prints_the_offset_and_both_sets_of_rows(tmp_path: Path, capsys) -> None:
    estimate = _stop_and_go(4.0, start_s=10.0)
    gt = _stop_and_go(16.0, start_s=10.0 - 0.8, duration_s=125.0)
    write_tum(tmp_path / "est.tum", estimate)
    write_tum(tmp_path / "gt.tum", gt)
    out = tmp_path / "m.json"
    args = ["eval", str(tmp_path / "est.tum"), str(tmp_path / "gt.tum"), "--json", str(out)]
    assert main([*args, "--estimate-offset", "--gt-accuracy", "2"]) == 0
    text = capsys.readouterr().out
    assert "GT clock offset +0.800 +-" in text and "est (GT offset +0.800 s)" in text
    data = json.loads(out.read_text())
    stamped, shifted = data["est"], data["est (GT offset +0.800 s)"]
    assert shifted["ate_rmse_m"] < 0.05 < stamped["ate_rmse_m"]
    assert shifted["drift_min_segment_m"] == 400.0
    kitti = tmp_path / "est.kitti"
    kitti.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n")
    assert main(["eval", str(kitti), str(kitti), "--estimate-offset"]) != 0
    assert "needs timestamps" in capsys.readouterr().err
