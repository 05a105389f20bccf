"""Simulator physics on hand-made worlds: geometry, occlusion, rotation, motion distortion,
ghosts, output levels. Known answers, reduced range bins, no files."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from radar_slam.sim.generate import build_scene
from radar_slam.sim.physics import (
    Glint,
    MotionDistortion,
    Multipath,
    NoiseFloor,
    PhysicsConfig,
    Speckle,
    output_lut,
)
from radar_slam.sim.render import make_tables, render_scan
from radar_slam.sim.scenarios import get_scenario
from radar_slam.sim.sensor import SensorConfig
from radar_slam.sim.world import (
    Occluders,
    assemble_world,
    concat_scatterers,
    point_scatterers,
)
from raplace.units import NS_PER_S

N_BINS = 1200  # 71 m
SENSOR = SensorConfig(n_bins=N_BINS)
QUIET = PhysicsConfig(speckle=Speckle(enabled=False))
NO_OCCLUDERS = Occluders(
    np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, np.float32), np.zeros(0, np.int32)
)
POINT_DB = 60.0
FACADE_DB_PER_M = 58.0
FACADE_STEP_M = 0.4
PENETRATION_DB = 20.0
COLUMNS_PER_QUARTER_TURN = 100  # 400 columns per revolution
FRONT_X_M, BACK_X_M, FACADE_HALF_WIDTH_M = 25.0, 45.0, 15.0
VALID_LEVELS = {0, 6, 9, 12, 14, 15, 17} | set(range(18, 137))
"""The real sensor's output levels (integer power counts in half-dB steps, cap 136)."""


def still(yaw: float = 0.0, n: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """Column poses and times of a sensor standing at the origin with heading `yaw`."""
    return np.tile([0.0, 0.0, yaw], (n, 1)), np.zeros(n)


def scan_of(world, physics: PhysicsConfig = QUIET, yaw: float = 0.0, seed: int = 0) -> np.ndarray:
    poses, times = still(yaw)
    return render_scan(
        world, poses, times, make_tables(SENSOR, physics), np.random.default_rng(seed)
    )


def column_of(x: float, y: float) -> int:
    """Nearest column of a direction (x forward, y left) for the default sensor."""
    return int(np.rint(SENSOR.column_of_angle(np.array([np.arctan2(y, x)]))[0])) % SENSOR.n_azimuths


def bin_of(range_m: float) -> int:
    return int(range_m / SENSOR.range_resolution_m)


def facade(x_m: float, owner: int):
    """A wall facing the sensor at x = x_m, |y| <= FACADE_HALF_WIDTH_M, and its occluder."""
    y = np.arange(-FACADE_HALF_WIDTH_M, FACADE_HALF_WIDTH_M, FACADE_STEP_M)
    xy = np.column_stack([np.full(len(y), x_m), y])
    db = FACADE_DB_PER_M + 10 * np.log10(FACADE_STEP_M)
    points = point_scatterers(
        xy, db, kind="facade", owner=owner, normal=np.array([-1.0, 0.0]), diffuse=0.15
    )
    segment = Occluders(
        np.array([[x_m, -FACADE_HALF_WIDTH_M]]),
        np.array([[x_m, FACADE_HALF_WIDTH_M]]),
        np.array([PENETRATION_DB], np.float32),
        np.array([owner], np.int32),
    )
    return points, segment


def join(occluders: list[Occluders]) -> Occluders:
    return Occluders(
        np.concatenate([o.p0 for o in occluders]),
        np.concatenate([o.p1 for o in occluders]),
        np.concatenate([o.loss_db for o in occluders]),
        np.concatenate([o.owner for o in occluders]),
    )


def test_point_targets_land_at_their_azimuth_and_range() -> None:
    # Forward, left, behind, right: columns 399/0, 299, 199, 99 (clockwise sweep from encoder 9).
    targets = [(20.0, 0.0), (0.0, 20.0), (-20.0, 0.0), (0.0, -30.0)]
    scan = scan_of(
        assemble_world(point_scatterers(np.array(targets), POINT_DB), NO_OCCLUDERS)
    ).astype(int)
    for x, y in targets:
        col, b = column_of(x, y), bin_of(np.hypot(x, y))
        window = scan[[(col + d) % 400 for d in (-1, 0, 1)], b - 30 : b + 30]
        peak_row, peak_bin = np.unravel_index(np.argmax(window), window.shape)
        assert peak_row == 1, (x, y)  # the nearest column holds the peak
        assert abs(peak_bin - 30) <= 2, (x, y)  # within 2 bins (12 cm) of the true range
        assert window.max() > 90
    assert column_of(0.0, 20.0) == 299 and column_of(0.0, -30.0) == 99


def test_facade_behind_facade_is_dimmer_but_not_removed() -> None:
    front, front_occ = facade(FRONT_X_M, owner=0)
    back, back_occ = facade(BACK_X_M, owner=1)
    both = scan_of(
        assemble_world(concat_scatterers([front, back]), join([front_occ, back_occ]))
    ).astype(float)
    alone = scan_of(assemble_world(back, back_occ)).astype(float)
    cols = [column_of(BACK_X_M, y) for y in np.linspace(-5, 5, 9)]  # behind the front facade
    b = bin_of(BACK_X_M)
    seen_through = both[cols, b - 10 : b + 10].max(axis=1).mean()
    seen_directly = alone[cols, b - 10 : b + 10].max(axis=1).mean()
    noise = both[cols, b + 100 : b + 200].mean()
    # 20 dB penetration = 40 output levels (0.5 dB per level); allow the compression knee.
    assert seen_directly - seen_through > 25
    assert seen_through > noise + 20  # attenuated, not removed


def test_scan_rotated_by_90_deg_is_shifted_by_100_columns() -> None:
    world = build_scene(get_scenario("tiny")).world
    centre = world.town.nodes[world.town.node_id(1, 1)]
    poses0 = np.tile([centre[0], centre[1], 0.3], (400, 1))
    poses1 = poses0 + [0.0, 0.0, np.pi / 2]
    # Frozen speckle, and the receiver noise (which does not rotate with the sensor) on or off.
    for physics, band in (
        (QUIET, 0.8),
        (replace(QUIET, noise_floor=NoiseFloor(enabled=False)), 0.95),
    ):
        tables = make_tables(SENSOR, physics)
        a = render_scan(world, poses0, np.zeros(400), tables, np.random.default_rng(1)).astype(
            float
        )
        b = render_scan(world, poses1, np.zeros(400), tables, np.random.default_rng(1)).astype(
            float
        )
        shifted = np.roll(a, COLUMNS_PER_QUARTER_TURN, axis=0)  # yaw +90 deg: +100 columns
        assert np.corrcoef(shifted.ravel(), b.ravel())[0, 1] > band
        assert np.corrcoef(a.ravel(), b.ravel())[0, 1] < 0.5  # not trivially satisfied


def test_motion_distortion_renders_each_column_from_its_own_pose() -> None:
    speed, target = 10.0, np.array([[-20.0, 2.0]])  # a pole behind: seen mid-sweep
    # The scan ends at t = 0.25 s.
    times = np.asarray(SENSOR.azimuth_offsets_ns(), float) / NS_PER_S + 0.25
    poses = np.column_stack([speed * times, np.zeros(400), np.zeros(400)])
    world = assemble_world(point_scatterers(target, POINT_DB), NO_OCCLUDERS)
    tables_on = make_tables(SENSOR, QUIET)
    tables_off = make_tables(
        SENSOR, replace(QUIET, motion_distortion=MotionDistortion(enabled=False))
    )
    on = render_scan(world, poses, times, tables_on, np.random.default_rng(0)).astype(int)
    end_pose = np.repeat(poses[-1:], 400, axis=0)  # what the renderer uses when distortion is off
    off = render_scan(world, end_pose, times, tables_off, np.random.default_rng(0)).astype(int)
    col = column_of(-20.0, 2.0)
    x_at_column = speed * times[col]  # the sensor position when that column fired
    expected_on = np.hypot(x_at_column + 20.0, 2.0)
    expected_off = np.hypot(poses[-1, 0] + 20.0, 2.0)
    for scan, expected in ((on, expected_on), (off, expected_off)):
        row = scan[np.argmax(scan.max(axis=1))]
        assert abs(np.argmax(row) - bin_of(expected)) <= 2
    assert abs(bin_of(expected_on) - bin_of(expected_off)) > 5  # the two differ measurably


def test_multipath_ghost_is_a_delayed_copy_on_the_same_column() -> None:
    sc = point_scatterers(np.array([[15.0, 0.0]]), 70.0)
    sc.ghost_delay_m[:] = 12.0
    world = assemble_world(sc, NO_OCCLUDERS)
    with_ghost = scan_of(world).astype(int)
    without = scan_of(world, replace(QUIET, multipath=Multipath(enabled=False))).astype(int)
    col, ghost_bin = column_of(15.0, 0.0), bin_of(27.0)
    assert (
        with_ghost[col, ghost_bin - 5 : ghost_bin + 5].max()
        > without[col, ghost_bin - 5 : ghost_bin + 5].max() + 20
    )
    assert (
        with_ghost[col, ghost_bin - 5 : ghost_bin + 5].max() < with_ghost[col].max()
    )  # weaker than the direct return


def test_output_levels_are_those_of_the_real_sensor() -> None:
    world = build_scene(get_scenario("tiny")).world
    centre = world.town.nodes[world.town.node_id(1, 1)]
    poses = np.tile([centre[0], centre[1], 0.0], (400, 1))
    scan = render_scan(
        world, poses, np.zeros(400), make_tables(SENSOR, PhysicsConfig()), np.random.default_rng(0)
    )
    assert scan.dtype == np.uint8 and scan.shape == (400, N_BINS)
    assert set(np.unique(scan).tolist()) <= VALID_LEVELS
    assert set(np.unique(output_lut(PhysicsConfig())).tolist()) <= VALID_LEVELS


def test_ring_noise_is_the_same_in_every_scan_and_column() -> None:
    tables = make_tables(SENSOR, PhysicsConfig())
    empty = assemble_world(point_scatterers(np.array([[500.0, 500.0]]), 0.0), NO_OCCLUDERS)
    poses, times = still()
    profiles = [
        render_scan(empty, poses, times, tables, np.random.default_rng(seed)).mean(axis=0)
        for seed in (1, 2)
    ]
    assert np.all(profiles[0][: tables.n_blank] == profiles[1][: tables.n_blank])  # blanked bins
    # The per-bin mean over 400 columns is a stable profile: the same bands in both scans.
    far = slice(100, None)
    assert np.corrcoef(profiles[0][far], profiles[1][far])[0, 1] > 0.5


@pytest.mark.parametrize(
    "effect",
    [
        "speckle",
        "beam_pattern",
        "range_psf",
        "noise_floor",
        "occlusion",
        "elevation",
        "saturation",
        "near_range",
        "ring_noise",
        "multipath",
        "path_loss",
    ],
)
def test_every_effect_can_be_switched_off(effect: str) -> None:
    section = getattr(QUIET, effect)
    physics = replace(QUIET, **{effect: replace(section, enabled=False)})
    front, front_occ = facade(FRONT_X_M, owner=0)
    scan = scan_of(assemble_world(front, front_occ), physics)
    assert scan.shape == (400, N_BINS)
    assert scan[column_of(FRONT_X_M, 0.0)].max() > 60  # the facade is still there


def _level_seen_from(world, bearing: float, physics: PhysicsConfig) -> int:
    """Output level of a point target at (20, 0) seen from 20 m away along world `bearing`."""
    target = np.array([20.0, 0.0])
    sensor = target - 20.0 * np.array([np.cos(bearing), np.sin(bearing)])
    poses = np.tile([sensor[0], sensor[1], bearing], (400, 1))
    scan = render_scan(
        world, poses, np.zeros(400), make_tables(SENSOR, physics), np.random.default_rng(0)
    )
    col, b = column_of(20.0, 0.0), bin_of(20.0)
    return int(scan[[(col + d) % 400 for d in (-1, 0, 1)], b - 5 : b + 5].max())


def test_glint_makes_a_target_brighter_or_dimmer_by_bearing() -> None:
    world = assemble_world(point_scatterers(np.array([[20.0, 0.0]]), POINT_DB), NO_OCCLUDERS)
    glint = replace(QUIET, glint=Glint(enabled=True, amplitude_db=10.0, lobes=6.0))
    bearings = np.deg2rad(np.arange(0.0, 60.0, 5.0))  # one lobe period
    plain = [_level_seen_from(world, b, QUIET) for b in bearings]
    varied = [_level_seen_from(world, b, glint) for b in bearings]
    assert max(plain) - min(plain) <= 2  # isotropic without glint
    # +-10 dB is +-20 output levels (0.5 dB per level); the compression knee takes some.
    assert max(varied) - min(varied) > 25
    assert _level_seen_from(world, bearings[3], glint) == varied[3]  # fixed per bearing
