"""A step of the yaw rate inside a sweep: de-skewed with `RateStep`, searched by peak quality."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from test_odometry_recovery import driven

from odometry import rate_search
from odometry.config import DeskewConfig, OdometryConfig
from odometry.deskew import RateStep
from odometry.odometry import Odometry
from odometry.registration import MotionEstimate, PreparedScan, prepare, register_images
from radar_slam.datasets import OxfordSequence
from radar_slam.datasets.frame import RadarFrame
from raplace import se2
from raplace.units import NS_PER_S
from raplace.warp import polar_sample_coords, remap

SWEEP_S = 0.25
SPEED_MPS = 8.0
RATE_BEFORE_DPS = 0.0
RATE_AFTER_DPS = 40.0
"""A curvature step into a junction turn at 8 m/s (radius about 11 m)."""
MAX_STEPPED_ERROR_DEG = 0.1
MIN_CONSTANT_ERROR_DEG = 0.2
"""A constant de-skew at the sweep's mean rate turns the image by the mean of the yaw it gets
wrong over the sweep: 40 deg/s x 0.25 s / 8 = 1.25 deg at a mid-sweep step, 0.34 deg at a step
60 ms before mid-sweep; the test means something only where the constant twist is that far off."""


def yaw_at(tau_s: np.ndarray, step_s: float) -> np.ndarray:
    """Yaw [rad] at `tau_s` from mid-sweep, the rate stepping at `step_s` (as `RateStep`)."""
    before, after = np.deg2rad(RATE_BEFORE_DPS), np.deg2rad(RATE_AFTER_DPS)
    return before * tau_s + (after - before) * (np.maximum(tau_s, step_s) - max(0.0, step_s))


def stepped_scan(frame: RadarFrame, start: np.ndarray, step_s: float) -> RadarFrame:
    """`frame`'s world re-measured by a sensor sweeping for 250 ms centred on its reference
    time, at `start` (frame's sensor frame) at mid-sweep, driving straight on at SPEED_MPS
    while its yaw rate steps at `step_s` [s] from mid-sweep."""
    n_az, n_bins = frame.polar.shape
    tau = (np.arange(n_az) - 0.5 * (n_az - 1)) * (SWEEP_S / n_az)
    offsets = np.stack([SPEED_MPS * tau, np.zeros(n_az), yaw_at(tau, step_s)], axis=1)
    poses = se2.compose(np.broadcast_to(start, (n_az, 3)), offsets)
    ranges = (np.arange(n_bins) + 0.5) * frame.range_resolution_m
    xs = ranges[None, :] * np.cos(frame.azimuths_rad)[:, None]
    ys = ranges[None, :] * np.sin(frame.azimuths_rad)[:, None]
    c, s = np.cos(poses[:, 2:3]), np.sin(poses[:, 2:3])
    bins, rows = polar_sample_coords(
        c * xs - s * ys + poses[:, 0:1],
        s * xs + c * ys + poses[:, 1:2],
        frame.azimuths_rad,
        frame.range_resolution_m,
    )
    polar = np.clip(np.rint(remap(frame.polar, bins, rows)), 0, 255).astype(np.uint8)
    timestamp = frame.timestamp_ns + int(SWEEP_S * NS_PER_S)
    times = (timestamp + np.rint(tau * NS_PER_S)).astype(np.int64)
    return dataclasses.replace(frame, timestamp_ns=timestamp, polar=polar, azimuth_times_ns=times)


def yaw_error_deg(estimate: MotionEstimate, truth: np.ndarray) -> float:
    return float(np.rad2deg(abs(se2.wrap_angle(estimate.motion[2] - truth[2]))))


@pytest.mark.parametrize("step_s", [-0.06, 0.0, 0.05])
def test_rate_step_deskew_follows_a_step_no_constant_twist_does(
    oxford_snapshot: RadarFrame, step_s: float
) -> None:
    cfg = OdometryConfig()
    start = np.array([2.0, 0.3, np.deg2rad(2.0)])
    scan = stepped_scan(oxford_snapshot, start, step_s)
    reference = prepare(oxford_snapshot, cfg)
    polar = prepare(scan, cfg).polar
    assert abs(polar.mid_sweep_s or 1.0) < 1e-3  # the image time is mid-sweep, as `yaw_at`'s 0
    before = np.array([SPEED_MPS, 0.0, np.deg2rad(RATE_BEFORE_DPS)])
    step = RateStep(step_s, np.deg2rad(RATE_AFTER_DPS - RATE_BEFORE_DPS))
    stepped = register_images(reference, PreparedScan(polar, before, cfg, step), cfg, hint=start)
    mean_rate = float(np.diff(yaw_at(np.array([-0.5, 0.5]) * SWEEP_S, step_s))[0]) / SWEEP_S
    constant = np.array([SPEED_MPS, 0.0, mean_rate])
    flat = register_images(reference, PreparedScan(polar, constant, cfg), cfg, hint=start)
    assert stepped.ok and flat.ok
    assert yaw_error_deg(stepped, start) <= MAX_STEPPED_ERROR_DEG
    assert yaw_error_deg(flat, start) >= MIN_CONSTANT_ERROR_DEG
    assert stepped.quality > flat.quality


def test_step_candidates_keep_the_measured_yaw(oxford_snapshot: RadarFrame) -> None:
    """Each candidate turns the measured yaw over the interval: the rate before up to its time,
    the rate after from there to the image time; the times lie in the sweep's first half."""
    cfg = OdometryConfig(deskew=DeskewConfig(rate_step_candidates=6))
    polar = prepare(stepped_scan(oxford_snapshot, np.zeros(3), 0.0), cfg).polar
    scan = PreparedScan(polar, np.array([SPEED_MPS, 0.0, 0.1]), cfg)
    before, measured, interval = np.deg2rad(5.0), np.deg2rad(12.0), 0.25
    rates = rate_search.StepRates(before, 0.0, measured, interval)
    steps = rate_search.step_candidates(scan, rates, cfg)
    assert len(steps) == 6
    times = np.array([s.time_s for s in steps])
    assert np.all(times < 0.0) and np.all(times > -0.5 * SWEEP_S) and np.all(np.diff(times) > 0)
    for s in steps:
        turned = before * (interval + s.time_s) + (before + s.change_radps) * -s.time_s
        if abs(s.change_radps) < np.deg2rad(cfg.deskew.rate_step_max_change_dps):
            assert turned == pytest.approx(measured * interval, abs=1e-9)
        else:  # the latest times would need a step beyond the bound: clipped to it
            assert abs(s.change_radps) == pytest.approx(np.deg2rad(60.0))


def test_step_search_finds_the_step_by_peak_quality(oxford_snapshot: RadarFrame) -> None:
    """De-skewed at the sweep's mean yaw rate, the scan is searched: the candidate at the true
    step time (with the yaw over the interval that time implies) correlates most strongly."""
    cfg = OdometryConfig(deskew=DeskewConfig(rate_step_candidates=4))
    start = np.array([2.0, -0.4, np.deg2rad(-1.0)])
    interval = 0.25
    probe = PreparedScan(prepare(stepped_scan(oxford_snapshot, start, 0.0), cfg).polar, None, cfg)
    first = probe.polar.timing.first_row_s - probe.image_time_s  # type: ignore[union-attr]
    step_s = first * (1.0 - 2.5 / 4)  # the third candidate's time
    polar = prepare(stepped_scan(oxford_snapshot, start, step_s), cfg).polar
    before, after = np.deg2rad(RATE_BEFORE_DPS), np.deg2rad(RATE_AFTER_DPS)
    measured = (before * (interval + step_s) + after * -step_s) / interval
    mean_rate = float(np.diff(yaw_at(np.array([-0.5, 0.5]) * SWEEP_S, step_s))[0]) / SWEEP_S
    scan = PreparedScan(polar, np.array([SPEED_MPS, 0.0, mean_rate]), cfg)
    reference = prepare(oxford_snapshot, cfg)
    estimate = register_images(reference, scan, cfg, hint=start)
    rates = rate_search.StepRates(before, 0.0, measured, interval)
    found_scan, found = rate_search.step_searched(
        reference, scan, estimate, rates, cfg, register_images
    )
    assert found_scan.rate_step is not None
    assert found_scan.rate_step.time_s == pytest.approx(step_s)
    assert found_scan.rate_step.change_radps == pytest.approx(after - before, rel=1e-6)
    assert yaw_error_deg(found, start) <= MAX_STEPPED_ERROR_DEG < yaw_error_deg(estimate, start)


def test_odometry_with_the_step_search_on_real_scans(
    oxford: OxfordSequence, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Switched on and run at every scan (no minimum change), the search leaves the real
    consecutive Oxford pairs within the stride-1 GT bar (0.15 m, 0.3 deg)."""
    calls = []
    search = rate_search.step_searched

    def counted(*args, **kwargs):  # type: ignore[no-untyped-def]
        calls.append(1)
        return search(*args, **kwargs)

    monkeypatch.setattr(rate_search, "step_searched", counted)
    cfg = OdometryConfig(deskew=DeskewConfig(rate_step_candidates=8, rate_step_min_dps=0.0))
    odometry = Odometry(cfg)
    poses = np.array([odometry.register(oxford[k]).pose for k in range(len(oxford))])
    gt = oxford.ground_truth
    assert gt is not None
    assert len(calls) >= len(oxford) - 3  # every scan once a velocity is known
    for k in range(len(oxford) - 1):
        diff = se2.between(se2.between(gt[k], gt[k + 1]), se2.between(poses[k], poses[k + 1]))
        assert np.hypot(diff[0], diff[1]) <= 0.15 and np.rad2deg(abs(diff[2])) <= 0.3, k


@pytest.mark.parametrize(
    ("prior_change_dps", "interval_s", "measured_dps", "wanted"),
    [
        (0.5, 0.25, 8.0, True),  # a steady rate, then a step, on consecutive scans
        (5.0, 0.25, 8.0, False),  # the rate was already changing: a ramp, not a step
        (0.5, 0.50, 8.0, False),  # 2 Hz: a whole sweep between the images is unseen
        (0.5, 0.25, 2.0, False),  # too small a change to search
    ],
)
def test_step_search_runs_only_where_its_model_holds(
    oxford_snapshot: RadarFrame,
    prior_change_dps: float,
    interval_s: float,
    measured_dps: float,
    wanted: bool,
) -> None:
    cfg = OdometryConfig()
    polar = prepare(stepped_scan(oxford_snapshot, np.zeros(3), 0.0), cfg).polar
    scan = PreparedScan(polar, np.array([SPEED_MPS, 0.0, 0.0]), cfg)
    estimate = register_images(prepare(oxford_snapshot, cfg), scan, cfg, hint=np.zeros(3))
    rates = rate_search.StepRates(
        0.0, np.deg2rad(prior_change_dps), np.deg2rad(measured_dps), interval_s
    )
    assert rate_search.step_wanted(scan, estimate, rates, cfg) is wanted
    off = OdometryConfig(deskew=DeskewConfig(rate_step_candidates=0))
    assert not rate_search.step_wanted(scan, estimate, rates, off)


MAX_ROTATIONAL_DRIFT_RATIO = 0.85
"""Rotational drift with the search over without it, summed over two drives through curvature
steps at 4 Hz (reduced bins)."""


def test_rate_step_lowers_the_rotational_drift_through_curvature_steps(
    synthetic_root: Path,
) -> None:
    """`tiny_roundabout` and `tiny_junction_turns` at 4 Hz, the search on (the default) and off:
    the steps of the yaw rate into and out of the turns no longer turn whole images."""
    off = OdometryConfig(deskew=DeskewConfig(rate_step_candidates=0))
    with_search, without = 0.0, 0.0
    for scenario in ("tiny_roundabout", "tiny_junction_turns"):
        with_search += driven(synthetic_root, scenario, stride=1)[2].rot_deg_per_100m
        without += driven(synthetic_root, scenario, stride=1, config=off)[2].rot_deg_per_100m
    assert with_search <= MAX_ROTATIONAL_DRIFT_RATIO * without, (with_search, without)
