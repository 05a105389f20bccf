"""The simulated world's data model: point scatterers, occluders, traffic, and the `World`.

Powers are linear, in counts at `PathLoss.reference_range_m` (see physics.py). Scatterers are
kept sorted by the cells of a spatial grid so that a scan culls them by cell.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from radar_slam.sim.town import Town

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
HEADING_BASE_M = 0.5
"""Half the baseline used to compute a moving vehicle's heading from its path [m]."""
GRID_CELL_M = 40.0
"""Cell size of the spatial grid used to cull scatterers per scan [m]."""


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


class ScattererBuilder:
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


def grid_scatterers(
    scatterers: Scatterers,
) -> tuple[Scatterers, tuple[float, float], tuple[int, int]]:
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
    builder = ScattererBuilder(np.random.default_rng(0), (0.0, 0.0))
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
