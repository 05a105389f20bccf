"""Town layout from a seed: a warped street lattice with curved roads, buildings along and between
the streets, sidewalks, street furniture, parks and parking bays.

Everything is 2-D, in a local world frame (x east, y north, metres). The street network starts
as a lattice of irregular block sizes in "lattice space", some edges bulge into arcs, some are
dropped, some blocks get a diagonal street, and the whole lattice is mapped through a smooth
warp (rotation plus low-frequency displacement), so streets curve and meet at varied angles.
Buildings are rectangles set back from the streets and aligned with the local street direction,
plus free-standing ones at random orientations inside the blocks. A raster of the ground use
(carriageway, sidewalk, building) rejects overlapping placements.

This module only lays out geometry; `world.py` turns it into radar scatterers.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

logger = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]

FREE, SIDEWALK, ROAD, BUILDING = 0, 1, 2, 3
"""Ground-use classes of the layout raster."""
POLYLINE_STEP_M = 1.0
"""Sampling of road centre lines [m]."""
FEATURE_STEP_M = 0.5
"""Sampling of curbs, fences and guard rails [m]."""
INTERSECTION_CLEARANCE_M = 14.0
"""No parking bays this close to a road's end nodes [m]."""
WORLD_MARGIN_M = 80.0
"""Margin of the layout raster around the outermost road: buildings continue beyond it [m]."""
MAX_WARP_SLOPE = 0.35
"""Upper bound of the warp's displacement gradient (keeps the map one-to-one)."""

BUILDING_HEIGHT_M = (5.0, 30.0)
"""Range of building heights [m]."""
FEATURE_PERIOD_M = (2.5, 6.0)
"""Range of the spacing of facade features (windows, balconies, pillars) [m]."""
PLACEMENT_SHRINK = (1.0, 0.7, 0.45)
"""Scale factors tried in turn when a street building does not fit."""
BUILDING_LINE_MARGIN_M = 0.7
"""Distance between the sidewalk's outer edge and the building line [m]."""
MAX_SIDEWALK_OVERLAP = 0.05
"""Share of a building footprint allowed on sidewalk pixels (raster rounding on curves)."""
PARKING_INSET_M = 1.1
"""Distance of a parking bay's centre inside the curb [m]."""


@dataclass(frozen=True)
class TownConfig:
    """Parameters of the town layout (ranges are uniform (min, max) draws).

    Attributes:
        n_blocks: lattice cells along (x, y); nodes are (n_blocks + 1) per axis.
        block_size_m: side length of a lattice cell [m].
        warp_amplitude_m: amplitude of each smooth displacement component [m].
        warp_wavelength_m: wavelength range of the displacement components [m].
        warp_components: number of displacement components.
        curved_fraction: share of roads bent into an arc.
        max_bulge_fraction: arc sagitta as a fraction of the road length.
        drop_fraction: share of non-protected roads removed (larger blocks, dead ends).
        diagonal_fraction: share of blocks crossed by a diagonal street.
        road_half_width_m: carriageway half width [m].
        sidewalk_m: sidewalk width between carriageway and building line [m].
        building_width_m: frontage of street buildings [m].
        building_depth_m: depth of street buildings [m].
        building_gap_m: gap between neighbouring street buildings [m].
        open_lot_probability: probability of an open lot instead of the next building.
        open_lot_m: length of an open lot [m].
        yaw_jitter_deg: sigma of street buildings' misalignment [deg].
        odd_orientation_probability: share of street buildings at an arbitrary orientation.
        interior_buildings_per_km2: free-standing buildings tried per km^2.
        building_min_gap_m: clearance kept around every building [m].
        park_patches_per_km2: vegetation patches tried per km^2.
        park_axis_m: semi-axis range of a vegetation patch [m].
        street_tree_fraction: share of road sides lined with trees.
        street_tree_spacing_m: spacing of street trees [m].
        pole_spacing_m: spacing of street lights along every road [m].
        guard_rail_fraction: share of road sides with a guard rail at the curb.
        fence_fraction: share of road sides with a fence at the building line.
        hedge_fraction: share of road sides with a hedge at the building line.
        clutter_per_m: small street objects (bins, bikes, signs, bollards) per metre of sidewalk.
        parking_fraction: share of wide-enough road sides with parking bays.
        parking_min_half_width_m: minimum carriageway half width for parking bays [m].
        parking_slot_m: length of a parking bay [m].
        raster_cell_m: cell size of the ground-use raster [m].
    """

    n_blocks: tuple[int, int] = (6, 5)
    block_size_m: tuple[float, float] = (85.0, 135.0)
    warp_amplitude_m: float = 14.0
    warp_wavelength_m: tuple[float, float] = (400.0, 900.0)
    warp_components: int = 3
    curved_fraction: float = 0.3
    max_bulge_fraction: float = 0.12
    drop_fraction: float = 0.08
    diagonal_fraction: float = 0.08
    road_half_width_m: tuple[float, float] = (4.8, 7.0)
    sidewalk_m: tuple[float, float] = (2.0, 5.0)
    building_width_m: tuple[float, float] = (8.0, 40.0)
    building_depth_m: tuple[float, float] = (8.0, 28.0)
    building_gap_m: tuple[float, float] = (1.0, 9.0)
    open_lot_probability: float = 0.15
    open_lot_m: tuple[float, float] = (15.0, 45.0)
    yaw_jitter_deg: float = 3.0
    odd_orientation_probability: float = 0.12
    interior_buildings_per_km2: float = 600.0
    building_min_gap_m: float = 1.5
    park_patches_per_km2: float = 160.0
    park_axis_m: tuple[float, float] = (4.0, 18.0)
    street_tree_fraction: float = 0.35
    street_tree_spacing_m: tuple[float, float] = (7.0, 12.0)
    pole_spacing_m: tuple[float, float] = (25.0, 40.0)
    guard_rail_fraction: float = 0.12
    fence_fraction: float = 0.2
    hedge_fraction: float = 0.25
    clutter_per_m: float = 0.08
    parking_fraction: float = 0.5
    parking_min_half_width_m: float = 5.2
    parking_slot_m: float = 6.0
    raster_cell_m: float = 0.5


@dataclass(frozen=True)
class Road:
    """A street between two lattice nodes.

    Attributes:
        a, b: node ids of its ends.
        polyline: (K, 2) centre line from node a to node b [m], about 1 m steps.
        half_width_m: carriageway half width [m].
        sidewalk_m: sidewalk width [m].
    """

    a: int
    b: int
    polyline: FloatArray
    half_width_m: float
    sidewalk_m: float


@dataclass(frozen=True)
class Building:
    """A rectangular building.

    Attributes:
        corners: (4, 2) corners counter-clockwise [m].
        feature_period_m: spacing of facade features (windows, balconies, pillars) [m].
        height_m: height [m].
    """

    corners: FloatArray
    feature_period_m: float
    height_m: float


@dataclass
class Raster:
    """Ground-use raster: `classes[row, col]` covers x = x0 + (col + 0.5) cell, y likewise."""

    classes: NDArray[np.uint8]
    x0: float
    y0: float
    cell_m: float

    def pixels(self, points: FloatArray) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """(rows, cols) of world points (N, 2), clipped to the raster."""
        cols = np.clip(
            ((points[:, 0] - self.x0) / self.cell_m).astype(np.int64), 0, self.classes.shape[1] - 1
        )
        rows = np.clip(
            ((points[:, 1] - self.y0) / self.cell_m).astype(np.int64), 0, self.classes.shape[0] - 1
        )
        return rows, cols

    def lookup(self, points: FloatArray) -> NDArray[np.uint8]:
        """Ground-use class at world points (N, 2)."""
        rows, cols = self.pixels(np.asarray(points, dtype=np.float64).reshape(-1, 2))
        return self.classes[rows, cols]

    def to_pixel_polygon(self, points: FloatArray) -> NDArray[np.int32]:
        """World polygon (K, 2) as int32 pixel coordinates (col, row) for cv2 drawing."""
        px = (np.asarray(points) - (self.x0, self.y0)) / self.cell_m
        return np.round(px).astype(np.int32)


@dataclass
class Town:
    """The laid-out town.

    Attributes:
        nodes: (N, 2) world positions of the lattice nodes [m].
        lattice: (N, 2) integer lattice indices (i, j) of the nodes.
        roads: streets.
        buildings: buildings.
        curbs, guard_rails, fences: (M, 4) points every FEATURE_STEP_M along those features:
            x, y [m] and the unit normal of the street there (nx, ny).
        hedges: (H, 2) points every FEATURE_STEP_M along hedges [m].
        clutter: (C, 2) small street objects on the sidewalks [m].
        poles: (P, 2) street lights and signs [m].
        street_trees: (T, 2) trunks along streets [m].
        parks: (V, 5) vegetation patches: centre x, y [m], semi-axes a, b [m], yaw [rad].
        parking: (S, 3) parking bays: centre x, y [m], yaw [rad] along the street.
        raster: ground-use raster.
    """

    nodes: FloatArray
    lattice: NDArray[np.int64]
    roads: list[Road]
    buildings: list[Building]
    curbs: FloatArray
    guard_rails: FloatArray
    fences: FloatArray
    hedges: FloatArray
    clutter: FloatArray
    poles: FloatArray
    street_trees: FloatArray
    parks: FloatArray
    parking: FloatArray
    raster: Raster
    _node_ids: dict[tuple[int, int], int] = field(default_factory=dict, repr=False)

    def node_id(self, i: int, j: int) -> int:
        """Id of the node at lattice index (i, j)."""
        if not self._node_ids:
            self._node_ids.update({(int(a), int(b)): k for k, (a, b) in enumerate(self.lattice)})
        return self._node_ids[(i, j)]

    def road_between(self, a: int, b: int) -> Road | None:
        """The road joining nodes a and b (either direction), or None."""
        for road in self.roads:
            if {road.a, road.b} == {a, b}:
                return road
        return None

    def neighbours(self, node: int) -> list[int]:
        """Nodes joined to `node` by a road."""
        return [r.b if r.a == node else r.a for r in self.roads if node in (r.a, r.b)]

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of the layout raster [m]."""
        h, w = self.raster.classes.shape
        r = self.raster
        return (r.x0, r.y0, r.x0 + w * r.cell_m, r.y0 + h * r.cell_m)


def _uniform(rng: np.random.Generator, bounds: tuple[float, float]) -> float:
    return float(rng.uniform(bounds[0], bounds[1]))


def resample_polyline(points: FloatArray, step_m: float) -> FloatArray:
    """Resample a polyline (K, 2) at equal arc-length steps (keeps both ends)."""
    seg = np.hypot(*np.diff(points, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    n = max(2, int(np.ceil(s[-1] / step_m)) + 1)
    si = np.linspace(0.0, s[-1], n)
    return np.stack([np.interp(si, s, points[:, 0]), np.interp(si, s, points[:, 1])], axis=1)


def polyline_frames(points: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Arc length (K,), unit tangents (K, 2) and left normals (K, 2) of a polyline."""
    seg = np.hypot(*np.diff(points, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    tangent = np.gradient(points, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-9)
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    return s, tangent, normal


def offset_polyline(points: FloatArray, offset_m: float) -> FloatArray:
    """The polyline shifted sideways by `offset_m` (positive: to the left of travel)."""
    _, _, normal = polyline_frames(points)
    return points + offset_m * normal


@dataclass(frozen=True)
class _Warp:
    """Smooth map lattice space -> world: rotation plus a sum of sinusoidal displacements."""

    rotation_rad: float
    amplitudes: FloatArray  # (C, 2) displacement vectors [m]
    wavevectors: FloatArray  # (C, 2) [rad/m]
    phases: FloatArray  # (C,)

    def __call__(self, p: FloatArray) -> FloatArray:
        arg = p @ self.wavevectors.T + self.phases  # (N, C)
        q = p + np.sin(arg) @ self.amplitudes
        c, s = np.cos(self.rotation_rad), np.sin(self.rotation_rad)
        return q @ np.array([[c, s], [-s, c]])


def _make_warp(rng: np.random.Generator, cfg: TownConfig) -> _Warp:
    n = cfg.warp_components
    wavelengths = rng.uniform(*cfg.warp_wavelength_m, n)
    directions = rng.uniform(0, 2 * np.pi, n)
    k = (2 * np.pi / wavelengths)[:, None] * np.stack([np.cos(directions), np.sin(directions)], 1)
    amp_dirs = rng.uniform(0, 2 * np.pi, n)
    amplitude = min(
        cfg.warp_amplitude_m, MAX_WARP_SLOPE * float(wavelengths.min()) / (2 * np.pi * n)
    )
    amps = amplitude * np.stack([np.cos(amp_dirs), np.sin(amp_dirs)], 1)
    return _Warp(float(rng.uniform(0, np.pi / 2)), amps, k, rng.uniform(0, 2 * np.pi, n))


def _lattice(
    rng: np.random.Generator, cfg: TownConfig, protected: set[frozenset[tuple[int, int]]]
) -> tuple[NDArray[np.int64], FloatArray, list[tuple[int, int, float]]]:
    """Lattice indices (N, 2), lattice-space positions (N, 2) and edges (a, b, bulge [m])."""
    nx, ny = cfg.n_blocks
    xs = np.concatenate([[0.0], np.cumsum(rng.uniform(*cfg.block_size_m, nx))])
    ys = np.concatenate([[0.0], np.cumsum(rng.uniform(*cfg.block_size_m, ny))])
    ii, jj = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), indexing="ij")
    lattice = np.stack([ii.ravel(), jj.ravel()], axis=1)
    pos = np.stack([xs[lattice[:, 0]], ys[lattice[:, 1]]], axis=1)
    index = {(int(i), int(j)): k for k, (i, j) in enumerate(lattice)}
    candidates = []
    for (i, j), k in index.items():
        for di, dj in ((1, 0), (0, 1)):
            if (i + di, j + dj) in index:
                candidates.append((k, index[(i + di, j + dj)]))
    degree = np.zeros(len(lattice), dtype=np.int64)
    for a, b in candidates:
        degree[a] += 1
        degree[b] += 1
    edges: list[tuple[int, int, float]] = []
    for a, b in candidates:
        key = frozenset(
            {(int(lattice[a][0]), int(lattice[a][1])), (int(lattice[b][0]), int(lattice[b][1]))}
        )
        if (
            key not in protected
            and rng.random() < cfg.drop_fraction
            and min(degree[a], degree[b]) > 2
        ):
            degree[a] -= 1
            degree[b] -= 1
            continue
        length = float(np.hypot(*(pos[b] - pos[a])))
        bulge = 0.0
        if key not in protected and rng.random() < cfg.curved_fraction:
            bulge = float(rng.uniform(-1, 1)) * cfg.max_bulge_fraction * length
        edges.append((a, b, bulge))
    for i in range(nx):
        for j in range(ny):
            if rng.random() < cfg.diagonal_fraction:
                if rng.random() < 0.5:
                    edges.append((index[(i, j)], index[(i + 1, j + 1)], 0.0))
                else:
                    edges.append((index[(i + 1, j)], index[(i, j + 1)], 0.0))
    return lattice, pos, edges


def _draw_roads(raster: Raster, roads: list[Road]) -> None:
    """Sidewalks then carriageways onto the raster (carriageway wins)."""
    for cls, width in ((SIDEWALK, "outer"), (ROAD, "inner")):
        for road in roads:
            half = road.half_width_m + (road.sidewalk_m if width == "outer" else 0.0)
            thickness = max(1, int(round(2 * half / raster.cell_m)))
            pts = raster.to_pixel_polygon(road.polyline)
            cv2.polylines(
                raster.classes, [pts], False, cls, thickness=thickness, lineType=cv2.LINE_8
            )
            for end in (pts[0], pts[-1]):
                cv2.circle(raster.classes, (int(end[0]), int(end[1])), thickness // 2, cls, -1)


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
                    cursor += _uniform(rng, cfg.open_lot_m)
                    continue
                width = _uniform(rng, cfg.building_width_m)
                depth = _uniform(rng, cfg.building_depth_m)
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
                cursor += width + _uniform(rng, cfg.building_gap_m)
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
            _uniform(rng, cfg.building_width_m),
            _uniform(rng, cfg.building_depth_m),
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
    protected = protected_edges or set()
    lattice, lattice_pos, edges = _lattice(rng, cfg, protected)
    warp = _make_warp(rng, cfg)
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
                half_width_m=_uniform(rng, cfg.road_half_width_m),
                sidewalk_m=_uniform(rng, cfg.sidewalk_m),
            )
        )
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
    _draw_roads(raster, roads)
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
