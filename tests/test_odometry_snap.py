"""A scan the motion model cannot describe stays a local error (`odometry.velocity`).

On `long_city` the simulator turns each reversal of the route (a street driven there and back)
into two heading snaps of 90 deg, each within one 0.25 s sweep, 0.75 s apart. Such a sweep is
half one heading, half the other: its registration is wrong, and before the fix the motion it
implied became the running velocity (clamped at 120 deg/s), which bent the next scans' images
by +-15 deg; a correct 90-deg registration against the keyframe was vetoed as faster than a car
turns, and the scans after it chained onto the wrong ones. Each snap left 7-180 deg of heading
error. Here the same U-turn is rendered at reduced bins in the `tiny` town.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from test_odometry_recovery import drive, errors, run, tiny_scene  # noqa: F401

from odometry.config import OdometryConfig
from odometry.odometry import Odometry
from odometry.velocity import agrees, plausible_twist
from radar_slam.datasets.frame import RadarFrame
from radar_slam.sim.generate import Scene
from radar_slam.sim.render import RenderTables

FloatArray = NDArray[np.float64]
PERIOD_S = 0.25
SNAP_RADPS = 2.0 * np.pi
"""A quarter turn within one sweep (the simulator's reversal)."""
MAX_HEADING_ERROR_DEG = 1.0
"""One hard scan must not become a 1-degree heading error."""
MAX_POSITION_ERROR_M = 0.5
MAX_GAP_RUN = 2
STRAIGHT_S = 2.0


def snap_u_turn(scene: Scene, tables: RenderTables) -> tuple[list[RadarFrame], FloatArray]:
    """Straight at 6 m/s, a 90-deg snap, 0.5 s across the street, another snap, straight back
    (one scan every 0.25 s; the snaps are the sweeps of scans 9 and 12)."""
    legs = [
        (STRAIGHT_S, np.array([6.0, 0.0, 0.0])),
        (PERIOD_S, np.array([5.0, 0.0, SNAP_RADPS])),
        (2 * PERIOD_S, np.array([5.0, 0.0, 0.0])),
        (PERIOD_S, np.array([5.0, 0.0, SNAP_RADPS])),
        (STRAIGHT_S, np.array([6.0, 0.0, 0.0])),
    ]
    return drive(scene, tables, 4.0, legs, period_s=PERIOD_S)


def test_a_heading_snap_stays_local(tiny_scene: tuple[Scene, RenderTables]) -> None:  # noqa: F811
    """After both snaps the heading is within 1 deg and the position within 0.5 m of the truth,
    with at most 2 consecutive gaps: the mixed scans' errors do not reach the scans after."""
    frames, truth = snap_u_turn(*tiny_scene)
    odometry: Odometry = run(frames)
    assert odometry.longest_gap_run <= MAX_GAP_RUN
    error_m, error_deg = errors(odometry.poses[-1], truth[-1])
    assert error_deg <= MAX_HEADING_ERROR_DEG, error_deg
    assert error_m <= MAX_POSITION_ERROR_M, error_m
    # Every scan after the second snap is within the same heading bound.
    second_snap = round((STRAIGHT_S + 4 * PERIOD_S) / PERIOD_S)
    for k in range(second_snap + 1, len(frames)):
        assert errors(odometry.poses[k], truth[k])[1] <= MAX_HEADING_ERROR_DEG, k


def test_an_implausible_twist_is_not_a_velocity() -> None:
    config = OdometryConfig()
    assert plausible_twist(np.array([10.0, 0.0, np.deg2rad(60.0)]), config)
    assert not plausible_twist(np.array([5.0, 0.0, np.deg2rad(360.0)]), config)
    assert not plausible_twist(np.array([50.0, 0.0, 0.0]), config)


def test_agreement_with_the_prediction() -> None:
    assert agrees(np.array([10.0, 1.0, 0.05]), np.array([9.0, 0.5, 0.0]))
    assert not agrees(np.array([10.0, 1.0, 0.0]), np.array([8.0, 1.0, 0.0]))
    assert agrees(np.array([0.0, 0.0, np.pi - 0.01]), np.array([0.0, 0.0, -np.pi]))
