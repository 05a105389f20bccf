"""Town layout from a seed: a warped street lattice with curved roads, buildings along and between
the streets, sidewalks, street furniture, parks and parking bays.

Everything is 2-D, in a local world frame (x east, y north, metres). The street network starts
as a lattice of irregular block sizes in "lattice space", some edges bulge into arcs, some are
dropped, some blocks get a diagonal street, and the whole lattice is mapped through a smooth
warp (rotation plus low-frequency displacement), so streets curve and meet at varied angles.
Buildings are rectangles set back from the streets and aligned with the local street direction,
plus free-standing ones at random orientations inside the blocks. A raster of the ground use
(carriageway, sidewalk, building) rejects overlapping placements.

This module holds the layout's records and the street network; `townplan.py` places the
buildings and street furniture (`generate_town`), and `world.py` turns a town into radar
scatterers.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

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

    The defaults build long street canyons: long blocks, near-continuous facades, few open lots
    and free-standing buildings, parking along most streets. A real scan is dominated by the
    street it is driven along; a town seen through gaps between buildings makes every place
    look different and place recognition easy (docs/benchmarks.md, "Simulated places against
    real ones").

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
    block_size_m: tuple[float, float] = (160.0, 250.0)
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
    building_gap_m: tuple[float, float] = (0.5, 3.0)
    open_lot_probability: float = 0.05
    open_lot_m: tuple[float, float] = (15.0, 45.0)
    yaw_jitter_deg: float = 3.0
    odd_orientation_probability: float = 0.03
    interior_buildings_per_km2: float = 150.0
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
    parking_fraction: float = 0.9
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


def uniform_in(rng: np.random.Generator, bounds: tuple[float, float]) -> float:
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
class Warp:
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


def make_warp(rng: np.random.Generator, cfg: TownConfig) -> Warp:
    n = cfg.warp_components
    wavelengths = rng.uniform(*cfg.warp_wavelength_m, n)
    directions = rng.uniform(0, 2 * np.pi, n)
    k = (2 * np.pi / wavelengths)[:, None] * np.stack([np.cos(directions), np.sin(directions)], 1)
    amp_dirs = rng.uniform(0, 2 * np.pi, n)
    amplitude = min(
        cfg.warp_amplitude_m, MAX_WARP_SLOPE * float(wavelengths.min()) / (2 * np.pi * n)
    )
    amps = amplitude * np.stack([np.cos(amp_dirs), np.sin(amp_dirs)], 1)
    return Warp(float(rng.uniform(0, np.pi / 2)), amps, k, rng.uniform(0, 2 * np.pi, n))


def street_lattice(
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


def draw_roads(raster: Raster, roads: list[Road]) -> None:
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
