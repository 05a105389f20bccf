"""Scenario semantics: driving (speeds, smooth turns), loops driven twice, the reverse revisit
with its lane offset (the whole circuit revisited the other way), the small CI loop, two sessions
of one town, the long route, and moving traffic. No rendering except for the traffic check; no
files."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from radar_slam.errors import RadarSlamError
from radar_slam.sim.generate import Scene, build_scene
from radar_slam.sim.physics import PhysicsConfig
from radar_slam.sim.render import make_tables, render_scan
from radar_slam.sim.scenarios import GROUPS, SCENARIOS, expand, get_scenario
from radar_slam.sim.sensor import SensorConfig
from radar_slam.sim.world import KIND, Occluders, assemble_world, point_scatterers
from raplace import se2

SAMPLE_S = 0.25
SPEED_BAND_MPS = (4.5, 15.5)  # 5-15 m/s, with a margin for the sampling
MAX_YAW_RATE = 1.2  # rad/s (5 m/s on a 4 m radius: the tightest street corners)
MAX_YAW_RATE_STEP = 0.35  # rad/s change in 0.25 s (a brisk steering input, 1.4 rad/s^2): no kinks
REVISIT_RADIUS_M = 5.0
LANE_OFFSET_BAND_M = (3.0, 4.0)
OPPOSITE_TOLERANCE_RAD = np.deg2rad(25.0)
MIN_REVERSE_OVERLAP_M = 300.0
MIN_REVERSE_COVERAGE = 0.85  # share of all scans revisited the other way (measured 0.94)
REVISIT_GAP_S = 30.0  # a revisit is at least this long after (or before) the visit
MIN_LONG_M = 3000.0


@pytest.fixture(scope="module")
def scenes() -> dict[str, Scene]:
    return {
        name: build_scene(get_scenario(name))
        for name in ("loop", "reverse", "multisession_a", "multisession_b")
    }


def sampled(scene: Scene, step_s: float = SAMPLE_S) -> np.ndarray:
    """Base poses (n, 3) every step_s over the scans (town frame)."""
    t = np.arange(0.0, scene.n_frames * SAMPLE_S, step_s)
    return scene.trajectory.base_poses(t)


DENSE_S = 0.01


def test_names_and_groups() -> None:
    assert {
        "tiny",
        "tiny_loop",
        "loop",
        "reverse",
        "multisession_a",
        "multisession_b",
        "long",
    } <= set(SCENARIOS)
    assert [s.name for s in expand("multisession")] == list(GROUPS["multisession"])
    with pytest.raises(RadarSlamError, match="known scenarios"):
        get_scenario("nope")


@pytest.mark.parametrize("name", ["loop", "reverse", "multisession_a", "multisession_b"])
def test_driving_speed_and_smooth_turns(scenes: dict[str, Scene], name: str) -> None:
    poses = sampled(scenes[name])
    speed = np.hypot(*np.diff(poses[:, :2], axis=0).T) / SAMPLE_S
    assert SPEED_BAND_MPS[0] <= speed.min() and speed.max() <= SPEED_BAND_MPS[1]
    yaw_rate = se2.wrap_angle(np.diff(poses[:, 2])) / SAMPLE_S
    assert np.abs(yaw_rate).max() < MAX_YAW_RATE
    assert np.abs(np.diff(yaw_rate)).max() < MAX_YAW_RATE_STEP
    assert speed.mean() > 7.0  # not crawling


def test_loop_is_driven_twice_in_the_same_direction(scenes: dict[str, Scene]) -> None:
    scene = scenes["loop"]
    poses, dense = sampled(scene), sampled(scene, DENSE_S)
    half, dense_half = len(poses) // 2, len(dense) // 2
    tree = cKDTree(dense[:dense_half, :2])
    distance, index = tree.query(poses[half + 20 : -20, :2])
    assert np.percentile(distance, 95) < 1.0  # the same lane
    heading = se2.wrap_angle(poses[half + 20 : -20, 2] - dense[index, 2])
    assert np.percentile(np.abs(heading), 95) < np.deg2rad(10)
    assert 210.0 <= scene.n_frames / 4.0 <= 270.0  # about four minutes


def test_reverse_revisits_in_the_opposite_direction_with_a_lane_offset(
    scenes: dict[str, Scene],
) -> None:
    scene = scenes["reverse"]
    poses, dense = sampled(scene), sampled(scene, DENSE_S)
    half, dense_half = len(poses) // 2, len(dense) // 2
    tree = cKDTree(dense[:dense_half, :2])
    distance, index = tree.query(poses[half:, :2])
    opposite = (
        np.abs(np.abs(se2.wrap_angle(poses[half:, 2] - dense[index, 2])) - np.pi)
        < OPPOSITE_TOLERANCE_RAD
    )
    revisit = opposite & (distance < REVISIT_RADIUS_M)
    # Lateral distance between the two passes on straight stretches (both lanes parallel).
    lateral = distance[revisit]
    straight = np.abs(np.diff(poses[:, 2], prepend=poses[0, 2]))[half:][revisit] < 0.02
    assert LANE_OFFSET_BAND_M[0] <= np.median(lateral[straight]) <= LANE_OFFSET_BAND_M[1]
    overlap_m = revisit.sum() * SAMPLE_S * 10.0  # roughly, at ~10 m/s
    assert overlap_m > MIN_REVERSE_OVERLAP_M
    same_direction = (~opposite) & (distance < 1.0)
    assert same_direction.mean() < 0.05  # no same-direction revisit
    # A closed circuit driven both ways: (nearly) every scan, in either lap, has a revisit in the
    # opposite direction (the exceptions: inside corners, the first and last half street).
    tree = cKDTree(poses[:, :2])
    reversed_revisit = [
        any(
            abs(j - k) * SAMPLE_S > REVISIT_GAP_S
            and abs(abs(se2.wrap_angle(poses[j, 2] - pose[2])) - np.pi) < OPPOSITE_TOLERANCE_RAD
            for j in tree.query_ball_point(pose[:2], REVISIT_RADIUS_M)
        )
        for k, pose in enumerate(poses)
    ]
    assert np.mean(reversed_revisit) > MIN_REVERSE_COVERAGE


def test_tiny_loop_is_a_small_revisit_at_reduced_bins() -> None:
    scene = build_scene(get_scenario("tiny_loop"))
    assert scene.scenario.sensor.n_bins == get_scenario("tiny").sensor.n_bins < 3360
    assert 150 <= scene.n_frames <= 200
    poses = sampled(scene)
    tree = cKDTree(poses[:, :2])
    revisited = [
        any(
            abs(j - k) * SAMPLE_S > REVISIT_GAP_S
            and abs(se2.wrap_angle(poses[j, 2] - pose[2])) < OPPOSITE_TOLERANCE_RAD
            for j in tree.query_ball_point(pose[:2], REVISIT_RADIUS_M)
        )
        for k, pose in enumerate(poses)
    ]
    assert np.mean(revisited) > 0.3  # around the block, then on along it again (measured 0.40)


def test_multisession_same_town_different_contents_and_routes(scenes: dict[str, Scene]) -> None:
    a, b = scenes["multisession_a"], scenes["multisession_b"]
    assert len(a.town.buildings) == len(b.town.buildings)
    assert all(
        np.array_equal(x.corners, y.corners)
        for x, y in zip(a.town.buildings, b.town.buildings, strict=True)
    )
    for kind in ("parked_car", "vegetation"):
        pa = a.world.scatterers.kind == KIND[kind]
        pb = b.world.scatterers.kind == KIND[kind]
        xa = np.column_stack([a.world.scatterers.x[pa], a.world.scatterers.y[pa]])
        xb = np.column_stack([b.world.scatterers.x[pb], b.world.scatterers.y[pb]])
        moved = cKDTree(xa).query(xb)[0] > 0.5
        assert moved.mean() > 0.3, kind  # parked cars moved, vegetation changed

    def facades(scene: Scene) -> np.ndarray:
        sc = scene.world.scatterers
        xy = np.column_stack([sc.x, sc.y])[sc.kind == KIND["facade"]]
        return xy[np.lexsort(xy.T)]

    assert np.array_equal(facades(a), facades(b))  # static structure identical
    pa, pb = sampled(a), sampled(b)
    shared = cKDTree(pa[:, :2]).query(pb[:, :2])[0] < 1.0
    assert 0.15 < shared.mean() < 0.7  # different routes that share streets
    assert a.scenario.start_ns != b.scenario.start_ns


def test_long_is_several_kilometres_with_loops() -> None:
    scene = build_scene(get_scenario("long"))
    poses = sampled(scene)
    length = np.hypot(*np.diff(poses[:, :2], axis=0).T).sum()
    assert length >= MIN_LONG_M
    tree = cKDTree(poses[:, :2])
    revisits = [
        any(abs(j - i) * SAMPLE_S > 60.0 for j in tree.query_ball_point(p, REVISIT_RADIUS_M))
        for i, p in enumerate(poses[:, :2])
    ]
    assert np.mean(revisits) > 0.3


def test_moving_vehicles_move_between_scans(scenes: dict[str, Scene]) -> None:
    traffic = scenes["loop"].world.traffic
    assert len(traffic) > 10
    vehicle = int(np.argmax(traffic.speed))
    t0, t1 = 20.0, 21.0
    p0, p1 = traffic.poses(np.array([vehicle, vehicle]), np.array([t0, t1]))
    assert abs(np.hypot(*(p1[:2] - p0[:2])) - traffic.speed[vehicle] * (t1 - t0)) < 0.5
    # Render only that traffic from a sensor standing 15 m beside the vehicle's position at t0.
    sensor = SensorConfig(n_bins=800)
    tables = make_tables(sensor, PhysicsConfig())
    empty = point_scatterers(np.array([[1e4, 1e4]]), 0.0)
    no_occ = Occluders(
        np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, np.float32), np.zeros(0, np.int32)
    )
    world = assemble_world(empty, no_occ, traffic=traffic)
    ego = np.array([p0[0] - 15.0 * np.sin(p0[2]), p0[1] + 15.0 * np.cos(p0[2]), 0.0])
    poses = np.tile(ego, (400, 1))
    scans = [
        render_scan(world, poses, np.full(400, t), tables, np.random.default_rng(0)).astype(float)
        for t in (t0, t1)
    ]
    strongest = [np.unravel_index(np.argmax(s[:, 30:]), s[:, 30:].shape) for s in scans]
    assert scans[0].max() > 80
    assert strongest[0] != strongest[1]
