"""A town populated with radar scatterers: what the simulated sensor sees.

A `World` holds
- static point scatterers (facades sampled as extended line reflectors with per-facade
  reflectivity, facade features, building corners, curbs, fences, guard rails, poles, tree
  trunks, ground clutter) in a spatial grid for fast per-scan culling;
- per-session scatterers (parked cars, vegetation and tree foliage), regenerated for another
  session of the same town (cars moved, vegetation changed);
- occluder segments (facades, parked car bodies) with a penetration loss each;
- moving vehicles driving random walks on the streets (positions are a function of time).

Powers are linear, in counts at `PathLoss.reference_range_m` (see physics.py). Extended objects
(facades, curbs, fences, rails) are sampled every few decimetres; each sample carries the
power of the length it represents, so the return of a resolution cell does not depend on the
sampling. Facade samples are directional: diffuse part plus a specular lobe around the normal.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from radar_slam.sim.scatterers import (
    HEIGHT_M,
    KIND,
    Occluders,
    ScattererBuilder,
    Scatterers,
    Traffic,
    World,
    concat_scatterers,
    grid_scatterers,
    no_traffic,
    point_scatterers,
)
from radar_slam.sim.town import (
    BUILDING,
    FEATURE_STEP_M,
    FREE,
    Town,
    offset_polyline,
    resample_polyline,
)

logger = logging.getLogger(__name__)

F32 = NDArray[np.float32]

STATIC_STREAM, SESSION_STREAM = 0, 1
"""Random streams: static structure from (seed, 0); session content from (seed, 1, session)."""


@dataclass(frozen=True)
class ObjectConfig:
    """Reflectivity and geometry of every object class.

    Point powers are dB counts at the reference range; line powers are dB counts per metre.
    Heights (z ranges) feed the elevation effect (slant range, elevation beam pattern).

    Attributes:
        facade_db_per_m: mean facade reflectivity [dB/m]; facade_sigma_db: spread between
            buildings (materials, glazing) [dB].
        facade_step_m: sampling of facades [m].
        facade_roughness_db: per-sample log-normal spread of facade power [dB].
        facade_diffuse: diffuse share of facade power (rest: specular lobe).
        facade_specular_exponent: specular lobe ~ |cos(incidence)| ** exponent.
        facade_penetration_db: range of facade penetration loss per building [dB].
        feature_gain_db: range of facade feature power above 1 m of facade [dB].
        corner_db: building corner (dihedral) power [dB].
        curb_db_per_m, guard_rail_db_per_m, fence_db_per_m: line reflectivities [dB/m].
        line_diffuse: diffuse share of curbs, rails and fences (rest: specular lobe).
        rail_post_db, rail_post_spacing_m: guard rail posts.
        pole_db: street light / sign power [dB].
        trunk_db: tree trunk power [dB].
        foliage_db: one foliage scatterer [dB]; foliage_points: per tree; foliage_radius_m.
        vegetation_db: one vegetation scatterer [dB]; vegetation_density_per_m2.
        park_trees_per_100m2: trunks inside vegetation patches.
        ground_db, ground_density_per_m2: weak clutter everywhere outside buildings.
        clutter_db: small street objects (bins, bikes, signs, bollards) [dB].
        hedge_db, hedge_points_per_m, hedge_width_m: hedges (vegetation scatterers) along a line.
        point_spread_db: log-normal spread of point and clutter powers [dB].
        car_db: range of a car's point powers [dB]; car_length_m, car_width_m.
        car_penetration_db: loss through a parked car [dB].
        parking_occupancy: probability that a parking bay holds a car (per session).
        vegetation_keep: share of vegetation patches present in a session.
        vegetation_density_jitter: session density factor range of a patch.
        moving_vehicles_per_km: moving vehicles per km of street.
        moving_speed_mps: speed range of moving vehicles [m/s].
        lane_offset_m: distance of a lane centre right of the street centre line [m].
        ghost_delay_m: range of the extra path length of a scatterer's multipath ghost [m].
    """

    facade_db_per_m: float = 58.0
    facade_sigma_db: float = 4.0
    facade_step_m: float = 0.4
    facade_roughness_db: float = 3.0
    facade_diffuse: float = 0.15
    facade_specular_exponent: float = 4.0
    facade_penetration_db: tuple[float, float] = (28.0, 38.0)
    feature_gain_db: tuple[float, float] = (-3.0, 3.0)
    corner_db: float = 68.0
    curb_db_per_m: float = 26.0
    guard_rail_db_per_m: float = 42.0
    fence_db_per_m: float = 36.0
    line_diffuse: float = 0.3
    rail_post_db: float = 50.0
    rail_post_spacing_m: float = 2.0
    pole_db: float = 62.0
    trunk_db: float = 48.0
    foliage_db: float = 31.0
    foliage_points: int = 25
    foliage_radius_m: float = 2.5
    vegetation_db: float = 30.0
    vegetation_density_per_m2: float = 0.5
    park_trees_per_100m2: float = 0.6
    ground_db: float = 24.0
    ground_density_per_m2: float = 0.1
    clutter_db: float = 46.0
    hedge_db: float = 30.0
    hedge_points_per_m: float = 3.0
    hedge_width_m: float = 1.0
    point_spread_db: float = 3.0
    car_db: tuple[float, float] = (50.0, 60.0)
    car_length_m: float = 4.5
    car_width_m: float = 1.8
    car_penetration_db: float = 8.0
    parking_occupancy: float = 0.8
    vegetation_keep: float = 0.8
    vegetation_density_jitter: tuple[float, float] = (0.6, 1.4)
    moving_vehicles_per_km: float = 6.0
    moving_speed_mps: tuple[float, float] = (5.0, 13.0)
    lane_offset_m: float = 1.75
    ghost_delay_m: tuple[float, float] = (2.0, 25.0)


def _facades(
    builder: ScattererBuilder, town: Town, cfg: ObjectConfig, rng: np.random.Generator
) -> Occluders:
    """Facade samples, features and corners of every building; returns the facade occluders."""
    p0s: list[NDArray[np.float64]] = []
    p1s: list[NDArray[np.float64]] = []
    losses: list[float] = []
    owners: list[int] = []
    for b in town.buildings:
        loss = rng.uniform(*cfg.facade_penetration_db)
        facade_db = rng.normal(cfg.facade_db_per_m, cfg.facade_sigma_db)
        feature_db = facade_db + rng.uniform(*cfg.feature_gain_db)
        corners = b.corners
        builder.add(corners, cfg.corner_db, "corner", spread_db=cfg.point_spread_db)
        for k in range(4):
            a, c = corners[k], corners[(k + 1) % 4]
            length = float(np.hypot(*(c - a)))
            direction = (c - a) / max(length, 1e-9)
            normal = np.array([direction[1], -direction[0]])  # outward for CCW corners
            n = max(1, int(length / cfg.facade_step_m))
            u = (np.arange(n) + rng.uniform(0.1, 0.9, n)) / n
            owner = len(p0s)
            builder.add(
                a + u[:, None] * (c - a),
                facade_db + 10 * np.log10(length / n),
                "facade",
                spread_db=cfg.facade_roughness_db,
                normal=normal,
                diffuse=cfg.facade_diffuse,
                owner=owner,
                height_m=(0.0, b.height_m),
            )
            nf = int(length / b.feature_period_m)
            if nf > 0:
                uf = (np.arange(nf) + 0.5) / nf
                builder.add(
                    a + uf[:, None] * (c - a),
                    feature_db,
                    "facade_feature",
                    spread_db=cfg.point_spread_db,
                    owner=owner,
                    height_m=(0.0, b.height_m),
                )
            p0s.append(a)
            p1s.append(c)
            losses.append(loss)
            owners.append(owner)
    return Occluders(
        np.array(p0s).reshape(-1, 2),
        np.array(p1s).reshape(-1, 2),
        np.array(losses, dtype=np.float32),
        np.array(owners, dtype=np.int32),
    )


def _lines_and_points(
    builder: ScattererBuilder, town: Town, cfg: ObjectConfig, rng: np.random.Generator
) -> None:
    """Curbs, guard rails (with posts), fences, poles, trunks, park trees and ground clutter."""
    step_db = 10 * np.log10(FEATURE_STEP_M)
    for pts, db, kind in (
        (town.curbs, cfg.curb_db_per_m, "curb"),
        (town.guard_rails, cfg.guard_rail_db_per_m, "guard_rail"),
        (town.fences, cfg.fence_db_per_m, "fence"),
    ):
        builder.add(
            pts[:, :2],
            db + step_db,
            kind,
            spread_db=cfg.point_spread_db,
            normal=pts[:, 2:],
            diffuse=cfg.line_diffuse,
        )
    every = max(1, int(round(cfg.rail_post_spacing_m / FEATURE_STEP_M)))
    builder.add(
        town.guard_rails[::every, :2], cfg.rail_post_db, "guard_rail", spread_db=cfg.point_spread_db
    )
    builder.add(town.poles, cfg.pole_db, "pole", spread_db=cfg.point_spread_db)
    builder.add(town.clutter, cfg.clutter_db, "street_clutter", spread_db=2 * cfg.point_spread_db)
    builder.add(town.street_trees, cfg.trunk_db, "trunk", spread_db=cfg.point_spread_db)
    builder.add(_park_trees(town, cfg, rng), cfg.trunk_db, "trunk", spread_db=cfg.point_spread_db)
    xmin, ymin, xmax, ymax = town.extent
    n = int(cfg.ground_density_per_m2 * (xmax - xmin) * (ymax - ymin))
    ground = np.column_stack([rng.uniform(xmin, xmax, n), rng.uniform(ymin, ymax, n)])
    ground = ground[town.raster.lookup(ground) != BUILDING]
    builder.add(ground, cfg.ground_db, "ground", spread_db=2 * cfg.point_spread_db)


def _ellipse_points(
    rng: np.random.Generator, patch: NDArray[np.float64], n: int
) -> NDArray[np.float64]:
    cx, cy, a, b, yaw = patch
    r = np.sqrt(rng.uniform(0, 1, n))
    t = rng.uniform(0, 2 * np.pi, n)
    u, v = a * r * np.cos(t), b * r * np.sin(t)
    c, s = np.cos(yaw), np.sin(yaw)
    return np.column_stack([cx + c * u - s * v, cy + s * u + c * v])


def _park_trees(town: Town, cfg: ObjectConfig, rng: np.random.Generator) -> NDArray[np.float64]:
    trees = [
        _ellipse_points(rng, p, rng.poisson(cfg.park_trees_per_100m2 * np.pi * p[2] * p[3] / 100))
        for p in town.parks
    ]
    pts = np.concatenate(trees) if trees else np.zeros((0, 2))
    return pts[town.raster.lookup(pts) == FREE]


def car_body(
    rng: np.random.Generator, cfg: ObjectConfig
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Body-frame scatterers of one car (x forward): corners, wheel houses, sides, bumpers.

    Returns positions (P, 2) [m] and powers (P,) [dB counts]; P is the same for every car.
    """
    hl, hw = cfg.car_length_m / 2, cfg.car_width_m / 2
    xy = np.array(
        [
            [hl, hw],
            [hl, -hw],
            [-hl, hw],
            [-hl, -hw],  # corners
            [hl * 0.6, hw],
            [hl * 0.6, -hw],
            [-hl * 0.6, hw],
            [-hl * 0.6, -hw],  # wheel houses
            [0.0, hw],
            [0.0, -hw],
            [hl, 0.0],
            [-hl, 0.0],  # doors, bumpers
        ]
    )
    xy = xy + rng.normal(0, 0.1, xy.shape)
    db = rng.uniform(*cfg.car_db, len(xy))
    return xy, db


def _place_body(xy: NDArray[np.float64], pose: NDArray[np.float64]) -> NDArray[np.float64]:
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return xy @ np.array([[c, s], [-s, c]]) + pose[:2]


def _parked_cars(
    builder: ScattererBuilder, town: Town, cfg: ObjectConfig, rng: np.random.Generator, owner0: int
) -> Occluders:
    """Session-dependent parked cars; returns their bodies as occluders."""
    occupied = town.parking[rng.random(len(town.parking)) < cfg.parking_occupancy]
    p0s, p1s, owners = [], [], []
    for k, bay in enumerate(occupied):
        pose = bay + np.array([0.0, 0.0, rng.normal(0, np.deg2rad(2))])
        shift = rng.uniform(-0.6, 0.6)
        pose[:2] += shift * np.array([np.cos(pose[2]), np.sin(pose[2])])
        xy, db = car_body(rng, cfg)
        builder.add(_place_body(xy, pose), db, "parked_car", owner=owner0 + k)
        box = _place_body(xy[[0, 2, 3, 1]], pose)
        for j in range(4):
            p0s.append(box[j])
            p1s.append(box[(j + 1) % 4])
            owners.append(owner0 + k)
    n = len(p0s)
    return Occluders(
        np.array(p0s).reshape(-1, 2),
        np.array(p1s).reshape(-1, 2),
        np.full(n, cfg.car_penetration_db, dtype=np.float32),
        np.array(owners, dtype=np.int32),
    )


def _vegetation(
    builder: ScattererBuilder, town: Town, cfg: ObjectConfig, rng: np.random.Generator
) -> None:
    """Session-dependent vegetation patches and tree foliage."""
    for patch in town.parks:
        if rng.random() > cfg.vegetation_keep:
            continue
        factor = rng.uniform(*cfg.vegetation_density_jitter)
        grown = patch.copy()
        grown[2:4] *= np.sqrt(factor)
        n = rng.poisson(cfg.vegetation_density_per_m2 * np.pi * grown[2] * grown[3] * factor)
        pts = _ellipse_points(rng, grown, n)
        builder.add(
            pts[town.raster.lookup(pts) == FREE],
            cfg.vegetation_db,
            "vegetation",
            spread_db=2 * cfg.point_spread_db,
        )
    if len(town.hedges):
        per_point = cfg.hedge_points_per_m * FEATURE_STEP_M
        counts = rng.poisson(
            per_point * rng.uniform(*cfg.vegetation_density_jitter), len(town.hedges)
        )
        pts = np.repeat(town.hedges, counts, axis=0)
        pts = pts + rng.uniform(-0.5, 0.5, pts.shape) * cfg.hedge_width_m
        builder.add(pts, cfg.hedge_db, "vegetation", spread_db=2 * cfg.point_spread_db)
    trunks = town.street_trees
    if len(trunks):
        counts = rng.poisson(
            cfg.foliage_points * rng.uniform(*cfg.vegetation_density_jitter, len(trunks))
        )
        centres = np.repeat(trunks, counts, axis=0)
        r = cfg.foliage_radius_m * np.sqrt(rng.uniform(0, 1, len(centres)))
        t = rng.uniform(0, 2 * np.pi, len(centres))
        pts = centres + np.column_stack([r * np.cos(t), r * np.sin(t)])
        builder.add(
            pts,
            cfg.foliage_db,
            "vegetation",
            spread_db=2 * cfg.point_spread_db,
            height_m=HEIGHT_M["foliage"],
        )


def _traffic(town: Town, cfg: ObjectConfig, rng: np.random.Generator, duration_s: float) -> Traffic:
    """Moving vehicles on random walks through the street graph, driving on the right."""
    total_km = sum(len(r.polyline) for r in town.roads) / 1000.0
    n = rng.poisson(cfg.moving_vehicles_per_km * total_km)
    speeds = rng.uniform(*cfg.moving_speed_mps, n)
    paths, s_start, s_end, bodies, powers = [], [], [], [], []
    offset = 0.0
    for v in range(n):
        need = speeds[v] * duration_s + 50.0
        node = int(rng.integers(len(town.nodes)))
        prev = -1
        pieces: list[NDArray[np.float64]] = []
        length = 0.0
        while length < need:
            options = [m for m in town.neighbours(node) if m != prev] or town.neighbours(node)
            nxt = int(rng.choice(options))
            road = town.road_between(node, nxt)
            assert road is not None
            line = road.polyline if road.a == node else road.polyline[::-1]
            pieces.append(line)
            length += len(line)
            prev, node = node, nxt
        line = resample_polyline(offset_polyline(np.concatenate(pieces), -cfg.lane_offset_m), 1.0)
        s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(line, axis=0).T))])
        start = float(rng.uniform(0, max(s[-1] - need, 1.0)))
        paths.append((line, s + offset))
        s_start.append(offset + start)
        s_end.append(offset + s[-1])
        offset += s[-1] + 10.0
        xy, db = car_body(rng, cfg)
        bodies.append(xy)
        powers.append(10 ** (db / 10))
    if n == 0:
        return no_traffic()
    xy = np.concatenate([p for p, _ in paths])
    return Traffic(
        path_x=np.ascontiguousarray(xy[:, 0]),
        path_y=np.ascontiguousarray(xy[:, 1]),
        path_s=np.concatenate([s for _, s in paths]),
        s_start=np.array(s_start),
        s_end=np.array(s_end),
        speed=speeds,
        body_xy=np.stack(bodies),
        body_power=np.stack(powers).astype(np.float32),
    )


def assemble_world(
    scatterers: Scatterers,
    occluders: Occluders,
    traffic: Traffic | None = None,
    town: Town | None = None,
    session: int = 0,
    specular_exponent: float = ObjectConfig().facade_specular_exponent,
) -> World:
    """A World from its parts (scatterers are sorted into the culling grid)."""
    gridded, origin, shape = grid_scatterers(scatterers)
    return World(
        gridded,
        occluders,
        traffic if traffic is not None else no_traffic(),
        origin,
        shape,
        town,
        session,
        specular_exponent,
    )


def build_world(
    town: Town, cfg: ObjectConfig, seed: int, session: int = 0, duration_s: float = 600.0
) -> World:
    """Populate `town` with scatterers.

    Args:
        town: layout.
        cfg: object reflectivities and geometry.
        seed: seed of the static structure (with the town's own seed, fixes the place).
        session: session index; parked cars, vegetation and traffic change with it.
        duration_s: longest time the traffic must keep driving [s].
    """
    static_rng = np.random.default_rng([seed, STATIC_STREAM])
    session_rng = np.random.default_rng([seed, SESSION_STREAM, session])
    builder = ScattererBuilder(static_rng, cfg.ghost_delay_m)
    facade_occ = _facades(builder, town, cfg, static_rng)
    _lines_and_points(builder, town, cfg, static_rng)
    builder.rng = session_rng
    car_occ = _parked_cars(builder, town, cfg, session_rng, owner0=len(facade_occ.loss_db))
    _vegetation(builder, town, cfg, session_rng)
    occluders = Occluders(
        np.concatenate([facade_occ.p0, car_occ.p0]),
        np.concatenate([facade_occ.p1, car_occ.p1]),
        np.concatenate([facade_occ.loss_db, car_occ.loss_db]),
        np.concatenate([facade_occ.owner, car_occ.owner]),
    )
    traffic = _traffic(town, cfg, session_rng, duration_s)
    world = assemble_world(
        builder.build(), occluders, traffic, town, session, cfg.facade_specular_exponent
    )
    logger.info(
        "world: %d scatterers, %d occluders, %d moving vehicles (session %d)",
        len(world.scatterers),
        len(occluders.loss_db),
        len(traffic),
        session,
    )
    return world


__all__ = [  # the data model lives in radar_slam.sim.scatterers; re-exported for older imports
    "KIND",
    "ObjectConfig",
    "Occluders",
    "Scatterers",
    "Traffic",
    "World",
    "assemble_world",
    "build_world",
    "concat_scatterers",
    "point_scatterers",
]
