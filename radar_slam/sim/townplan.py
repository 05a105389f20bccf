"""A town laid out from a seed: the street network, then buildings along and between the streets,
street furniture (curbs, fences, guard rails, hedges, poles, trees, clutter), parking bays and
parks, each placement checked against the ground-use raster.
"""

from __future__ import annotations

import logging

import cv2
import numpy as np
from numpy.typing import NDArray

from radar_slam.sim.town import (
    BUILDING,
    BUILDING_HEIGHT_M,
    BUILDING_LINE_MARGIN_M,
    FEATURE_PERIOD_M,
    FEATURE_STEP_M,
    FREE,
    INTERSECTION_CLEARANCE_M,
    MAX_SIDEWALK_OVERLAP,
    PARKING_INSET_M,
    PLACEMENT_SHRINK,
    POLYLINE_STEP_M,
    ROAD,
    SIDEWALK,
    WORLD_MARGIN_M,
    Building,
    FloatArray,
    Raster,
    Road,
    Town,
    TownConfig,
    draw_roads,
    make_warp,
    offset_polyline,
    polyline_frames,
    resample_polyline,
    street_lattice,
    uniform_in,
)

logger = logging.getLogger(__name__)


def _rectangle(centre: FloatArray, yaw: float, width: float, depth: float) -> FloatArray:
    """(4, 2) corners (counter-clockwise) of a rectangle with `width` along `yaw`."""
    c, s = np.cos(yaw), np.sin(yaw)
    u, v = np.array([c, s]) * width / 2, np.array([-s, c]) * depth / 2
    return np.array([centre - u - v, centre + u - v, centre + u + v, centre - u + v])


def _try_place(raster: Raster, corners: FloatArray, gap_m: float) -> bool:
    """Place a rectangular building (drawn into the raster) if its footprint lies on free ground
    (up to raster rounding at the sidewalk edge) and, grown by gap_m on every side, touches no
    other building."""
    centre = corners.mean(axis=0)
    u = corners[1] - corners[0]
    v = corners[3] - corners[0]
    grow_u = u * (0.5 + gap_m / max(float(np.hypot(*u)), 1e-6))
    grow_v = v * (0.5 + gap_m / max(float(np.hypot(*v)), 1e-6))
    grown = centre + np.array(
        [-grow_u - grow_v, grow_u - grow_v, grow_u + grow_v, -grow_u + grow_v]
    )
    px_grown = raster.to_pixel_polygon(grown)
    h, w = raster.classes.shape
    c0, r0 = px_grown.min(axis=0)
    c1, r1 = px_grown.max(axis=0) + 1
    if c0 < 0 or r0 < 0 or c1 > w or r1 > h:
        return False
    window = raster.classes[r0:r1, c0:c1]
    mask = np.zeros(window.shape, dtype=np.uint8)
    cv2.fillConvexPoly(mask, px_grown - (c0, r0), 1)
    if np.any(window[mask > 0] == BUILDING):
        return False
    mask[:] = 0
    px = raster.to_pixel_polygon(corners)
    cv2.fillConvexPoly(mask, px - (c0, r0), 1)
    under = window[mask > 0]
    if np.any(under >= ROAD) or np.mean(under == SIDEWALK) > MAX_SIDEWALK_OVERLAP:
        return False
    cv2.fillConvexPoly(raster.classes, px, BUILDING)
    return True


def _new_building(rng: np.random.Generator, corners: FloatArray) -> Building:
    return Building(
        corners=corners,
        feature_period_m=float(rng.uniform(*FEATURE_PERIOD_M)),
        height_m=float(rng.uniform(*BUILDING_HEIGHT_M)),
    )


def _street_buildings(
    rng: np.random.Generator, cfg: TownConfig, raster: Raster, roads: list[Road]
) -> list[Building]:
    buildings: list[Building] = []
    for road in roads:
        s, tangent, normal = polyline_frames(road.polyline)
        for side in (-1.0, 1.0):
            cursor = float(rng.uniform(0, 8))
            while cursor < s[-1]:
                if rng.random() < cfg.open_lot_probability:
                    cursor += uniform_in(rng, cfg.open_lot_m)
                    continue
                width = uniform_in(rng, cfg.building_width_m)
                depth = uniform_in(rng, cfg.building_depth_m)
                mid = min(cursor + width / 2, s[-1])
                k = int(np.searchsorted(s, mid).clip(0, len(s) - 1))
                yaw = float(np.arctan2(tangent[k, 1], tangent[k, 0]))
                yaw += np.deg2rad(rng.normal(0, cfg.yaw_jitter_deg))
                setback = road.half_width_m + road.sidewalk_m + depth / 2 + BUILDING_LINE_MARGIN_M
                if rng.random() < cfg.odd_orientation_probability:
                    yaw += float(rng.uniform(0.2, np.pi / 2 - 0.2))
                    setback += 0.3 * max(width, depth)
                for shrink in PLACEMENT_SHRINK:  # retry smaller near corners and on curves
                    w, d = width * shrink, depth * shrink
                    offset = road.half_width_m + road.sidewalk_m + d / 2 + (setback - depth / 2)
                    corners = _rectangle(road.polyline[k] + side * offset * normal[k], yaw, w, d)
                    if _try_place(raster, corners, cfg.building_min_gap_m):
                        buildings.append(_new_building(rng, corners))
                        break
                cursor += width + uniform_in(rng, cfg.building_gap_m)
    return buildings


def _interior_buildings(
    rng: np.random.Generator, cfg: TownConfig, raster: Raster
) -> list[Building]:
    xmin, ymin = raster.x0, raster.y0
    h, w = raster.classes.shape
    area_km2 = h * w * raster.cell_m**2 / 1e6
    buildings = []
    for _ in range(int(cfg.interior_buildings_per_km2 * area_km2)):
        centre = np.array(
            [xmin + rng.uniform(0, w * raster.cell_m), ymin + rng.uniform(0, h * raster.cell_m)]
        )
        corners = _rectangle(
            centre,
            float(rng.uniform(0, np.pi)),
            uniform_in(rng, cfg.building_width_m),
            uniform_in(rng, cfg.building_depth_m),
        )
        if _try_place(raster, corners, cfg.building_min_gap_m):
            buildings.append(_new_building(rng, corners))
    return buildings


def _side_points(road: Road, offset_m: float, step_m: float) -> FloatArray:
    """(K, 4) points every step_m along a road at a lateral offset (positive: left of a->b),
    with the unit normal of the road there: x, y, nx, ny."""
    line = resample_polyline(offset_polyline(road.polyline, offset_m), step_m)
    _, _, normal = polyline_frames(line)
    return np.hstack([line, normal])


def _street_features(
    rng: np.random.Generator, cfg: TownConfig, raster: Raster, roads: list[Road]
) -> dict[str, FloatArray]:
    curbs, rails, fences, hedges, clutter, poles, trees, parking = [], [], [], [], [], [], [], []
    for road in roads:
        for side in (-1.0, 1.0):
            curb = _side_points(road, side * road.half_width_m, FEATURE_STEP_M)
            outward = _side_points(road, side * (road.half_width_m + 0.6), FEATURE_STEP_M)
            n = min(len(curb), len(outward))
            curbs.append(curb[:n][raster.lookup(outward[:n, :2]) == SIDEWALK])
            if rng.random() < cfg.guard_rail_fraction:
                rail = _side_points(road, side * (road.half_width_m + 0.5), FEATURE_STEP_M)
                rails.append(rail[raster.lookup(rail[:, :2]) == SIDEWALK])
            if rng.random() < cfg.fence_fraction:
                fence = _side_points(
                    road, side * (road.half_width_m + road.sidewalk_m + 0.2), FEATURE_STEP_M
                )
                fences.append(fence[raster.lookup(fence[:, :2]) == FREE])
            elif rng.random() < cfg.hedge_fraction:
                hedge = _side_points(
                    road, side * (road.half_width_m + road.sidewalk_m + 0.5), FEATURE_STEP_M
                )
                hedges.append(hedge[raster.lookup(hedge[:, :2]) == FREE, :2])
            walk = _side_points(road, side * (road.half_width_m + 0.5 * road.sidewalk_m), 1.0)
            picks = rng.random(len(walk)) < cfg.clutter_per_m
            spot = (
                walk[picks, :2]
                + side
                * walk[picks, 2:]
                * rng.uniform(-0.4, 0.4, (int(picks.sum()), 1))
                * road.sidewalk_m
            )
            clutter.append(spot[raster.lookup(spot) == SIDEWALK])
            if rng.random() < cfg.street_tree_fraction:
                row = _side_points(road, side * (road.half_width_m + 0.6 * road.sidewalk_m), 1.0)[
                    :, :2
                ]
                idx = np.cumsum(rng.uniform(*cfg.street_tree_spacing_m, len(row))).astype(np.int64)
                row = row[idx[idx < len(row)]]
                trees.append(row[raster.lookup(row) == SIDEWALK])
            line = _side_points(road, side * (road.half_width_m + 0.6), 1.0)[:, :2]
            idx = np.cumsum(rng.uniform(*cfg.pole_spacing_m, len(line))).astype(np.int64)
            sel = line[idx[idx < len(line)]]
            poles.append(sel[raster.lookup(sel) == SIDEWALK])
            if (
                road.half_width_m >= cfg.parking_min_half_width_m
                and rng.random() < cfg.parking_fraction
            ):
                parking.append(_parking_bays(cfg, raster, road, side))

    def stack(parts: list[FloatArray], width: int) -> FloatArray:
        return np.concatenate(parts) if parts else np.zeros((0, width))

    return {
        "curbs": stack(curbs, 4),
        "guard_rails": stack(rails, 4),
        "fences": stack(fences, 4),
        "hedges": stack(hedges, 2),
        "clutter": stack(clutter, 2),
        "poles": stack(poles, 2),
        "street_trees": stack(trees, 2),
        "parking": stack(parking, 3),
    }


def _parking_bays(cfg: TownConfig, raster: Raster, road: Road, side: float) -> NDArray[np.float64]:
    s, tangent, normal = polyline_frames(road.polyline)
    stations = np.arange(
        INTERSECTION_CLEARANCE_M, s[-1] - INTERSECTION_CLEARANCE_M, cfg.parking_slot_m
    )
    if len(stations) == 0:
        return np.zeros((0, 3))
    k = np.searchsorted(s, stations).clip(0, len(s) - 1)
    centre = road.polyline[k] + side * (road.half_width_m - PARKING_INSET_M) * normal[k]
    outside = road.polyline[k] + side * (road.half_width_m + 0.6) * normal[k]
    yaw = np.arctan2(tangent[k, 1], tangent[k, 0])
    ok = (raster.lookup(centre) == ROAD) & (raster.lookup(outside) == SIDEWALK)
    return np.column_stack([centre, yaw])[ok]


def _parks(rng: np.random.Generator, cfg: TownConfig, raster: Raster) -> FloatArray:
    h, w = raster.classes.shape
    area_km2 = h * w * raster.cell_m**2 / 1e6
    n = int(cfg.park_patches_per_km2 * area_km2)
    centres = np.column_stack(
        [
            raster.x0 + rng.uniform(0, w * raster.cell_m, n),
            raster.y0 + rng.uniform(0, h * raster.cell_m, n),
        ]
    )
    axes = rng.uniform(*cfg.park_axis_m, (n, 2))
    yaw = rng.uniform(0, np.pi, n)
    ok = raster.lookup(centres) == FREE
    return np.column_stack([centres, axes, yaw])[ok]


def _street_network(
    rng: np.random.Generator, cfg: TownConfig, protected: set[frozenset[tuple[int, int]]]
) -> tuple[FloatArray, NDArray[np.int64], list[Road]]:
    """Node positions (N, 2) [m], their lattice indices (N, 2) and the streets: the first
    draws of `rng` for a town."""
    lattice, lattice_pos, edges = street_lattice(rng, cfg, protected)
    warp = make_warp(rng, cfg)
    nodes = warp(lattice_pos)
    roads: list[Road] = []
    for a, b, bulge in edges:
        u = np.linspace(
            0.0, 1.0, max(2, int(np.hypot(*(lattice_pos[b] - lattice_pos[a])) / POLYLINE_STEP_M))
        )
        d = lattice_pos[b] - lattice_pos[a]
        n = np.array([-d[1], d[0]]) / max(np.hypot(*d), 1e-9)
        pts = lattice_pos[a] + u[:, None] * d + (4 * bulge * u * (1 - u))[:, None] * n
        roads.append(
            Road(
                a=a,
                b=b,
                polyline=resample_polyline(warp(pts), POLYLINE_STEP_M),
                half_width_m=uniform_in(rng, cfg.road_half_width_m),
                sidewalk_m=uniform_in(rng, cfg.sidewalk_m),
            )
        )
    return nodes, lattice, roads


def street_plan(
    seed: int, cfg: TownConfig, protected_edges: set[frozenset[tuple[int, int]]] | None = None
) -> Town:
    """The streets of the town `generate_town` lays out from the same arguments, without
    buildings, street furniture or vegetation (enough to drive a route through: fast)."""
    nodes, lattice, roads = _street_network(
        np.random.default_rng(seed), cfg, protected_edges or set()
    )
    none = np.zeros((0, 4))
    return Town(
        nodes=nodes,
        lattice=lattice,
        roads=roads,
        buildings=[],
        curbs=none,
        guard_rails=none,
        fences=none,
        hedges=np.zeros((0, 2)),
        clutter=np.zeros((0, 2)),
        poles=np.zeros((0, 2)),
        street_trees=np.zeros((0, 2)),
        parks=np.zeros((0, 5)),
        parking=np.zeros((0, 3)),
        raster=Raster(np.zeros((1, 1), dtype=np.uint8), 0.0, 0.0, cfg.raster_cell_m),
    )


def generate_town(
    seed: int, cfg: TownConfig, protected_edges: set[frozenset[tuple[int, int]]] | None = None
) -> Town:
    """Lay out a town from `seed`.

    Args:
        seed: seed of every random draw of the layout.
        cfg: layout parameters.
        protected_edges: lattice edges {(i, j), (i', j')} that must exist and stay straight
            (the routes of a scenario drive on them).
    """
    rng = np.random.default_rng(seed)
    nodes, lattice, roads = _street_network(rng, cfg, protected_edges or set())
    all_pts = np.concatenate([r.polyline for r in roads])
    lo = all_pts.min(axis=0) - WORLD_MARGIN_M
    hi = all_pts.max(axis=0) + WORLD_MARGIN_M
    shape = np.ceil((hi - lo) / cfg.raster_cell_m).astype(np.int64)
    raster = Raster(
        np.zeros((int(shape[1]), int(shape[0])), dtype=np.uint8),
        float(lo[0]),
        float(lo[1]),
        cfg.raster_cell_m,
    )
    draw_roads(raster, roads)
    buildings = _street_buildings(rng, cfg, raster, roads)
    buildings += _interior_buildings(rng, cfg, raster)
    features = _street_features(rng, cfg, raster, roads)
    parks = _parks(rng, cfg, raster)
    logger.info(
        "town: %d roads, %d buildings, %d poles, %d parks, %d parking bays",
        len(roads),
        len(buildings),
        len(features["poles"]),
        len(parks),
        len(features["parking"]),
    )
    return Town(
        nodes=nodes,
        lattice=lattice,
        roads=roads,
        buildings=buildings,
        curbs=features["curbs"],
        guard_rails=features["guard_rails"],
        fences=features["fences"],
        hedges=features["hedges"],
        clutter=features["clutter"],
        poles=features["poles"],
        street_trees=features["street_trees"],
        parks=parks,
        parking=features["parking"],
        raster=raster,
    )
