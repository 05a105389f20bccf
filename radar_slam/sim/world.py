"""Radar scatterers of a town: what the simulated sensor sees.

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
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

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

KIND_NAMES = (
    "facade",
    "street_clutter",
    "facade_feature",
    "corner",
    "curb",
    "guard_rail",
    "fence",
    "pole",
    "trunk",
    "ground",
    "parked_car",
    "vegetation",
    "moving_vehicle",
)
"""Scatterer kinds (index = `kind` code), for figures and statistics."""
KIND = {name: code for code, name in enumerate(KIND_NAMES)}
STATIC_STREAM, SESSION_STREAM = 0, 1
"""Random streams: static structure from (seed, 0); session content from (seed, 1, session)."""
HEADING_BASE_M = 0.5
"""Half the baseline used to compute a moving vehicle's heading from its path [m]."""
GRID_CELL_M = 40.0
"""Cell size of the spatial grid used to cull scatterers per scan [m]."""


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
    parking_occupancy: float = 0.55
    vegetation_keep: float = 0.8
    vegetation_density_jitter: tuple[float, float] = (0.6, 1.4)
    moving_vehicles_per_km: float = 6.0
    moving_speed_mps: tuple[float, float] = (5.0, 13.0)
    lane_offset_m: float = 1.75
    ghost_delay_m: tuple[float, float] = (2.0, 25.0)


HEIGHT_M = {
    "corner": (0.0, 1.0),
    "street_clutter": (0.3, 1.5),
    "curb": (0.0, 0.15),
    "guard_rail": (0.4, 0.8),
    "fence": (0.0, 1.8),
    "pole": (0.0, 6.0),
    "trunk": (0.0, 3.0),
    "ground": (0.0, 0.0),
    "parked_car": (0.3, 1.4),
    "vegetation": (0.0, 2.5),
    "foliage": (2.0, 8.0),
    "moving_vehicle": (0.3, 1.4),
}
"""Height ranges of scatterers by class [m] (facades: up to the building's height)."""


@dataclass
class Scatterers:
    """Point scatterers (N,) sorted by grid cell (`cell_start[c]:cell_start[c + 1]` is cell c).

    Attributes:
        x, y: world position [m].
        z: height above ground [m].
        power: linear power at the reference range [counts].
        nx, ny: unit facade normal (0 for isotropic scatterers).
        diffuse: diffuse share (1 for isotropic scatterers).
        owner: occluder owner id whose segments never shadow this scatterer (-1: none).
        ghost_delay_m: extra path length of this scatterer's multipath ghost [m].
        kind: KIND code.
    """

    x: F32
    y: F32
    z: F32
    power: F32
    nx: F32
    ny: F32
    diffuse: F32
    owner: NDArray[np.int32]
    ghost_delay_m: F32
    kind: NDArray[np.uint8]
    cell_start: NDArray[np.int64] = field(default_factory=lambda: np.zeros(1, dtype=np.int64))

    def __len__(self) -> int:
        return len(self.x)

    def take(self, index: NDArray[np.int64]) -> Scatterers:
        """The scatterers at `index` (no grid)."""
        return Scatterers(*(getattr(self, n)[index] for n in _FIELDS))


_FIELDS = ("x", "y", "z", "power", "nx", "ny", "diffuse", "owner", "ghost_delay_m", "kind")


@dataclass(frozen=True)
class Occluders:
    """Occluding segments (M,): facades and parked car bodies.

    Attributes:
        p0, p1: (M, 2) end points [m].
        loss_db: penetration loss [dB].
        owner: owner id (a scatterer with the same owner is never shadowed by it).
    """

    p0: NDArray[np.float64]
    p1: NDArray[np.float64]
    loss_db: F32
    owner: NDArray[np.int32]


@dataclass(frozen=True)
class Traffic:
    """Moving vehicles, each driving its own path at constant speed.

    Attributes:
        path_x, path_y: (K,) all paths concatenated, 1 m steps [m].
        path_s: (K,) global arc length; vehicle v's path is s in [s_start[v], s_end[v]].
        s_start, s_end: (V,) global arc length bounds of each path [m].
        speed: (V,) speed [m/s].
        body_xy: (V, P, 2) body-frame scatterer positions (x forward) [m].
        body_power: (V, P) linear power [counts].
    """

    path_x: NDArray[np.float64]
    path_y: NDArray[np.float64]
    path_s: NDArray[np.float64]
    s_start: NDArray[np.float64]
    s_end: NDArray[np.float64]
    speed: NDArray[np.float64]
    body_xy: NDArray[np.float64]
    body_power: F32

    def __len__(self) -> int:
        return len(self.speed)

    def poses(self, vehicle: NDArray[np.int64], t_s: NDArray[np.float64]) -> NDArray[np.float64]:
        """(N, 3) world poses (x, y, yaw) of vehicles `vehicle` (N,) at times `t_s` (N,) [s]."""
        s = np.minimum(self.s_start[vehicle] + self.speed[vehicle] * t_s, self.s_end[vehicle])
        ahead, behind = s + HEADING_BASE_M, s - HEADING_BASE_M
        x = np.interp(s, self.path_s, self.path_x)
        y = np.interp(s, self.path_s, self.path_y)
        hx = np.interp(ahead, self.path_s, self.path_x) - np.interp(
            behind, self.path_s, self.path_x
        )
        hy = np.interp(ahead, self.path_s, self.path_y) - np.interp(
            behind, self.path_s, self.path_y
        )
        return np.stack([x, y, np.arctan2(hy, hx)], axis=1)


@dataclass
class World:
    """Everything the renderer needs.

    Attributes:
        scatterers: static and session scatterers in a spatial grid.
        occluders: occluding segments.
        traffic: moving vehicles.
        grid_origin: (x, y) of the grid's lower-left corner [m]; grid_shape (ny, nx).
        town: the layout the world was built from (None for hand-made test worlds).
        session: session index.
        specular_exponent: facade specular lobe ~ |cos(incidence)| ** exponent.
    """

    scatterers: Scatterers
    occluders: Occluders
    traffic: Traffic
    grid_origin: tuple[float, float]
    grid_shape: tuple[int, int]
    town: Town | None
    session: int
    specular_exponent: float

    def cull(self, centre: NDArray[np.float64], radius_m: float) -> NDArray[np.int64]:
        """Indices of the scatterers in the grid cells overlapping the disc (centre, radius)."""
        ny, nx = self.grid_shape
        ox, oy = self.grid_origin
        cx0 = int(np.clip(np.floor((centre[0] - radius_m - ox) / GRID_CELL_M), 0, nx - 1))
        cx1 = int(np.clip(np.floor((centre[0] + radius_m - ox) / GRID_CELL_M), 0, nx - 1))
        cy0 = int(np.clip(np.floor((centre[1] - radius_m - oy) / GRID_CELL_M), 0, ny - 1))
        cy1 = int(np.clip(np.floor((centre[1] + radius_m - oy) / GRID_CELL_M), 0, ny - 1))
        starts = self.scatterers.cell_start
        rows = np.arange(cy0, cy1 + 1)
        lo, hi = starts[rows * nx + cx0], starts[rows * nx + cx1 + 1]
        return np.concatenate([np.arange(a, b) for a, b in zip(lo, hi, strict=True)])


class _Builder:
    """Accumulates scatterer arrays of several object classes."""

    def __init__(self, rng: np.random.Generator, ghost_delay_m: tuple[float, float]) -> None:
        self.parts: list[dict[str, np.ndarray]] = []
        self.rng = rng
        self.ghost_delay_m = ghost_delay_m

    def add(
        self,
        xy: NDArray[np.float64],
        power_db: float | NDArray[np.float64],
        kind: str,
        spread_db: float = 0.0,
        normal: NDArray[np.float64] | None = None,
        diffuse: float = 1.0,
        owner: int | NDArray[np.int64] = -1,
        height_m: tuple[float, float] | None = None,
    ) -> None:
        n = len(xy)
        if n == 0:
            return
        z_range = height_m if height_m is not None else HEIGHT_M[kind]
        db = np.broadcast_to(np.asarray(power_db, dtype=np.float64), (n,))
        if spread_db > 0:
            db = db + self.rng.normal(0.0, spread_db, n)
        nrm = np.zeros((n, 2)) if normal is None else np.broadcast_to(normal, (n, 2))
        self.parts.append(
            {
                "x": xy[:, 0],
                "y": xy[:, 1],
                "z": self.rng.uniform(z_range[0], z_range[1], n),
                "power": 10.0 ** (db / 10.0),
                "nx": nrm[:, 0],
                "ny": nrm[:, 1],
                "diffuse": np.full(n, diffuse if normal is not None else 1.0),  # isotropic: 1
                "owner": np.broadcast_to(np.asarray(owner), (n,)),
                "ghost_delay_m": self.rng.uniform(*self.ghost_delay_m, n),
                "kind": np.full(n, KIND[kind]),
            }
        )

    def build(self) -> Scatterers:
        dtypes = {"owner": np.int32, "kind": np.uint8}
        return Scatterers(
            *(
                np.concatenate([p[name] for p in self.parts]).astype(dtypes.get(name, np.float32))
                for name in _FIELDS
            )
        )


def _facades(
    builder: _Builder, town: Town, cfg: ObjectConfig, rng: np.random.Generator
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
    builder: _Builder, town: Town, cfg: ObjectConfig, rng: np.random.Generator
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
    builder: _Builder, town: Town, cfg: ObjectConfig, rng: np.random.Generator, owner0: int
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


def _vegetation(builder: _Builder, town: Town, cfg: ObjectConfig, rng: np.random.Generator) -> None:
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


def _grid(scatterers: Scatterers) -> tuple[Scatterers, tuple[float, float], tuple[int, int]]:
    """Sort scatterers by GRID_CELL_M cell; returns them with the grid origin and (ny, nx)."""
    xmin = float(scatterers.x.min()) if len(scatterers) else 0.0
    ymin = float(scatterers.y.min()) if len(scatterers) else 0.0
    nx = int((float(scatterers.x.max()) - xmin) // GRID_CELL_M) + 1 if len(scatterers) else 1
    ny = int((float(scatterers.y.max()) - ymin) // GRID_CELL_M) + 1 if len(scatterers) else 1
    cx = np.clip(((scatterers.x - xmin) / GRID_CELL_M).astype(np.int64), 0, nx - 1)
    cy = np.clip(((scatterers.y - ymin) / GRID_CELL_M).astype(np.int64), 0, ny - 1)
    cell = cy * nx + cx
    order = np.argsort(cell, kind="stable")
    sorted_sc = scatterers.take(order)
    sorted_sc.cell_start = np.searchsorted(cell[order], np.arange(nx * ny + 1))
    return sorted_sc, (xmin, ymin), (ny, nx)


def point_scatterers(
    xy: NDArray[np.float64],
    power_db: float | NDArray[np.float64],
    kind: str = "pole",
    owner: int = -1,
    height_m: float = 0.0,
    normal: NDArray[np.float64] | None = None,
    diffuse: float = 1.0,
) -> Scatterers:
    """Scatterers at `xy` (N, 2) with fixed powers [dB counts] (hand-made worlds, tests)."""
    builder = _Builder(np.random.default_rng(0), (0.0, 0.0))
    builder.add(
        np.asarray(xy, dtype=np.float64).reshape(-1, 2),
        power_db,
        kind,
        normal=normal,
        diffuse=diffuse,
        owner=owner,
        height_m=(height_m, height_m),
    )
    return builder.build()


def concat_scatterers(parts: list[Scatterers]) -> Scatterers:
    """Scatterers of several sets together (no grid)."""
    return Scatterers(*(np.concatenate([getattr(p, n) for p in parts]) for n in _FIELDS))


def no_traffic() -> Traffic:
    """A Traffic without vehicles."""
    none = np.zeros(0)
    return Traffic(
        none, none, none, none, none, none, np.zeros((0, 0, 2)), np.zeros((0, 0), np.float32)
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
    gridded, origin, shape = _grid(scatterers)
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
    builder = _Builder(static_rng, cfg.ghost_delay_m)
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
