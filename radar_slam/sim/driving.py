"""Driving made of legs of constant curvature: forward and reverse gear, stops, sharp turns.

The smooth lattice drive of `route.py` turns along Gaussian-smoothed corners at 5-15 m/s and
never stops. This module drives what that cannot: a path made of legs of piecewise-constant
curvature (the moving vehicle steers from one leg's to the next over `STEERING_TRANSITION_M`;
standing, at once), driven in forward or reverse gear (reverse: negative forward speed, the
vehicle heading unchanged), with standing times, a speed profile limited by lateral acceleration
and by longitudinal acceleration and braking (constant acceleration between path samples, exact
in time), and its time parametrisation into the same `Trajectory` as route.py. `manoeuvres.py`
turns a lattice route plus events (stops, roundabouts, U-turns, three-point turns, reversing)
into legs.

Poses are those of the vehicle base (x forward, y left) in the town frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from radar_slam.errors import RadarSlamError
from radar_slam.sim.route import PATH_STEP_M, TIME_STEP_S, Trajectory, limit_acceleration

FloatArray = NDArray[np.float64]

MIN_LEG_M = 1e-6
"""Legs shorter than this are dropped [m]."""
STEERING_TRANSITION_M = 8.0
"""A moving vehicle's curvature changes linearly over this distance [m] centred on a leg boundary
(a clothoid: the steering turned at a steady rate). Its yaw rate then changes about as fast as
the real Edinburgh drive's (IMU) does, where a step would change it by a whole turn's at once."""
LANE_KEEPING_M = 40.0
"""The sideways offset a steering transition leaves is eased out over this distance [m]."""


@dataclass(frozen=True)
class PlanDrivingConfig:
    """How the ego vehicle drives a plan (see manoeuvres.py).

    Attributes:
        cruise_speed_mps: range of the cruise speed drawn per street [m/s] (urban: <= 14).
        lateral_accel_mps2: lateral acceleration limit in turns [m/s^2].
        accel_mps2: longitudinal acceleration limit [m/s^2].
        decel_mps2: braking limit [m/s^2].
        lane_offset_m: lane centre right of the street centre line [m].
        right_turn_radius_m: radius of a 90-degree right turn at a junction (lane centre) [m].
        left_turn_radius_m: radius of a 90-degree left turn at a junction [m].
        lock_radius_m: tightest turning radius of the vehicle (full steering lock) [m].
        lane_change_radius_m: radius of the two opposite arcs of a lateral shift [m].
        manoeuvre_speed_mps: speed limit in U-turns and three-point turns [m/s].
        reverse_speed_mps: speed limit in reverse gear [m/s].
        gear_change_s: standing time when the gear changes [s].
        stop_line_m: a stop before a straight-through junction is this far before its node [m].
        curb_clearance_m: closest approach of the vehicle centre to a curb in manoeuvres [m].
        ring_radius_m: radius of a roundabout's circulating lane (around the node) [m].
        ring_entry_radius_m: radius of the right-hand entry and exit arcs of a roundabout [m].
        ring_speed_mps: speed limit in a roundabout [m/s].
    """

    cruise_speed_mps: tuple[float, float] = (10.0, 14.0)
    lateral_accel_mps2: float = 3.0
    accel_mps2: float = 2.5
    decel_mps2: float = 3.0
    lane_offset_m: float = 1.75
    right_turn_radius_m: float = 8.0
    left_turn_radius_m: float = 12.0
    lock_radius_m: float = 5.5
    lane_change_radius_m: float = 25.0
    manoeuvre_speed_mps: float = 3.0
    reverse_speed_mps: float = 2.5
    gear_change_s: float = 1.5
    stop_line_m: float = 9.0
    curb_clearance_m: float = 1.3
    ring_radius_m: float = 12.0
    ring_entry_radius_m: float = 8.0
    ring_speed_mps: float = 6.0


@dataclass(frozen=True)
class Leg:
    """A piece of path at constant steering curvature and gear.

    Attributes:
        length_m: distance travelled (positive in either gear) [m].
        curvature: steering curvature in the vehicle frame (left positive) [1/m]; the heading
            changes by gear * curvature per metre travelled.
        gear: +1 forward, -1 reverse.
        max_speed_mps: speed limit on the leg (magnitude) [m/s].
        stop_s: standing time at the leg's end [s] (None: no stop unless the gear changes next).
    """

    length_m: float
    curvature: float = 0.0
    gear: int = 1
    max_speed_mps: float = math.inf
    stop_s: float | None = None


def arc(angle_rad: float, radius_m: float, gear: int = 1, max_speed_mps: float = math.inf) -> Leg:
    """A leg turning the heading by `angle_rad` (left positive) on a circle of `radius_m`."""
    curvature = math.copysign(1.0 / radius_m, angle_rad) * gear
    return Leg(abs(angle_rad) * radius_m, curvature, gear, max_speed_mps)


def lane_shift(delta_left_m: float, radius_m: float, max_speed_mps: float = math.inf) -> list[Leg]:
    """Two opposite arcs moving the vehicle sideways by `delta_left_m` (left positive) [m] and
    leaving its heading unchanged; empty for a negligible shift."""
    if abs(delta_left_m) < 1e-3:
        return []
    if abs(delta_left_m) > 2 * radius_m:
        raise RadarSlamError(f"a lateral shift of {delta_left_m:.1f} m needs a larger radius")
    angle = math.acos(1.0 - abs(delta_left_m) / (2 * radius_m))
    sign = math.copysign(1.0, delta_left_m)
    return [
        arc(sign * angle, radius_m, max_speed_mps=max_speed_mps),
        arc(-sign * angle, radius_m, max_speed_mps=max_speed_mps),
    ]


def along_leg(
    start: tuple[float, float, float], leg: Leg, distance_m: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """x [m], y [m] and heading [rad] (each like `distance_m`) after travelling `distance_m`
    along `leg` from `start` (x, y, heading): constant-curvature kinematics in closed form."""
    x0, y0, h0 = start
    u = np.asarray(distance_m, dtype=np.float64)
    h = h0 + leg.gear * leg.curvature * u
    if abs(leg.curvature) < 1e-12:
        return x0 + leg.gear * u * math.cos(h0), y0 + leg.gear * u * math.sin(h0), h
    x = x0 + (np.sin(h) - math.sin(h0)) / leg.curvature
    y = y0 - (np.cos(h) - math.cos(h0)) / leg.curvature
    return x, y, h


@dataclass(frozen=True)
class PathSamples:
    """A path sampled every ~PATH_STEP_M of distance travelled.

    Attributes:
        s: (K,) distance travelled [m].
        poses: (K, 3) base poses x [m], y [m], heading [rad, unwrapped].
        gear: (K - 1,) gear of each interval between samples.
        curvature: (K - 1,) heading change per metre travelled of each interval [1/m].
        speed_limit: (K - 1,) speed limit of each interval [m/s].
        stop: (K,) the vehicle stands (speed zero) at the sample.
        dwell_s: (K,) standing time at each sample [s].
    """

    s: FloatArray
    poses: FloatArray
    gear: NDArray[np.int64]
    curvature: FloatArray
    speed_limit: FloatArray
    stop: NDArray[np.bool_]
    dwell_s: FloatArray


def integrate_legs(
    start: tuple[float, float, float], legs: list[Leg], step_m: float, gear_change_s: float
) -> PathSamples:
    """Sample the path of `legs` driven from `start` (x [m], y [m], heading [rad]) every
    ~`step_m` [m].

    Constant-curvature kinematics in closed form, so arcs and straights are exact and the
    curvature steps at leg boundaries (`steered` spreads the steps). The vehicle stops at the end
    of a leg with `stop_s` and before every gear change (standing at least `gear_change_s` [s]
    there).
    """
    legs = [leg for leg in legs if leg.length_m > MIN_LEG_M]
    if not legs:
        raise RadarSlamError("a driving plan needs at least one leg")
    xs, ys, hs, s_all = [start[0]], [start[1]], [start[2]], [0.0]
    gear, curv, limit = [], [], []
    dwell, stop = [0.0], [False]
    for k, leg in enumerate(legs):
        if leg.gear not in (1, -1):
            raise RadarSlamError(f"leg gear must be +1 or -1, got {leg.gear}")
        n = max(1, int(math.ceil(leg.length_m / step_m)))
        u = np.linspace(0.0, leg.length_m, n + 1)[1:]
        x, y, h = along_leg((xs[-1], ys[-1], hs[-1]), leg, u)
        rate = leg.gear * leg.curvature  # heading change per metre travelled
        xs.extend(x.tolist())
        ys.extend(y.tolist())
        hs.extend(h.tolist())
        s_all.extend((s_all[-1] + u).tolist())
        gear.extend([leg.gear] * n)
        curv.extend([rate] * n)
        limit.extend([leg.max_speed_mps] * n)
        dwell.extend([0.0] * n)
        stop.extend([False] * n)
        changes_gear = k + 1 < len(legs) and legs[k + 1].gear != leg.gear
        if leg.stop_s is not None or changes_gear:
            stop[-1] = True
            dwell[-1] = max(leg.stop_s or 0.0, gear_change_s if changes_gear else 0.0)
    return PathSamples(
        s=np.array(s_all),
        poses=np.column_stack([xs, ys, hs]),
        gear=np.array(gear, dtype=np.int64),
        curvature=np.array(curv),
        speed_limit=np.array(limit),
        stop=np.array(stop, dtype=bool),
        dwell_s=np.array(dwell),
    )


def running_mean(values: FloatArray, width: int) -> FloatArray:
    """(n,) mean of `width` neighbouring `values` (n,) around each one, the ends repeated."""
    padded = np.pad(values, (width // 2, width - 1 - width // 2), "edge")
    return np.convolve(padded, np.ones(width) / width, "valid")


def steered(path: PathSamples, transition_m: float) -> PathSamples:
    """`path` with each curvature step between two stops spread linearly over `transition_m` [m]
    (a moving average of the heading change per metre: every turn keeps its heading change; at a
    stop the steering may turn standing), its poses integrated again; the sideways offset this
    leaves after a turn (a few cm) is eased out over `LANE_KEEPING_M`."""
    ds = np.diff(path.s)
    step = float(np.median(ds))
    width = int(round(transition_m / step))
    if width < 2:
        return path
    curvature = path.curvature.copy()
    stops = np.flatnonzero(path.stop[1:-1]) + 1  # intervals split at standing samples
    for a, b in zip(np.r_[0, stops], np.r_[stops, len(ds)], strict=True):
        curvature[a:b] = running_mean(path.curvature[a:b], width)
    turn = curvature * ds
    heading = path.poses[0, 2] + np.concatenate([[0.0], np.cumsum(turn)])
    chord = path.gear * ds * np.sinc(turn / (2.0 * np.pi))  # exact on each constant-rate piece
    along = np.column_stack([np.cos(heading[:-1] + 0.5 * turn), np.sin(heading[:-1] + 0.5 * turn)])
    xy = path.poses[0, :2] + np.concatenate([[[0.0, 0.0]], np.cumsum(chord[:, None] * along, 0)])
    keep = int(round(LANE_KEEPING_M / step)) | 1
    offset = xy - path.poses[:, :2]
    eased = np.column_stack([running_mean(offset[:, k], keep) for k in range(2)])
    moved = np.hypot(*np.diff(xy - eased, axis=0).T)
    ds *= moved / np.hypot(*np.diff(xy, axis=0).T)  # the distance the easing adds or removes
    xy -= eased
    s = np.concatenate([[0.0], np.cumsum(ds)])
    curvature = np.diff(heading) / ds
    return replace(path, s=s, poses=np.column_stack([xy, heading]), curvature=curvature)


def speed_profile(path: PathSamples, cfg: PlanDrivingConfig) -> FloatArray:
    """Speed magnitude (K,) at each sample [m/s]: interval limits (cruise, lateral
    acceleration), zero at stops, then acceleration and braking limits in both directions."""
    if not np.all(np.isfinite(path.speed_limit)):
        raise RadarSlamError("every leg of a driving plan needs a finite speed limit")
    turn = np.sqrt(cfg.lateral_accel_mps2 / np.maximum(np.abs(path.curvature), 1e-9))
    return limited_speeds(path, np.minimum(path.speed_limit, turn), cfg.accel_mps2, cfg.decel_mps2)


def limited_speeds(
    path: PathSamples, interval_cap: FloatArray, accel_mps2: float, decel_mps2: float
) -> FloatArray:
    """Speed magnitude (K,) at each sample of `path` [m/s]: the caps of the intervals on either
    side (`interval_cap` (K - 1,) [m/s]), zero at stops, then acceleration and braking limits
    [m/s^2] in both directions."""
    v = np.minimum(np.append(interval_cap, np.inf), np.insert(interval_cap, 0, np.inf))
    v[path.stop] = 0.0
    limit_acceleration(v, np.diff(path.s), accel_mps2, decel_mps2)
    return v


def time_parametrise(path: PathSamples, speed: FloatArray) -> Trajectory:
    """Base poses every TIME_STEP_S along `path` driven at `speed` (K,) [m/s], standing
    `path.dwell_s` at stops; constant acceleration between samples (exact distance in time)."""
    ds = np.diff(path.s)
    mean = 0.5 * (speed[1:] + speed[:-1])
    if np.any(mean <= 0.0):
        raise RadarSlamError("a driving plan stops twice within one path sample")
    dt = ds / mean
    accel = (speed[1:] ** 2 - speed[:-1] ** 2) / (2 * ds)
    dwell = path.dwell_s
    arrive = np.concatenate([[0.0], np.cumsum(dt + dwell[:-1])])
    depart = arrive + dwell
    t_grid = np.arange(0.0, depart[-1], TIME_STEP_S)
    k = np.clip(np.searchsorted(depart, t_grid, side="right") - 1, 0, len(ds) - 1)
    tau = np.clip(t_grid - depart[k], 0.0, dt[k])
    s = path.s[k] + speed[k] * tau + 0.5 * accel[k] * tau**2
    s = np.minimum(s, path.s[k + 1])
    poses = np.stack([np.interp(s, path.s, path.poses[:, j]) for j in range(3)], axis=1)
    return Trajectory(t_s=t_grid, poses=poses, length_m=float(path.s[-1]))


def drive_legs(
    start: tuple[float, float, float], legs: list[Leg], cfg: PlanDrivingConfig
) -> Trajectory:
    """The trajectory of `legs` driven from `start` (x [m], y [m], heading [rad])."""
    path = steered(
        integrate_legs(start, legs, PATH_STEP_M, cfg.gear_change_s), STEERING_TRANSITION_M
    )
    return time_parametrise(path, speed_profile(path, cfg))
