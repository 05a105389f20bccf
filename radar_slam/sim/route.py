"""The ego vehicle's trajectory: a route through the street graph driven in the right lane at
5-15 m/s with smooth turns.

A route is a list of lattice waypoints joined along lattice lines. Its centre line is smoothed
(Gaussian along arc length: corners become smooth turns), shifted into the right-hand lane, and
time-parametrised with a speed profile limited by a per-street cruise speed, lateral
acceleration in turns, and longitudinal acceleration/deceleration. Poses are those of the
vehicle base (x forward, y left) in the town frame; the radar is mounted at
`MULRAN_T_BASE_RADAR` on the base, as in MulRan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from radar_slam.datasets.navtech import MULRAN_T_BASE_RADAR
from radar_slam.errors import RadarSlamError
from radar_slam.sim.town import Town, offset_polyline, resample_polyline
from raplace import compose, wrap_angle

FloatArray = NDArray[np.float64]

PATH_STEP_M = 0.1
"""Arc-length sampling of the smoothed path [m]."""
TIME_STEP_S = 0.002
"""Time sampling of the stored trajectory; poses in between are interpolated linearly [s]."""
SMOOTHING_TRUNCATE = 4.0
"""The centre-line Gaussian is cut off at this many sigmas (scipy's default)."""
MAX_LATERAL_ACCEL_MPS2 = 7.0
"""About 0.7 g: what a car's tyres hold on dry asphalt; no drive's minimum speed exceeds it."""


@dataclass(frozen=True)
class DrivingConfig:
    """How the ego vehicle drives.

    Attributes:
        min_speed_mps: lowest speed, also in tight turns, unless a turn is too tight for it
            within MAX_LATERAL_ACCEL_MPS2 [m/s].
        cruise_speed_mps: range of the cruise speed drawn per street [m/s] (max 15).
        lateral_accel_mps2: lateral acceleration limit in turns [m/s^2].
        accel_mps2: longitudinal acceleration limit [m/s^2].
        decel_mps2: braking limit [m/s^2].
        smoothing_m: Gaussian sigma of the centre-line smoothing (sets the turn radius) [m].
        lane_offset_m: lane centre right of the street centre line [m]; opposite directions
            of the same street are 2 * lane_offset_m apart.
    """

    min_speed_mps: float = 5.0
    cruise_speed_mps: tuple[float, float] = (10.0, 15.0)
    lateral_accel_mps2: float = 2.5
    accel_mps2: float = 1.2
    decel_mps2: float = 2.0
    smoothing_m: float = 8.0
    lane_offset_m: float = 1.75


@dataclass(frozen=True)
class Trajectory:
    """Base poses sampled every TIME_STEP_S from t = 0.

    Attributes:
        t_s: (K,) times [s].
        poses: (K, 3) base poses (x [m], y [m], yaw [rad], yaw unwrapped) in the town frame.
        length_m: driven distance [m].
    """

    t_s: FloatArray
    poses: FloatArray
    length_m: float

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1])

    def base_poses(self, t_s: FloatArray) -> FloatArray:
        """(N, 3) base poses at times `t_s` (N,) [s], yaw wrapped to [-pi, pi)."""
        t = np.asarray(t_s, dtype=np.float64)
        out = np.stack([np.interp(t, self.t_s, self.poses[:, k]) for k in range(3)], axis=-1)
        out[..., 2] = wrap_angle(out[..., 2])
        return out

    def radar_poses(self, t_s: FloatArray) -> FloatArray:
        """(N, 3) radar poses T_world_radar = T_world_base * T_base_radar at times `t_s`."""
        return compose(self.base_poses(t_s), MULRAN_T_BASE_RADAR)


def expand_waypoints(waypoints: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """Lattice nodes visited when going straight from waypoint to waypoint (same i or same j)."""
    nodes = [waypoints[0]]
    for (i0, j0), (i1, j1) in zip(waypoints[:-1], waypoints[1:], strict=True):
        if i0 != i1 and j0 != j1:
            raise RadarSlamError(
                f"route waypoints {(i0, j0)} -> {(i1, j1)} are not on one lattice line"
            )
        n = max(abs(i1 - i0), abs(j1 - j0))
        for k in range(1, n + 1):
            nodes.append((i0 + k * np.sign(i1 - i0), j0 + k * np.sign(j1 - j0)))
    return [(int(i), int(j)) for i, j in nodes]


def route_edges(waypoints: list[tuple[int, int]]) -> set[frozenset[tuple[int, int]]]:
    """Lattice edges a route drives on (to protect them when the town is laid out)."""
    nodes = expand_waypoints(waypoints)
    return {frozenset({a, b}) for a, b in zip(nodes[:-1], nodes[1:], strict=True)}


def path_heading(path: FloatArray) -> FloatArray:
    """Unwrapped direction of travel [rad] (K,) along a path (K, 2) [m] driven forwards."""
    d = np.gradient(path, axis=0)
    return np.unwrap(np.arctan2(d[:, 1], d[:, 0]))


def route_centre_line(
    town: Town, waypoints: list[tuple[int, int]]
) -> tuple[FloatArray, list[float]]:
    """Street centre line of a route (K, 2) [m], from the middle of its first street to the
    middle of its last one, and the cruise-speed street boundaries' arc lengths (for speeds)."""
    nodes = [town.node_id(i, j) for i, j in expand_waypoints(waypoints)]
    pieces = []
    for a, b in zip(nodes[:-1], nodes[1:], strict=True):
        road = town.road_between(a, b)
        if road is None:
            raise RadarSlamError(
                f"no street between nodes {a} and {b}: the route needs protected edges"
            )
        pieces.append(road.polyline if road.a == a else road.polyline[::-1])
    lengths = [float(np.sum(np.hypot(*np.diff(p, axis=0).T))) for p in pieces]
    line = np.concatenate([p if k == 0 else p[1:] for k, p in enumerate(pieces)])
    line = resample_polyline(line, PATH_STEP_M)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(line, axis=0).T))])
    start, end = lengths[0] / 2, s[-1] - lengths[-1] / 2
    keep = (s >= start) & (s <= end)
    boundaries = list(np.cumsum(lengths)[:-1] - start)
    return line[keep], boundaries


def limit_acceleration(v: FloatArray, ds: FloatArray, accel_mps2: float, decel_mps2: float) -> None:
    """Lower the speeds `v` (K,) [m/s] in place so that no step of length `ds` (K - 1,) [m]
    accelerates faster than `accel_mps2` or brakes harder than `decel_mps2` [m/s^2]."""
    for k in range(len(ds)):  # sequential by nature: each speed bounds the next
        v[k + 1] = min(v[k + 1], math.sqrt(v[k] ** 2 + 2 * accel_mps2 * ds[k]))
    for k in range(len(ds) - 1, -1, -1):
        v[k] = min(v[k], math.sqrt(v[k + 1] ** 2 + 2 * decel_mps2 * ds[k]))


def speed_cap(curvature: FloatArray, cruise: FloatArray, cfg: DrivingConfig) -> FloatArray:
    """The smooth drive's speed cap [m/s] at curvatures `curvature` [1/m] and cruise speeds
    `cruise` [m/s]: the cruise speed, lowered by the lateral acceleration limit in turns, never
    below the minimum speed where a car can take the turn at that speed."""
    k = np.maximum(np.abs(curvature), 1e-6)
    floor = np.minimum(cfg.min_speed_mps, np.sqrt(MAX_LATERAL_ACCEL_MPS2 / k))
    return np.maximum(np.minimum(cruise, np.sqrt(cfg.lateral_accel_mps2 / k)), floor)


def _speed_profile(
    s: FloatArray, curvature: FloatArray, cruise: FloatArray, cfg: DrivingConfig
) -> FloatArray:
    """Speed at each arc length: cruise and turn limits, then acceleration limits both ways."""
    v = speed_cap(curvature, cruise, cfg)
    v[0] = min(v[0], cfg.min_speed_mps)
    limit_acceleration(v, np.diff(s), cfg.accel_mps2, cfg.decel_mps2)
    return v


def smoothed_centre_line(centre: FloatArray, cfg: DrivingConfig) -> FloatArray:
    """The route's centre line (K, 2) [m], sampled every PATH_STEP_M, smoothed along its
    length by a Gaussian of `cfg.smoothing_m` (corners become turns); same K samples."""
    from scipy.ndimage import gaussian_filter1d  # SciPy's ndimage only when a route is made

    sigma = cfg.smoothing_m / PATH_STEP_M
    return np.stack(
        [
            gaussian_filter1d(centre[:, k], sigma, mode="nearest", truncate=SMOOTHING_TRUNCATE)
            for k in range(2)
        ],
        axis=1,
    )


def smoothing_reach(cfg: DrivingConfig) -> int:
    """Samples either side of a centre-line sample that its smoothed value depends on."""
    return int(SMOOTHING_TRUNCATE * cfg.smoothing_m / PATH_STEP_M + 0.5)


def cruise_speeds(
    s: FloatArray, boundaries: list[float], cfg: DrivingConfig, rng: np.random.Generator
) -> FloatArray:
    """Cruise speed [m/s] at arc lengths `s` [m], drawn per street (street boundaries at
    `boundaries` [m], from `route_centre_line`)."""
    edges = np.concatenate([[0.0], boundaries, [np.inf]])
    cruise_per_street = rng.uniform(*cfg.cruise_speed_mps, len(edges) - 1)
    return cruise_per_street[np.searchsorted(edges, s, side="right") - 1]


def drive(
    town: Town, waypoints: list[tuple[int, int]], cfg: DrivingConfig, rng: np.random.Generator
) -> Trajectory:
    """Drive a route: smoothed right-lane path, speed profile, and base poses over time.

    Args:
        town: the layout.
        waypoints: lattice waypoints of the route (consecutive ones on one lattice line).
        cfg: driving behaviour.
        rng: draws the cruise speed of every street.
    """
    centre, boundaries = route_centre_line(town, waypoints)
    smooth = smoothed_centre_line(centre, cfg)
    path = resample_polyline(offset_polyline(smooth, -cfg.lane_offset_m), PATH_STEP_M)
    heading = path_heading(path)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path, axis=0).T))])
    curvature = np.gradient(heading, s)
    cruise = cruise_speeds(s, boundaries, cfg, rng)
    v = _speed_profile(s, curvature, cruise, cfg)
    t = np.concatenate([[0.0], np.cumsum(np.diff(s) / (0.5 * (v[1:] + v[:-1])))])
    t_grid = np.arange(0.0, t[-1], TIME_STEP_S)
    s_grid = np.interp(t_grid, t, s)
    poses = np.stack(
        [
            np.interp(s_grid, s, path[:, 0]),
            np.interp(s_grid, s, path[:, 1]),
            np.interp(s_grid, s, heading),
        ],
        axis=1,
    )
    return Trajectory(t_s=t_grid, poses=poses, length_m=float(s[-1]))
