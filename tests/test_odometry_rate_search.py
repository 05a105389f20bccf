"""The de-skew yaw-rate search by correlation peak quality at low frame rates (on by default).

At 1 Hz through yaw-rate reversals the velocity of the second before de-skews a scan tens of
deg/s off; searching its yaw rate by peak quality matches its distortion to the reference
image's (`odometry.rate_search`). Reduced bins, `tiny_roundabouts` at --stride 4. A registration
far weaker than the previous one is searched at any rate: a reversal between two scans at 2 Hz,
rendered at full MulRan geometry.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from test_odometry_recovery import driven
from test_odometry_sim import render

from odometry import OdometryConfig
from odometry.config import DeskewConfig
from odometry.deskew import motion_from_twist
from odometry.odometry import Odometry
from odometry.rate_search import MAX_VERTEX_STEPS, rounds_wanted, vertex_offset
from odometry.registration import MotionEstimate
from radar_slam.datasets.frame import RadarFrame
from radar_slam.sim.generate import build_scene, make_renderer
from radar_slam.sim.scenarios import get_scenario
from raplace import se2

MAX_DRIFT_PCT = 1.6
MAX_DRIFT_DEG = 1.1
"""KITTI drift [%, deg/100 m] on tiny_roundabouts at --stride 4 with the default settings, which
search (1.05 and 0.80 at stop 14, 1.22 and 0.91 with `yaw_rate_search_dps: 0`; 1.26 / 0.81 and
2.11 / 1.40 when the search was added)."""


def test_vertex_of_the_peak_quality_parabola() -> None:
    """The parabola through three qualities at -1, 0, +1 half-widths peaks where it should."""
    offsets = np.array([-1.0, 0.0, 1.0])
    for true_peak in (-2.2, -0.6, 0.5, 1.7):
        qualities = 50.0 - 7.0 * (offsets - true_peak) ** 2
        found = vertex_offset((qualities[0], qualities[1], qualities[2]))
        assert found == pytest.approx(true_peak, abs=1e-9)
    assert vertex_offset((40.0, 50.0, 40.0)) is None  # at the point already tried
    assert vertex_offset((50.0, 40.0, 50.0)) is None  # a minimum, not a peak
    assert vertex_offset((10.0, 40.0, 69.0)) == MAX_VERTEX_STEPS  # clipped


def test_search_through_reversals_at_one_hertz(synthetic_root: Path) -> None:
    """Six roundabouts at 1 Hz: the yaw rate steps and reverses between scans; with the search
    the drift is within a bound the constant-velocity / trend / re-de-skew choice misses."""
    odometry, _, drift = driven(
        synthetic_root, "tiny_roundabouts", stride=4, config=OdometryConfig()
    )
    assert odometry.gaps == []
    assert drift.trans_pct <= MAX_DRIFT_PCT, drift
    assert drift.rot_deg_per_100m <= MAX_DRIFT_DEG, drift


def test_search_settings_are_checked() -> None:
    with pytest.raises(ValueError, match="yaw_rate_search_dps"):
        DeskewConfig(yaw_rate_search_dps=-1.0)
    with pytest.raises(ValueError, match="yaw_rate_search_min_gain"):
        DeskewConfig(yaw_rate_search_min_gain=-0.1)
    with pytest.raises(ValueError, match="yaw_rate_search_weak_fraction"):
        DeskewConfig(yaw_rate_search_weak_fraction=1.5)
    with pytest.raises(ValueError, match="yaw_rate_search_weak_rounds"):
        DeskewConfig(yaw_rate_search_weak_rounds=0)


def test_rounds_wanted() -> None:
    """No search at 4 Hz with the trend agreeing, unless the peak is weak against the previous
    scan's; one round at 1 Hz with the trend off the kept de-skew; none when switched off."""
    cfg = OdometryConfig()
    twist = np.array([10.0, 0.0, 0.2])
    scan = SimpleNamespace(twist=twist)

    def wanted(quality: float, interval_s: float, trend: NDArray[np.float64], **deskew: Any) -> int:
        config = dataclasses.replace(cfg, deskew=dataclasses.replace(cfg.deskew, **deskew))
        estimate = MotionEstimate(np.zeros(3), np.eye(3), quality, quality, ok=True)
        return rounds_wanted(scan, estimate, trend, interval_s, 60.0, config)  # type: ignore[arg-type]

    far_trend = twist + np.array([0.0, 0.0, 0.5])
    assert wanted(50.0, 0.25, twist) == 0
    assert wanted(20.0, 0.25, twist) == cfg.deskew.yaw_rate_search_weak_rounds
    assert wanted(20.0, 0.25, twist, yaw_rate_search_weak_rounds=3) == 3
    assert wanted(50.0, 1.0, twist) == 0
    assert wanted(50.0, 1.0, far_trend) == 1
    assert wanted(20.0, 1.0, far_trend, yaw_rate_search_weak_rounds=3) == 3
    assert wanted(20.0, 0.25, twist, yaw_rate_search_weak_fraction=0.0) == 0
    assert wanted(20.0, 1.0, far_trend, yaw_rate_search_dps=0.0) == 0


REVERSAL_PERIOD_S = 0.5
REVERSAL_TWIST = np.array([6.0, 0.0, np.deg2rad(28.0)])
"""2 Hz, 6 m/s, turning left at 28 deg/s for four scans, then right at 28 deg/s for four."""
MAX_STEP_YAW_ERROR_DEG = 4.5
"""Largest step yaw error of the reported poses through the reversal: 3.9 deg with the search,
5.5 without it (the rest is the move from mid-sweep to the end of the sweep, `reference_time`)."""


def reversal_scans() -> tuple[list[RadarFrame], NDArray[np.float64]]:
    """Scans of the `loop` town (full MulRan geometry) through a yaw-rate reversal, each swept
    at its step's constant twist, and their true poses (N, 3)."""
    scene = build_scene(get_scenario("loop"))
    tables = make_renderer(scene).tables
    start_s = 20.0
    flip = np.array([1.0, 1.0, -1.0])
    twists = [REVERSAL_TWIST] * 4 + [REVERSAL_TWIST * flip] * 4
    poses = [scene.trajectory.radar_poses(np.array([start_s]))[0]]
    for twist in twists[1:]:
        poses.append(se2.compose(poses[-1], motion_from_twist(twist, REVERSAL_PERIOD_S)))
    scans = [
        render(scene, tables, pose, start_s + k * REVERSAL_PERIOD_S, twist, seed=k)
        for k, (pose, twist) in enumerate(zip(poses, twists, strict=True))
    ]
    return scans, np.array(poses)


def test_weak_registration_through_a_reversal_is_searched() -> None:
    """At 2 Hz the scan after the reversal is de-skewed at the old yaw rate, 56 deg/s off: its
    peak falls to under half the previous one. Searched, it correlates more strongly and the
    reported steps through the reversal stay within the bar; not searched, they do not."""
    scans, truth = reversal_scans()
    off = OdometryConfig(deskew=DeskewConfig(yaw_rate_search_weak_fraction=0.0))
    outcomes = []
    for config in (OdometryConfig(), off):
        odometry = Odometry(config)
        for scan in scans:
            odometry.register(scan)
        steps = se2.between(odometry.poses[:-1], odometry.poses[1:])
        truth_steps = se2.between(truth[:-1], truth[1:])
        errors = np.rad2deg(np.abs(se2.wrap_angle(steps[:, 2] - truth_steps[:, 2])))
        outcomes.append((errors.max(), odometry.results[4].quality))
    (searched_max, searched_quality), (plain_max, plain_quality) = outcomes
    assert plain_quality < 0.5 * odometry.results[3].quality  # the case the search is for
    assert searched_quality > 1.3 * plain_quality, (searched_quality, plain_quality)
    assert searched_max <= MAX_STEP_YAW_ERROR_DEG < plain_max, (searched_max, plain_max)
