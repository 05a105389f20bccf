"""Driving that shows what gentle driving hides: legs of constant curvature, reverse
gear, stops, and the scenarios built from them (turn-around, U-turn, three-point turn,
roundabout, stop-and-go, stepped junction turns, reversing, held-out drives). Route properties
are measured on the simulated base poses; generation is checked on a few reduced-bin scans."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from radar_slam.datasets import open_sequence
from radar_slam.errors import RadarSlamError
from radar_slam.sim.driving import (
    STEERING_TRANSITION_M,
    Leg,
    PlanDrivingConfig,
    arc,
    drive_legs,
)
from radar_slam.sim.generate import generate_sequence, lay_out
from radar_slam.sim.route import Trajectory
from radar_slam.sim.scenarios import (
    DRIVING_SCENARIOS,
    HELD_OUT,
    SCENARIOS,
    TINY_BINS,
    get_scenario,
)
from radar_slam.sim.town import BUILDING, Town
from raplace import se2

URBAN_MAX_SPEED_MPS = 14.0
ARTERIAL_MAX_SPEED_MPS = 20.0
FAST_SCENARIOS = ("heldout_fast",)
"""Driven at arterial speeds (up to `ARTERIAL_MAX_SPEED_MPS`); every other one is urban."""
MAX_ACCEL_MPS2 = 3.0
ACCEL_TOLERANCE_MPS2 = 0.05
MAX_YAW_RATE = 0.8  # rad/s: 5 m/s on a 6 m radius
ACCEL_WINDOW_S = 0.1
STEERING_WINDOW_S = 0.3
MAX_YAW_RATE_CHANGE_DPS = 25.0
"""Over `STEERING_WINDOW_S` the real Edinburgh drive's IMU changes its yaw rate by at most about
15 deg/s; a curvature step would change it by a whole turn's yaw rate (about 30 deg/s and more
in these drives)."""
LANE_BAND_M = (3.0, 4.0)  # opposite lanes are 3.5 m apart
OPPOSITE_TOLERANCE_RAD = np.deg2rad(20.0)
MAX_FRAMES = 1200  # at most five minutes of driving at 4 Hz


@dataclass(frozen=True)
class Drive:
    """A scenario's town and drive (no world contents: fast)."""

    town: Town
    trajectory: Trajectory
    n_frames: int
    period_s: float


def laid_out(name: str) -> Drive:
    scenario = get_scenario(name)
    town, trajectory = lay_out(scenario, scenario.seed)
    period_ns = scenario.sensor.scan_period_ns
    n_frames = int(round(trajectory.duration_s * 1e9)) // period_ns
    return Drive(town, trajectory, n_frames, period_ns / 1e9)


@pytest.fixture(scope="module")
def scenes() -> dict[str, Drive]:
    return {s.name: laid_out(s.name) for s in DRIVING_SCENARIOS}


def kinematics(scene: Drive) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times (n,) [s], base poses (n, 3) and forward speed (n - 1,) [m/s] (negative in reverse
    gear) on the trajectory's own time grid, over the scans."""
    traj = scene.trajectory
    keep = traj.t_s <= scene.n_frames * scene.period_s
    t, poses = traj.t_s[keep], traj.poses[keep]
    step = np.diff(poses[:, :2], axis=0) / np.diff(t)[:, None]
    forward = step[:, 0] * np.cos(poses[:-1, 2]) + step[:, 1] * np.sin(poses[:-1, 2])
    return t, poses, forward


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, end) index ranges (end exclusive) where `mask` is true."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))


def test_legs_known_answers() -> None:
    cfg = PlanDrivingConfig(accel_mps2=2.0, decel_mps2=2.0)
    # A quarter circle of radius 10 m, then 5 m in reverse gear (a gear-change stop between).
    legs = [arc(math.pi / 2, 10.0, max_speed_mps=5.0), Leg(5.0, gear=-1, max_speed_mps=2.0)]
    traj = drive_legs((0.0, 0.0, 0.0), legs, cfg)
    corner = np.argmin(np.hypot(traj.poses[:, 0] - 10.0, traj.poses[:, 1] - 10.0))
    assert np.hypot(*(traj.poses[corner, :2] - (10.0, 10.0))) < 0.02
    assert traj.poses[corner, 2] == pytest.approx(math.pi / 2, abs=1e-3)
    assert np.allclose(traj.poses[-1, :2], (10.0, 5.0), atol=0.02)  # backwards, heading kept
    assert traj.poses[-1, 2] == pytest.approx(math.pi / 2, abs=1e-9)
    assert traj.length_m == pytest.approx(5 * math.pi + 5.0, abs=1e-6)
    standing = traj.t_s[np.flatnonzero(np.all(np.diff(traj.poses, axis=0) == 0, axis=1))]
    assert standing[-1] - standing[0] == pytest.approx(cfg.gear_change_s, abs=0.01)
    with pytest.raises(RadarSlamError, match="finite speed"):
        drive_legs((0.0, 0.0, 0.0), [Leg(5.0)], cfg)


@pytest.mark.parametrize("name", [s.name for s in DRIVING_SCENARIOS])
def test_driving_is_physically_plausible_and_short(scenes: dict[str, Drive], name: str) -> None:
    scene = scenes[name]
    t, poses, forward = kinematics(scene)
    fast = name in FAST_SCENARIOS
    assert np.abs(forward).max() <= (ARTERIAL_MAX_SPEED_MPS if fast else URBAN_MAX_SPEED_MPS)
    if fast:
        assert np.abs(forward).max() > 0.9 * ARTERIAL_MAX_SPEED_MPS
    every = int(round(ACCEL_WINDOW_S / np.diff(t[:2])[0]))
    accel = np.diff(forward[::every]) / ACCEL_WINDOW_S
    assert np.abs(accel).max() <= MAX_ACCEL_MPS2 + ACCEL_TOLERANCE_MPS2
    yaw_rate = np.diff(poses[::every, 2]) / ACCEL_WINDOW_S
    assert np.abs(yaw_rate).max() <= MAX_YAW_RATE
    assert not np.any(scene.town.raster.lookup(poses[::50, :2]) == BUILDING)
    assert 100 <= scene.n_frames <= MAX_FRAMES


def returns_along_the_outbound_street(scene: Drive) -> tuple[np.ndarray, float]:
    """Lateral distances [m] of poses in the last 40 % of the drive to the nearest pose of its
    first 40 % driven the other way, and the length of that return stretch [m]."""
    poses = scene.trajectory.base_poses(
        np.arange(0.0, scene.n_frames * scene.period_s, scene.period_s)
    )
    n = len(poses)
    out, back = poses[: 2 * n // 5], poses[3 * n // 5 :]
    distance, index = cKDTree(out[:, :2]).query(back[:, :2])
    heading = se2.wrap_angle(back[:, 2] - out[index, 2])
    match = (np.abs(np.abs(heading) - np.pi) < OPPOSITE_TOLERANCE_RAD) & (distance < 6.0)
    step = np.hypot(*np.diff(back[:, :2], axis=0).T)
    return distance[match], float(step[match[1:]].sum())


@pytest.mark.parametrize("name", ["turn_around", "u_turn", "three_point_turn"])
def test_turning_round_comes_back_along_the_street_in_the_other_lane(
    scenes: dict[str, Drive], name: str
) -> None:
    _, poses, _ = kinematics(scenes[name])
    heading = np.unwrap(poses[:, 2])
    assert abs(abs(heading[-1] - heading[0]) - np.pi) < np.deg2rad(10)
    assert np.ptp(heading) > np.deg2rad(170)
    lateral, length_m = returns_along_the_outbound_street(scenes[name])
    assert length_m > 30.0  # a real stretch of the same street, the other way
    assert LANE_BAND_M[0] <= np.median(lateral) <= LANE_BAND_M[1]


def test_three_point_turn_reverses_with_the_heading_kept(scenes: dict[str, Drive]) -> None:
    t, poses, forward = kinematics(scenes["three_point_turn"])
    reverse = [(a, b) for a, b in runs(forward < -0.05)]
    assert len(reverse) == 1
    a, b = reverse[0]
    assert forward[a:b].min() < -1.0 and t[b] - t[a] > 1.0
    # Reverse gear on right lock: the heading keeps turning left while the base moves backwards.
    assert poses[b, 2] - poses[a, 2] > np.deg2rad(30)
    u_forward = kinematics(scenes["u_turn"])[2]
    assert u_forward.min() > 0.0  # a U-turn is driven forwards


def test_roundabout_yaw_rate_is_constant_then_changes_sign(scenes: dict[str, Drive]) -> None:
    t, poses, _ = kinematics(scenes["roundabout"])
    every = int(round(ACCEL_WINDOW_S / np.diff(t[:2])[0]))
    yaw_rate = np.diff(poses[::every, 2]) / ACCEL_WINDOW_S
    ring = max(runs(yaw_rate > 0.3), key=lambda r: r[1] - r[0])
    inside = yaw_rate[ring[0] + 2 : ring[1] - 2]
    assert (ring[1] - ring[0]) * ACCEL_WINDOW_S > 5.0  # seconds at a constant high yaw rate
    assert np.ptp(inside) < 0.05 and inside.mean() > 0.4
    assert poses[ring[1] * every, 2] - poses[ring[0] * every, 2] > np.deg2rad(180)  # most of it
    before, after = yaw_rate[ring[0] - 15 : ring[0]], yaw_rate[ring[1] : ring[1] + 15]
    assert before.min() < -0.3 and after.min() < -0.3  # right-hand entry and exit arcs


def test_stop_and_go_stands_ten_seconds_and_brakes_at_three(scenes: dict[str, Drive]) -> None:
    t, _, forward = kinematics(scenes["stop_and_go"])
    dt = float(np.diff(t[:2])[0])
    standing = [(b - a) * dt for a, b in runs(forward == 0.0)]
    assert sum(s >= 10.0 - 0.01 for s in standing) == 2 and max(standing) < 10.5
    every = int(round(ACCEL_WINDOW_S / dt))
    accel = np.diff(forward[::every]) / ACCEL_WINDOW_S
    assert accel.max() > MAX_ACCEL_MPS2 - 0.1 and accel.min() < -(MAX_ACCEL_MPS2 - 0.1)
    assert np.abs(accel).max() <= MAX_ACCEL_MPS2 + ACCEL_TOLERANCE_MPS2
    assert forward.max() > 11.0  # urban speed between the stops


def curvature_by_distance(poses: np.ndarray, step_m: float) -> np.ndarray:
    """Heading change per metre [1/m] over consecutive `step_m` pieces of the driven path."""
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(poses[:, :2], axis=0).T))])
    grid = np.arange(0.0, s[-1], step_m)
    heading = np.interp(grid, s, np.unwrap(poses[:, 2]))
    return np.diff(heading) / step_m


def count_curvature_steps(poses: np.ndarray, radius_m: float, step_m: float = 0.25) -> int:
    """Onsets where the curvature goes from ~0 to >= 0.9/R within one sample (one straddling
    the leg boundary)."""
    kappa = np.abs(curvature_by_distance(poses, step_m))
    onset = (kappa[:-2] < 0.05 / radius_m) & (kappa[2:] > 0.9 / radius_m)
    return len(runs(onset))


def test_junction_turns_steer_in_and_out_over_metres(scenes: dict[str, Drive]) -> None:
    scene = scenes["junction_turns"]
    _, poses, forward = kinematics(scene)
    cfg = PlanDrivingConfig()
    radius = max(cfg.left_turn_radius_m, cfg.right_turn_radius_m)
    assert count_curvature_steps(poses, radius) == 0  # no curvature step into a turn
    assert count_curvature_steps(poses[::-1], radius) == 0  # nor out of one
    kappa = curvature_by_distance(poses, 0.25)
    ramp = np.abs(np.diff(kappa)).max() / 0.25  # [1/m per m]
    tightest = 1.0 / min(cfg.left_turn_radius_m, cfg.right_turn_radius_m)
    assert ramp == pytest.approx(tightest / STEERING_TRANSITION_M, rel=0.25)  # a linear ramp
    assert forward.max() > 12.0  # urban speeds between the junctions
    heading_change = np.abs(np.diff(np.unwrap(poses[:, 2])))
    assert np.rad2deg(heading_change.sum()) == pytest.approx(5 * 90.0, abs=1.0)


@pytest.mark.parametrize("name", [s.name for s in DRIVING_SCENARIOS])
def test_yaw_rate_changes_as_fast_as_a_steered_car(scenes: dict[str, Drive], name: str) -> None:
    t, poses, _ = kinematics(scenes[name])
    every = int(round(ACCEL_WINDOW_S / np.diff(t[:2])[0]))
    yaw_rate = np.diff(poses[::every, 2]) / ACCEL_WINDOW_S
    lag = int(round(STEERING_WINDOW_S / ACCEL_WINDOW_S))
    change = np.rad2deg(np.abs(yaw_rate[lag:] - yaw_rate[:-lag]))
    assert change.max() <= MAX_YAW_RATE_CHANGE_DPS


def test_reverse_gear_stretch(scenes: dict[str, Drive]) -> None:
    t, poses, forward = kinematics(scenes["reverse_gear"])
    (a, b), *more = runs(forward < 0.0)
    assert not more
    assert np.hypot(*(poses[b, :2] - poses[a, :2])) == pytest.approx(30.0, abs=0.05)
    assert np.ptp(poses[a : b + 1, 2]) < 1e-9  # straight back, heading unchanged
    assert forward.min() == pytest.approx(-PlanDrivingConfig().reverse_speed_mps, abs=0.01)
    assert forward[a - 1] == 0.0 and forward[b] == 0.0  # stops on both sides


def test_held_out_scenarios_are_marked() -> None:
    assert set(HELD_OUT) == {
        "heldout_town",
        "heldout_mixed",
        "heldout_junctions",
        "heldout_revisits",
        "heldout_fast",
        "tiny_heldout_town",
        "tiny_heldout_mixed",
        "tiny_heldout_junctions",
        "tiny_heldout_revisits",
        "tiny_heldout_fast",
    }
    for name in ("tiny", "tiny_loop", "loop", "reverse", "multisession_a", "long"):
        assert not SCENARIOS[name].held_out


def test_unplannable_routes_are_rejected() -> None:
    scenario = get_scenario("u_turn")
    plan = scenario.plan
    assert plan is not None
    no_turn_event = replace(plan, events=())
    with pytest.raises(RadarSlamError, match="TurnAround"):
        lay_out(replace(scenario, plan=no_turn_event), scenario.seed)


@pytest.mark.parametrize("name", [s.name for s in DRIVING_SCENARIOS])
def test_reduced_bin_version_generates_and_loads_with_ground_truth(
    tmp_path: Path, name: str
) -> None:
    tiny = get_scenario(f"tiny_{name}")
    assert tiny.sensor.n_bins == TINY_BINS and tiny.waypoints == get_scenario(name).waypoints
    folder = tmp_path / tiny.name
    generate_sequence(tiny, folder, frames=4, workers=0)
    sequence = open_sequence(str(folder))
    assert len(sequence) == 4 and sequence[0].polar.shape[1] == TINY_BINS
    gt = sequence.ground_truth
    assert gt is not None and gt.shape == (4, 3)
    step = np.hypot(*np.diff(gt[:, :2], axis=0).T)
    max_speed = ARTERIAL_MAX_SPEED_MPS if name in FAST_SCENARIOS else URBAN_MAX_SPEED_MPS
    assert np.all(step > 0.5) and np.all(step < max_speed / 4)


def test_held_out_revisits_drive_the_ring_back_the_other_way(scenes: dict[str, Drive]) -> None:
    """`heldout_revisits`: after its U-turn, back along the street and round half the ring in
    the other direction, in the other lane (the reverse-direction revisits the held-out set
    lacked; the last 40 % of the drive meets its first 40 % the other way for about 250 m)."""
    lateral, length_m = returns_along_the_outbound_street(scenes["heldout_revisits"])
    assert length_m > 200.0
    assert LANE_BAND_M[0] <= np.median(lateral) <= LANE_BAND_M[1]
