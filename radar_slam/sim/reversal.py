"""Route reversals of the smooth lattice drive, driven as U-turns or three-point turns.

Where a lattice route drives a street and straight back (its expanded nodes k - 1 and k + 1 are
the same), the Gaussian-smoothed centre line of route.py folds onto itself and the lane offset
turns the fold into two corners of almost zero radius: a quarter turn within one radar sweep,
which no vehicle does. `drive_route` drives such a route as a driver would: along the smooth
right-lane path to `TURN_BEFORE_M` before the node, a U-turn at full lock where the carriageway
leaves room for it and a three-point turn where it does not (the legs of manoeuvres.py), into
the opposite lane, and on along the smooth path.

The legs are laid out in street coordinates along the smoothed centre line (station along it,
offset to its left), so they follow a curved street. They end where the smooth lane path of the
way back runs; the few centimetres between the two (the smoothing of the two directions differs
near the street's ends) are blended out over `REJOIN_BLEND_M`. Speeds: the smooth drive's caps
(cruise, lateral acceleration, minimum speed) on its path, the manoeuvre's caps on the legs
(no minimum speed; standing still at the three-point turn's gear changes), then the smooth
drive's acceleration and braking limits throughout; times as for a driving plan (driving.py).
A route without a reversal is driven exactly as `route.drive` drives it.

Poses are those of the vehicle base (x forward, y left) in the town frame.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from radar_slam.errors import RadarSlamError
from radar_slam.sim.driving import (
    PathSamples,
    PlanDrivingConfig,
    integrate_legs,
    limited_speeds,
    time_parametrise,
)
from radar_slam.sim.manoeuvres import fits_u_turn, turn_around_legs
from radar_slam.sim.route import (
    PATH_STEP_M,
    DrivingConfig,
    Trajectory,
    cruise_speeds,
    drive,
    expand_waypoints,
    path_heading,
    route_centre_line,
    smoothed_centre_line,
    smoothing_reach,
    speed_cap,
)
from radar_slam.sim.town import Town, offset_polyline, polyline_frames
from raplace import wrap_angle

logger = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]

TURN_BEFORE_M = 55.0
"""A turn-around starts this far before the node the route turns back at [m]: the whole
manoeuvre stays clear of the fold, which the smoothing spreads `smoothing_reach` samples (32 m)
either side of the node."""
REJOIN_BLEND_M = 20.0
"""Length over which the end of a manoeuvre is blended into the smooth lane path [m]."""
MAX_REJOIN_OFFSET_M = 0.5
"""Largest gap between a manoeuvre's end and the lane path of the way back [m]."""


@dataclass(frozen=True)
class _Piece:
    """Part of a path: samples (n,) and the intervals (n - 1,) between them."""

    xy: FloatArray  # (n, 2) [m]
    heading: FloatArray  # (n,) [rad], unwrapped within the piece
    gear: NDArray[np.int64]  # (n - 1,)
    cap: FloatArray  # (n - 1,) speed cap [m/s]
    stop: NDArray[np.bool_]  # (n,)
    dwell: FloatArray  # (n,) [s]


def reversal_nodes(waypoints: list[tuple[int, int]]) -> list[int]:
    """Indices k of the route's expanded nodes (`route.expand_waypoints`) where it turns back
    along the street it came (node k - 1 is node k + 1)."""
    nodes = expand_waypoints(waypoints)
    return [k for k in range(1, len(nodes) - 1) if nodes[k - 1] == nodes[k + 1]]


def manoeuvre_config(cfg: DrivingConfig) -> PlanDrivingConfig:
    """Settings of a smooth drive's turn-arounds: its lane offset, lateral acceleration and
    longitudinal limits, and PlanDrivingConfig's lock radius, manoeuvre speeds and clearances."""
    return PlanDrivingConfig(
        lateral_accel_mps2=cfg.lateral_accel_mps2,
        accel_mps2=cfg.accel_mps2,
        decel_mps2=cfg.decel_mps2,
        lane_offset_m=cfg.lane_offset_m,
    )


def _intervals(xy: FloatArray, heading: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Lengths [m] and heading change per metre [1/m] of the intervals between samples."""
    ds = np.hypot(*np.diff(xy, axis=0).T)
    return ds, np.diff(heading) / np.maximum(ds, 1e-9)


def _smooth_piece(lane: FloatArray, cruise: FloatArray, cfg: DrivingConfig) -> _Piece:
    """A stretch of the smooth lane path (n, 2) [m] with the cruise speed of its samples."""
    heading = path_heading(lane)
    _, curvature = _intervals(lane, heading)
    cap = speed_cap(curvature, np.minimum(cruise[1:], cruise[:-1]), cfg)
    n = len(lane)
    return _Piece(lane, heading, np.ones(n - 1, np.int64), cap, np.zeros(n, bool), np.zeros(n))


def _node_index(centre: FloatArray, s: FloatArray, node_s: float, node_xy: FloatArray) -> int:
    """Index of the centre-line sample at a node: the nearest one around its arc length."""
    near = np.flatnonzero(np.abs(s - node_s) <= 2.0)
    return int(near[np.argmin(np.hypot(*(centre[near] - node_xy).T))])


def _street_frame(
    smooth: FloatArray, first: int, last: int
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Street coordinates along the smoothed centre line between samples `first` and `last`:
    station (n,) [m], points (n, 2) [m], unwrapped direction (n,) [rad], curvature (n,) [1/m]."""
    _, tangent, _ = polyline_frames(smooth)
    points = smooth[first : last + 1]
    station = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))])
    direction = np.unwrap(np.arctan2(tangent[first : last + 1, 1], tangent[first : last + 1, 0]))
    return station, points, direction, np.gradient(direction, station)


def _turn_around(
    smooth: FloatArray,
    i_node: int,
    half_width_m: float,
    cruise_mps: float,
    cfg: DrivingConfig,
) -> tuple[_Piece, int]:
    """The manoeuvre turning back before centre-line sample `i_node` (a piece in the town
    frame starting on the lane path at sample `i_node - TURN_BEFORE_M / PATH_STEP_M`) and the
    first sample it may not reach (the fold)."""
    pcfg = manoeuvre_config(cfg)
    kind: Literal["u_turn", "three_point"] = (
        "u_turn" if fits_u_turn(half_width_m, pcfg) else "three_point"
    )
    legs = turn_around_legs(kind, half_width_m, cruise_mps, pcfg)
    local = integrate_legs((0.0, -pcfg.lane_offset_m, 0.0), legs, PATH_STEP_M, pcfg.gear_change_s)
    first = i_node - round(TURN_BEFORE_M / PATH_STEP_M)
    last = i_node - smoothing_reach(cfg) - 2  # the last sample the fold does not reach
    too_short = RadarSlamError(
        f"a {kind.replace('_', ' ')} does not fit between the route's start or the fold "
        f"{TURN_BEFORE_M:.0f} m before a reversal: the street is too short"
    )
    if first < 0:
        raise too_short
    station, points, direction, kappa = _street_frame(smooth, first, last)
    x, y, h = local.poses.T
    if x.min() < 0.0 or x.max() > station[-1]:
        raise too_short
    along = np.column_stack([np.interp(x, station, points[:, k]) for k in range(2)])
    theta = np.interp(x, station, direction)
    k_at = np.interp(x, station, kappa)
    xy = along + y[:, None] * np.column_stack([-np.sin(theta), np.cos(theta)])
    # A heading h relative to the street maps to h + (the stretch of the offset curve's station).
    heading = theta + h + wrap_angle(np.arctan2(np.sin(h), (1.0 - k_at * y) * np.cos(h)) - h)
    _, curvature = _intervals(xy, heading)
    cap = speed_cap(curvature, local.speed_limit, replace(cfg, min_speed_mps=0.0))
    logger.debug("reversal at centre sample %d: %s, %d samples", i_node, kind, len(xy))
    return _Piece(xy, heading, local.gear, cap, local.stop, local.dwell_s), first


def _rejoin(lane: FloatArray, end: FloatArray, i_node: int, cfg: DrivingConfig) -> int:
    """Blend the lane path of the way back (in place) so that it passes through a manoeuvre's
    end point `end` (2,) [m] and fades back over REJOIN_BLEND_M; returns that sample's index."""
    reach = smoothing_reach(cfg)
    window = np.arange(i_node + reach + 2, i_node + round(2 * TURN_BEFORE_M / PATH_STEP_M))
    window = window[window < len(lane)]
    if len(window) == 0:
        raise RadarSlamError("the route ends before the way back after a turn-around")
    j = int(window[np.argmin(np.hypot(*(lane[window] - end).T))])
    gap = end - lane[j]
    logger.debug("turn-around rejoins the lane %.3f m off at sample %d", np.hypot(*gap), j)
    if np.hypot(*gap) > MAX_REJOIN_OFFSET_M:
        raise RadarSlamError(
            f"a turn-around ends {np.hypot(*gap):.2f} m off the lane of the way back"
        )
    n = min(round(REJOIN_BLEND_M / PATH_STEP_M), len(lane) - j)
    weight = 0.5 * (1.0 + np.cos(np.pi * np.arange(n) / n))
    lane[j : j + n] += weight[:, None] * gap
    return j


def _join(pieces: list[_Piece]) -> PathSamples:
    """One path from pieces that each start where the previous one ends (that sample is kept
    once); headings unwrapped across the joints."""
    xy, heading = [pieces[0].xy], [pieces[0].heading]
    stop, dwell = [pieces[0].stop], [pieces[0].dwell]
    for piece in pieces[1:]:
        turns = np.round((heading[-1][-1] - piece.heading[0]) / (2 * np.pi))
        xy.append(piece.xy[1:])
        heading.append(piece.heading[1:] + 2 * np.pi * turns)
        stop.append(piece.stop[1:])
        dwell.append(piece.dwell[1:])
    points, yaw = np.concatenate(xy), np.concatenate(heading)
    ds, curvature = _intervals(points, yaw)
    return PathSamples(
        s=np.concatenate([[0.0], np.cumsum(ds)]),
        poses=np.column_stack([points, yaw]),
        gear=np.concatenate([p.gear for p in pieces]),
        curvature=curvature,
        speed_limit=np.concatenate([p.cap for p in pieces]),
        stop=np.concatenate(stop),
        dwell_s=np.concatenate(dwell),
    )


def drive_route(
    town: Town, waypoints: list[tuple[int, int]], cfg: DrivingConfig, rng: np.random.Generator
) -> Trajectory:
    """Drive a lattice route as `route.drive` does (same arguments), turning round at its
    reversals.

    Raises:
        RadarSlamError: a street of a reversal is too short or narrow for a turn-around.
    """
    reversals = reversal_nodes(waypoints)
    if not reversals:
        return drive(town, waypoints, cfg, rng)
    nodes = expand_waypoints(waypoints)
    centre, boundaries = route_centre_line(town, waypoints)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(centre, axis=0).T))])
    cruise = cruise_speeds(s, boundaries, cfg, rng)
    smooth = smoothed_centre_line(centre, cfg)
    lane = offset_polyline(smooth, -cfg.lane_offset_m)  # sample k is centre sample k
    pieces: list[_Piece] = []
    at = 0
    for k in reversals:
        node = town.node_id(*nodes[k])
        i_node = _node_index(centre, s, boundaries[k - 1], town.nodes[node])
        road = town.road_between(town.node_id(*nodes[k - 1]), node)
        assert road is not None  # route_centre_line checked every street
        manoeuvre, start = _turn_around(smooth, i_node, road.half_width_m, cruise[i_node - 1], cfg)
        if start <= at:
            raise RadarSlamError(f"route reversal at node {k} follows the previous one too closely")
        pieces += [_smooth_piece(lane[at : start + 1], cruise[at : start + 1], cfg), manoeuvre]
        at = _rejoin(lane, manoeuvre.xy[-1], i_node, cfg)
    pieces.append(_smooth_piece(lane[at:], cruise[at:], cfg))
    path = _join(pieces)
    cap = path.speed_limit.copy()
    cap[0] = min(cap[0], cfg.min_speed_mps)  # the smooth drive starts at its minimum speed
    return time_parametrise(path, limited_speeds(path, cap, cfg.accel_mps2, cfg.decel_mps2))
