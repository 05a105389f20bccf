"""Consistency of the pose graph's factors against the ground truth (`radar_slam.evaluation.nees`)
and the loop covariance's de-skew terms (`LoopCovarianceConfig.deskew_error_fraction`,
`swept_turn_fraction`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from odometry import RadarFrame
from radar_slam.datasets import open_sequence
from radar_slam.datasets.frame import RadarSequence
from radar_slam.datasets.stride import strided
from radar_slam.evaluation.nees import factor_error, factor_nees
from radar_slam.loops import verification
from radar_slam.loops.config import CHI2_3DOF_99, LoopCovarianceConfig
from radar_slam.loops.records import KeyScan
from radar_slam.loops.verification import deskew_variance, loop_covariance, swept_turn_variance
from radar_slam.pipeline import Pipeline, Results, load_config
from radar_slam.pipeline.steps import odometry_factor
from raplace import se2
from raplace.se2 import compose

NEES_RANGE = (1.0, 6.0)
"""Mean NEES of a factor type (3 when calibrated)."""
TURNING_DPS = 5.0
"""An odometry step turns when its true yaw rate is above this [deg/s] (as `bench_nees`)."""
CALIBRATED = {"odometry": {"quality": {"sigma_scale": 1.5}}}
"""The settings that calibrate both factor types alike at 4 Hz (docs/decisions.md,
covariance notes and "The graph takes the revised odometry"), with `CALIBRATED_LOOPS`; not the
defaults, which keep both conservative at 4 Hz (on `tiny_loop` mean NEES 0.33 for the revised
odometry factors, 0.50 for the loops, below `NEES_RANGE`)."""
CALIBRATED_LOOPS = LoopCovarianceConfig(
    # On top of the odometry's 1.5, which the verifier's registration uses (mean loop NEES
    # 2.3 / 2.1 on `loop` / `reverse`, per axis below 1: still conservative).
    sigma_scale=0.8,
    disagreement_weight=0.1,
    min_sigma_xy_m=0.01,
    min_sigma_yaw_deg=0.02,
    deskew_error_fraction=0.5,
    swept_turn_fraction=0.1,
)
"""The loop covariance model of the calibrated run (in place of `LOOP_COVARIANCE`)."""


def test_factor_error_is_the_truth_seen_from_the_measurement() -> None:
    truth_i = np.array([10.0, -2.0, 0.7])
    measurement = np.array([3.0, 1.0, np.deg2rad(30.0)])
    offset = np.array([0.05, -0.02, np.deg2rad(0.4)])
    truth_j = compose(truth_i, compose(measurement, offset))
    np.testing.assert_allclose(factor_error(measurement, truth_i, truth_j), offset, atol=1e-12)
    covariance = np.diag([0.05**2, 0.04**2, np.deg2rad(0.2) ** 2])
    result = factor_nees(measurement, covariance, truth_i, truth_j)
    assert result.nees == pytest.approx(1.0 + 0.25 + 4.0)
    np.testing.assert_allclose(result.axes, [1.0, 0.25, 4.0])


def _scan(change: tuple[float, float, float] | None) -> KeyScan:
    n_az = 400
    times = np.linspace(0, 250_000_000, n_az, endpoint=False).astype(np.int64)
    frame = RadarFrame(
        timestamp_ns=250_000_000,
        polar=np.zeros((n_az, 8), dtype=np.uint8),
        azimuths_rad=np.linspace(0, 2 * np.pi, n_az, endpoint=False),
        range_resolution_m=0.06,
        sensor="test",
        azimuth_times_ns=times,
    )
    twist_change = None if change is None else np.array(change)
    return KeyScan(0, 250_000_000, frame, np.zeros(3), twist_change)


def test_loop_covariance_grows_with_the_twist_change_of_both_scans() -> None:
    """A yaw-rate step of 30 deg/s across a 250 ms sweep bends it by about 3.75 deg over half
    the sweep; the term adds that fraction as a standard deviation per scan, and nothing for
    scans whose twist did not change."""
    step = (1.0, 0.0, np.deg2rad(30.0))
    variance = deskew_variance(_scan(step), _scan(None))
    # Half of a 399/400 x 250 ms sweep is 0.1247 s: 0.1247 m per 1 m/s, 3.74 deg at 30 deg/s.
    bend = np.array([0.1246875, 0.1246875, np.deg2rad(3.740625)])
    np.testing.assert_allclose(np.sqrt(variance), bend, rtol=1e-9)
    np.testing.assert_allclose(deskew_variance(_scan(step), _scan(step)), 2 * variance)
    cfg = LoopCovarianceConfig(deskew_error_fraction=0.5, swept_turn_fraction=0.1)
    peak = np.diag([1e-4, 1e-4, 1e-6])
    plain = loop_covariance(peak, np.zeros(3), 0.0, cfg)
    bent = loop_covariance(peak, np.zeros(3), 0.0, cfg, variance)
    np.testing.assert_allclose(np.sqrt(np.diag(bent - plain)), 0.5 * bend, rtol=1e-9)
    turning = _scan(None)
    turning = KeyScan(0, turning.timestamp_ns, turning.scan, np.array([5.0, 0.0, 0.5]))
    turn = swept_turn_variance(turning, _scan(None))
    assert np.sqrt(turn) == pytest.approx(0.06234375, rel=1e-9)  # 0.5 rad/s over 0.1247 s
    swept = loop_covariance(peak, np.zeros(3), 0.0, cfg, turn_variance=turn)
    added = np.sqrt(np.diag(swept - plain))
    np.testing.assert_allclose(added, [0.0, 0.0, 0.006234375], rtol=1e-9, atol=1e-12)


@pytest.fixture(scope="module")
def tiny_run(tiny_loop: RadarSequence) -> Results:
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(verification, "LOOP_COVARIANCE", CALIBRATED_LOOPS)
        return Pipeline(tiny_loop, load_config("synthetic", overrides=CALIBRATED)).run()


def test_odometry_and_loop_factors_are_consistent(tiny_run: Results) -> None:
    """On `synthetic/tiny_loop` (reduced bins) with the calibrated settings, the odometry
    factors the graph takes and the accepted loop factors both have a mean NEES in `NEES_RANGE`
    against the ground truth, and every accepted loop is true."""
    assert not any(r.gap for r in tiny_run.odometry_results)
    odometry, loops = factor_nees_of(tiny_run)
    assert len(loops) >= 3
    assert tiny_run.metrics.loops_accepted_true == tiny_run.metrics.loops_accepted
    assert NEES_RANGE[0] <= np.mean(odometry) <= NEES_RANGE[1], np.mean(odometry)
    assert NEES_RANGE[0] <= np.mean(loops) <= NEES_RANGE[1], np.mean(loops)


def factor_nees_of(results: Results) -> tuple[list[float], list[float]]:
    """NEES of every odometry factor and of every accepted loop of a run."""
    truth = results.ground_truth_poses
    assert truth is not None
    odometry = [
        factor_nees(*odometry_factor(r), truth[r.index - 1], truth[r.index]).nees
        for r in results.odometry_results[1:]
    ]
    loops = [
        factor_nees(d.measurement, d.covariance, truth[d.query_key], truth[d.match_key]).nees
        for d in results.loops
        if d.status == "accepted"
    ]
    return odometry, loops


def test_default_factors_are_consistent_at_one_hertz_through_a_turn_around(
    synthetic_root: Path,
) -> None:
    """With the default settings at --stride 4 (1 Hz) through a turn round a block: loops between
    scans swept while turning, odometry steps of 10 m and 45 deg. The de-skew and velocity-lag
    terms keep the mean NEES of the turning steps' odometry factors (true yaw rate above
    `TURNING_DPS`) in range (measured 1.13; 68 without the de-skew and revised-lag terms) and no
    factor type above it; every loop's error is inside its 99 % ellipse (without the loops' terms
    one of five is at 17), and every accepted loop is true. The straight steps are conservative
    at 1 Hz (mean 0.75)."""
    sequence = strided(open_sequence("synthetic/tiny_turn_around", synthetic_root), 4)
    results = Pipeline(sequence, load_config("synthetic")).run()
    odometry, loops = factor_nees_of(results)
    assert len(loops) >= 3
    assert results.metrics.loops_accepted_true == results.metrics.loops_accepted
    truth = results.ground_truth_poses
    assert truth is not None
    stamps_s = np.array([r.timestamp_ns for r in results.odometry_results]) / 1e9
    turn = np.abs(se2.wrap_angle(se2.between(truth[:-1], truth[1:])[:, 2]))
    turning = np.rad2deg(turn) / np.diff(stamps_s) > TURNING_DPS
    assert turning.sum() >= 10
    turning_nees = np.array(odometry)[turning]
    assert NEES_RANGE[0] <= np.mean(turning_nees) <= NEES_RANGE[1], np.mean(turning_nees)
    assert np.mean(odometry) <= NEES_RANGE[1], np.mean(odometry)
    assert max(loops) <= CHI2_3DOF_99, loops
