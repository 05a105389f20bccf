"""Route reversals are driven as a car drives them, and every scenario stays within a car's
envelope (a smooth drive would fold a street driven there and back into a quarter turn
within one radar sweep). Checked on the drives' base poses only (no rendering)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from radar_slam.errors import RadarSlamError
from radar_slam.sim.family import is_complete
from radar_slam.sim.generate import ego_drive
from radar_slam.sim.kinematics import MAX_YAW_RATE_DPS, kinematics
from radar_slam.sim.reversal import TURN_BEFORE_M, drive_route, reversal_nodes
from radar_slam.sim.route import (
    MAX_LATERAL_ACCEL_MPS2,
    DrivingConfig,
    Trajectory,
    drive,
    route_edges,
)
from radar_slam.sim.scenarios import SCENARIOS, SIM_VERSION, Scenario
from radar_slam.sim.sensor import SensorConfig
from radar_slam.sim.town import Town, TownConfig
from radar_slam.sim.townplan import street_plan
from radar_slam.sim.writer import COMPLETE_MARKER
from raplace.se2 import wrap_angle

SEED = 5
ROUTE = [(0, 1), (3, 1), (1, 1)]
"""Along a row of the town, back after its third street (a reversal at node (3, 1))."""
SMALL_TOWN = TownConfig(n_blocks=(3, 3), block_size_m=(80.0, 90.0))
LANE_GAP_M = (3.2, 3.8)  # the two directions' lanes are 3.5 m apart
MANOEUVRE_MAX_SPEED_MPS = 3.0
FOLD_YAW_RATE_DPS = 300.0


def _drive_both(town_cfg: TownConfig) -> tuple[Town, Trajectory, Trajectory]:
    town = street_plan(SEED, town_cfg, route_edges(ROUTE))
    cfg = DrivingConfig()
    folded = drive(town, ROUTE, cfg, np.random.default_rng(SEED))
    turned = drive_route(town, ROUTE, cfg, np.random.default_rng(SEED))
    return town, folded, turned


def _drive_key(scenario: Scenario) -> Scenario:
    """What a scenario's drive depends on (reduced-bin versions drive as their originals)."""
    return replace(scenario, name="", description="", sensor=SensorConfig(), start_ns=0)


def test_every_scenario_stays_within_a_cars_yaw_rate_and_lateral_acceleration() -> None:
    assert len(reversal_nodes(list(SCENARIOS["long_city"].waypoints))) == 4
    drives: dict[Scenario, Scenario] = {}
    for scenario in SCENARIOS.values():
        drives.setdefault(_drive_key(scenario), scenario)
    worst = {}
    for scenario in drives.values():
        k = kinematics(ego_drive(scenario))
        worst[scenario.name] = (
            float(np.rad2deg(np.abs(k.yaw_rate_radps).max())),
            float(np.abs(k.lateral_accel_mps2).max()),
        )
    assert {"long_city", "loop", "reverse", "long", "u_turn"} <= set(worst)
    over = {n: w for n, w in worst.items() if w[0] > MAX_YAW_RATE_DPS}
    assert not over, f"yaw rate [deg/s] over {MAX_YAW_RATE_DPS}: {over}"
    over = {n: w for n, w in worst.items() if w[1] > MAX_LATERAL_ACCEL_MPS2}
    assert not over, f"lateral acceleration [m/s^2] over {MAX_LATERAL_ACCEL_MPS2}: {over}"


def test_a_folded_reversal_breaks_the_envelope_and_a_turn_around_does_not() -> None:
    assert reversal_nodes(ROUTE) == [3]
    _, folded, turned = _drive_both(SMALL_TOWN)
    fold = kinematics(folded)
    assert np.rad2deg(np.abs(fold.yaw_rate_radps).max()) > FOLD_YAW_RATE_DPS
    assert not fold.within_limits()
    k = kinematics(turned)
    assert k.within_limits()
    # The car slows to manoeuvring speed, turns round by 180 deg and comes back in the other
    # lane; streets of this town are too narrow for a U-turn, so it reverses on the way.
    assert np.abs(k.speed_mps).min() < 0.1
    assert k.speed_mps.min() < -0.5
    slow = np.abs(k.speed_mps) < MANOEUVRE_MAX_SPEED_MPS + 0.1
    assert np.abs(k.yaw_rate_radps[~slow]).max() < np.abs(k.yaw_rate_radps[slow]).max()
    poses = turned.poses
    assert abs(wrap_angle(poses[-1, 2] - poses[0, 2] - np.pi)) < np.deg2rad(5.0)
    there = poses[: np.argmax(np.abs(k.speed_mps) < MANOEUVRE_MAX_SPEED_MPS)]
    back = poses[len(poses) - np.argmax(np.abs(k.speed_mps[::-1]) < MANOEUVRE_MAX_SPEED_MPS) :]
    gaps = np.hypot(*(back[::50, None, :2] - there[None, ::10, :2]).transpose(2, 0, 1)).min(axis=1)
    assert LANE_GAP_M[0] < np.median(gaps) < LANE_GAP_M[1]


def test_a_wide_street_gets_a_u_turn_in_forward_gear() -> None:
    wide = replace(SMALL_TOWN, road_half_width_m=(7.0, 7.5))
    _, folded, turned = _drive_both(wide)
    assert not kinematics(folded).within_limits()
    k = kinematics(turned)
    assert k.within_limits()
    assert k.speed_mps.min() > 0.5  # never stops, never reverses
    assert np.abs(k.speed_mps).min() < MANOEUVRE_MAX_SPEED_MPS + 0.1
    # It turns before the node, not at it: the whole manoeuvre stays TURN_BEFORE_M - 30 m short.
    town = street_plan(SEED, wide, route_edges(ROUTE))
    node = town.nodes[town.node_id(3, 1)]
    assert np.hypot(*(turned.poses[:, :2] - node).T).min() > TURN_BEFORE_M - 30.0


def test_a_route_without_reversal_is_driven_exactly_as_before() -> None:
    route = [(0, 1), (2, 1), (2, 2), (1, 2)]
    assert reversal_nodes(route) == []
    town = street_plan(SEED, SMALL_TOWN, route_edges(route))
    before = drive(town, route, DrivingConfig(), np.random.default_rng(SEED))
    now = drive_route(town, route, DrivingConfig(), np.random.default_rng(SEED))
    assert np.array_equal(before.t_s, now.t_s) and np.array_equal(before.poses, now.poses)


def test_a_sequence_of_another_simulator_version_is_regenerated(tmp_path: Path) -> None:
    for name, version, complete in (
        ("loop", SIM_VERSION, True),
        ("long_city", SIM_VERSION, True),
        ("long_city", "1.3", False),
        ("loop", "1.2", False),
    ):
        folder = tmp_path / f"{name}_{version}"
        folder.mkdir()
        marker = {"simulator_version": version, "scenario": name, "complete": True}
        (folder / COMPLETE_MARKER).write_text(json.dumps(marker))
        assert is_complete(folder, name) is complete


def test_a_reversal_too_close_to_the_start_is_rejected() -> None:
    route = [(0, 1), (1, 1), (0, 1), (0, 2)]  # back after half a street: no room to turn
    town = street_plan(SEED, SMALL_TOWN, route_edges(route))
    with pytest.raises(RadarSlamError, match="too short"):
        drive_route(town, route, DrivingConfig(), np.random.default_rng(SEED))
