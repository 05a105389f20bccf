"""Driving plans: a lattice route plus events, turned into legs of constant curvature.

A plan drives a lattice route (see route.py) through a town with straight streets (a town laid
out with `warp_amplitude_m = 0`: streets are exact straight lines between their nodes, so every
lane and junction is exact geometry) in the right-hand lane. At a junction the route turns on a
circular arc tangent to both lanes, entered and left while steering (driving.py's transitions).
Events add what real urban driving has and the smooth drive of route.py has not:

- `Stop`: stand still before a junction (a stop line or a red light), e.g. 10 s.
- `Roundabout`: drive the turn at a junction through a roundabout centred on its node (right-hand
  entry arc, anticlockwise circulation at constant yaw rate, right-hand exit arc); the town gets
  a central island (curb ring, vegetation, a sign post).
- `TurnAround`: where the route goes back along the street it came (a 180-degree turn at a node),
  turn round before the node with a U-turn (wide streets) or a three-point turn (forward, reverse,
  forward on full lock; narrow streets).
- `Reverse`: stop on a street, reverse in gear along it, stop, drive on.

Node indices count the route's expanded lattice nodes (`route.expand_waypoints`); street k joins
node k and node k + 1. Stations along a street are metres from its first node.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from radar_slam.errors import RadarSlamError
from radar_slam.sim.driving import (
    Leg,
    PlanDrivingConfig,
    along_leg,
    arc,
    drive_legs,
    lane_shift,
)
from radar_slam.sim.route import Trajectory, expand_waypoints
from radar_slam.sim.town import FEATURE_STEP_M, FREE, Town
from raplace import wrap_angle

FloatArray = NDArray[np.float64]

STRAIGHT_STREET_TOLERANCE_M = 0.3
"""Largest distance of a planned street's centre line from the straight chord [m]."""
MANOEUVRE_STOP_S = 1.0
"""Standing time before a three-point turn starts [s]."""
ISLAND_CURB_INSET_M = 3.0
"""A roundabout island's curb lies this far inside the circulating lane's centre [m]."""
ISLAND_VEGETATION_INSET_M = 5.0
"""Its vegetation fills the disc this far inside the circulating lane's centre [m]."""
STRAIGHT_THROUGH_RAD = math.radians(5.0)
"""Turns smaller than this at a node are driven straight through."""


@dataclass(frozen=True)
class Stop:
    """Stand still before node `node` for `seconds` [s]."""

    node: int
    seconds: float = 10.0


@dataclass(frozen=True)
class Roundabout:
    """Drive the turn at node `node` through a roundabout centred on the node."""

    node: int


@dataclass(frozen=True)
class TurnAround:
    """Turn round `before_m` [m] before node `node`, where the route goes back the way it came.

    Attributes:
        node: the node the route turns back at (it is not reached).
        kind: "u_turn" (one forward arc at full lock; needs a wide street) or "three_point"
            (forward, reverse, forward at full lock).
        before_m: where the manoeuvre starts, before the node [m].
    """

    node: int
    kind: Literal["u_turn", "three_point"]
    before_m: float = 40.0


@dataclass(frozen=True)
class Reverse:
    """On street `street`, stop at station `at_m` [m], reverse `length_m` [m], drive on."""

    street: int
    at_m: float
    length_m: float


Event = Stop | Roundabout | TurnAround | Reverse


@dataclass(frozen=True)
class DrivePlan:
    """Events along a scenario's route and how the vehicle drives it."""

    events: tuple[Event, ...] = ()
    driving: PlanDrivingConfig = field(default_factory=PlanDrivingConfig)


@dataclass(frozen=True)
class _Street:
    start: FloatArray  # (2,) first node [m]
    direction: FloatArray  # (2,) unit vector
    length_m: float
    half_width_m: float
    cruise_mps: float

    @property
    def heading(self) -> float:
        return math.atan2(self.direction[1], self.direction[0])


def _streets(town: Town, nodes: list[tuple[int, int]], cruise: FloatArray) -> list[_Street]:
    streets = []
    for k, (a, b) in enumerate(zip(nodes[:-1], nodes[1:], strict=True)):
        ia, ib = town.node_id(*a), town.node_id(*b)
        road = town.road_between(ia, ib)
        if road is None:
            raise RadarSlamError(f"no street between nodes {a} and {b}: protect the route's edges")
        p0, p1 = town.nodes[ia], town.nodes[ib]
        chord = p1 - p0
        length = float(np.hypot(*chord))
        normal = np.array([-chord[1], chord[0]]) / length
        if np.abs((road.polyline - p0) @ normal).max() > STRAIGHT_STREET_TOLERANCE_M:
            raise RadarSlamError(
                f"street {a}-{b} is not straight: plans need a town with warp_amplitude_m = 0"
            )
        streets.append(_Street(p0, chord / length, length, road.half_width_m, float(cruise[k])))
    return streets


def turn_around_legs(
    kind: Literal["u_turn", "three_point"],
    half_width_m: float,
    cruise_mps: float,
    cfg: PlanDrivingConfig,
) -> list[Leg]:
    """Legs of a turn-around from the right lane of a straight street with a carriageway
    `half_width_m` [m] wide either side of its centre line into the opposite lane, starting at
    (0, -lane offset) heading along +x (street frame: x along it, y left) and ending heading
    back at (x_end, +lane offset); `cruise_mps` [m/s] caps the lane changes before and after.

    Raises:
        RadarSlamError: the street is too narrow for the manoeuvre.
    """
    if kind == "u_turn":
        return _u_turn(half_width_m, cruise_mps, cfg)
    return _three_point_turn(half_width_m, cruise_mps, cfg)


def fits_u_turn(half_width_m: float, cfg: PlanDrivingConfig) -> bool:
    """A U-turn at full lock fits a carriageway `half_width_m` [m] wide either side."""
    return cfg.lock_radius_m <= half_width_m - cfg.curb_clearance_m


def _u_turn(half_width_m: float, cruise: float, cfg: PlanDrivingConfig) -> list[Leg]:
    """U-turn from the right lane into the opposite one: swing out, a half circle at full lock
    centred on the street's centre line, swing in."""
    radius, off = cfg.lock_radius_m, cfg.lane_offset_m
    if not fits_u_turn(half_width_m, cfg):
        raise RadarSlamError(
            f"a street {2 * half_width_m:.1f} m wide is too narrow for a U-turn on a "
            f"{radius:.1f} m radius: use a three-point turn"
        )
    shift_r = 2 * cfg.lock_radius_m
    return [
        *lane_shift(-(radius - off), shift_r, cruise),
        arc(math.pi, radius, max_speed_mps=cfg.manoeuvre_speed_mps),
        *lane_shift(radius - off, shift_r, cruise),
    ]


def _three_point_turn(half_width_m: float, cruise: float, cfg: PlanDrivingConfig) -> list[Leg]:
    """Three-point turn: pull over to the curb and stop, forward on left lock (up to straight
    across the street), reverse on right lock, forward on left lock, into the opposite lane."""
    radius, off, speed = cfg.lock_radius_m, cfg.lane_offset_m, cfg.manoeuvre_speed_mps
    edge = half_width_m - cfg.curb_clearance_m
    a1 = min(math.pi / 2, math.acos(max(-1.0, 1.0 - 2 * edge / radius)))
    a2 = a3 = (math.pi - a1) / 2
    y1 = -edge + radius * (1 - math.cos(a1))
    y2 = y1 + radius * (math.cos(a1 + a2) - math.cos(a1))
    y3 = y2 + radius * (math.cos(a1 + a2) + 1)
    if max(abs(y1), abs(y2), abs(y3)) > edge + 1e-6:
        raise RadarSlamError(f"a three-point turn does not fit a {2 * half_width_m} m street")
    pull_over = lane_shift(-(edge - off), 2 * radius, cruise)
    if pull_over:
        pull_over[-1] = replace(pull_over[-1], stop_s=MANOEUVRE_STOP_S)
    return [
        *pull_over,
        arc(a1, radius, max_speed_mps=speed),
        arc(a2, radius, gear=-1, max_speed_mps=min(speed, cfg.reverse_speed_mps)),
        arc(a3, radius, max_speed_mps=speed),
        *lane_shift(y3 - off, 2 * radius, cruise),
    ]


def local_end(legs: list[Leg], cfg: PlanDrivingConfig) -> tuple[float, float, float]:
    """End pose of `legs` driven from (0, -lane offset, 0): longitudinal, lateral, heading."""
    pose = (0.0, -cfg.lane_offset_m, 0.0)
    for leg in legs:
        x, y, h = along_leg(pose, leg, np.array([leg.length_m]))
        pose = (float(x[0]), float(y[0]), float(h[0]))
    return pose


def _roundabout(turn: float, speed: float, cfg: PlanDrivingConfig) -> tuple[list[Leg], float]:
    """Legs through a roundabout turning the heading by `turn` [rad] (mod 2 pi), and the
    distance of the entry (and exit) tangent point from the node along the lane [m]."""
    rr, re, off = cfg.ring_radius_m, cfg.ring_entry_radius_m, cfg.lane_offset_m
    # Entry arc (right turn) tangent to the lane y = -off and externally tangent to the ring.
    centre = np.array([-math.sqrt((rr + re) ** 2 - (off + re) ** 2), -off - re])
    beta = float(wrap_angle(math.atan2(centre[1], centre[0]) + math.pi / 2))  # < 0
    sweep = float((turn - 2 * beta) % (2 * math.pi))
    ring_speed = min(speed, cfg.ring_speed_mps)
    legs = [
        arc(beta, re, max_speed_mps=ring_speed),
        arc(sweep, rr, max_speed_mps=ring_speed),
        arc(beta, re, max_speed_mps=ring_speed),
    ]
    return legs, float(-centre[0])


def _junction(
    k: int, streets: list[_Street], events: dict[int, list[Event]], cfg: PlanDrivingConfig
) -> tuple[float, list[Leg], float]:
    """At node k + 1 (street k to street k + 1): the station where street k's straight ends,
    the legs of the turn, and the station where street k + 1's straight starts."""
    here, nxt = streets[k], streets[k + 1]
    turn = float(wrap_angle(nxt.heading - here.heading))
    at_node = events.get(k + 1, [])
    speed = min(here.cruise_mps, nxt.cruise_mps)
    if any(isinstance(e, Roundabout) for e in at_node):
        legs, reach = _roundabout(turn, speed, cfg)
        return here.length_m - reach, legs, reach
    turn_around = [e for e in at_node if isinstance(e, TurnAround)]
    if abs(abs(turn) - math.pi) < 1e-6:
        if not turn_around:
            raise RadarSlamError(f"the route turns back at node {k + 1}: add a TurnAround event")
        event = turn_around[0]
        legs = turn_around_legs(event.kind, here.half_width_m, here.cruise_mps, cfg)
        x_end, y_end, h_end = local_end(legs, cfg)
        assert abs(y_end - cfg.lane_offset_m) < 1e-6 and abs(h_end - math.pi) < 1e-6
        return here.length_m - event.before_m, legs, event.before_m - x_end
    if abs(turn) < STRAIGHT_THROUGH_RAD:
        return here.length_m, [], 0.0
    radius = cfg.left_turn_radius_m if turn > 0 else cfg.right_turn_radius_m
    tangent = radius * math.tan(abs(turn) / 2)
    cross = cfg.lane_offset_m * math.tan(turn / 2)
    legs = [arc(turn, radius, max_speed_mps=speed)]
    return here.length_m + cross - tangent, legs, -cross + tangent


def _straight(
    k: int,
    street: _Street,
    t0: float,
    t1: float,
    events: dict[int, list[Event]],
    reverses: list[Reverse],
    turns: bool,
    cfg: PlanDrivingConfig,
) -> list[Leg]:
    """Legs along street k from station t0 to t1 [m]: reversing stretches and a stop."""
    if t1 < t0 - 1e-6:
        raise RadarSlamError(f"street {k} is too short for the turns and manoeuvres at its ends")
    legs: list[Leg] = []
    at = t0
    for event in sorted(reverses, key=lambda e: e.at_m):
        if not (at <= event.at_m - event.length_m and event.at_m <= t1):
            raise RadarSlamError(
                f"reversing on street {k} leaves the straight [{t0:.0f}, {t1:.0f}] m"
            )
        legs.append(Leg(event.at_m - at, max_speed_mps=street.cruise_mps))
        legs.append(Leg(event.length_m, gear=-1, max_speed_mps=cfg.reverse_speed_mps))
        at = event.at_m - event.length_m
    stops = [e for e in events.get(k + 1, []) if isinstance(e, Stop)]
    if stops:
        stop_at = t1 if turns else min(t1, street.length_m - cfg.stop_line_m)
        legs.append(Leg(stop_at - at, max_speed_mps=street.cruise_mps, stop_s=stops[0].seconds))
        at = stop_at
    legs.append(Leg(t1 - at, max_speed_mps=street.cruise_mps))
    return legs


def plan_legs(
    town: Town, waypoints: list[tuple[int, int]], plan: DrivePlan, rng: np.random.Generator
) -> tuple[tuple[float, float, float], list[Leg]]:
    """Start pose (x [m], y [m], heading [rad]) in the middle of the route's first street (right
    lane) and the legs that drive the plan to the middle of its last street.

    Raises:
        RadarSlamError: a street is missing, curved or too short, or a turn back has no event.
    """
    cfg = plan.driving
    nodes = expand_waypoints(waypoints)
    streets = _streets(town, nodes, rng.uniform(*cfg.cruise_speed_mps, len(nodes) - 1))
    events: dict[int, list[Event]] = {}
    reverses: dict[int, list[Reverse]] = {}
    for event in plan.events:
        if isinstance(event, Reverse):
            reverses.setdefault(event.street, []).append(event)
        else:
            events.setdefault(event.node, []).append(event)
    first = streets[0]
    t = first.length_m / 2
    xy = (
        first.start
        + t * first.direction
        + cfg.lane_offset_m * np.array([first.direction[1], -first.direction[0]])
    )
    legs: list[Leg] = []
    for k, street in enumerate(streets):
        if k + 1 < len(streets):
            t_end, turn_legs, t_next = _junction(k, streets, events, cfg)
        else:
            t_end, turn_legs, t_next = street.length_m / 2, [], 0.0
        legs += _straight(k, street, t, t_end, events, reverses.get(k, []), bool(turn_legs), cfg)
        legs += turn_legs
        t = t_next
    return (float(xy[0]), float(xy[1]), first.heading), legs


def drive_plan(
    town: Town, waypoints: list[tuple[int, int]], plan: DrivePlan, rng: np.random.Generator
) -> Trajectory:
    """Drive a plan: legs of constant curvature through the town, speeds, stops, base poses."""
    start, legs = plan_legs(town, waypoints, plan, rng)
    return drive_legs(start, legs, plan.driving)


def with_roundabout_islands(town: Town, waypoints: list[tuple[int, int]], plan: DrivePlan) -> Town:
    """The town with a central island (curb ring, vegetation, sign post) at every roundabout
    of the plan; the town itself is not changed."""
    nodes = expand_waypoints(waypoints)
    centres = np.array(
        [town.nodes[town.node_id(*nodes[e.node])] for e in plan.events if isinstance(e, Roundabout)]
    )
    if len(centres) == 0:
        return town
    ring = plan.driving.ring_radius_m
    curb_r, veg_r = ring - ISLAND_CURB_INSET_M, ring - ISLAND_VEGETATION_INSET_M
    angles = np.arange(0.0, 2 * np.pi, FEATURE_STEP_M / curb_r)
    outward = np.column_stack([np.cos(angles), np.sin(angles)])
    curbs = [np.hstack([c + curb_r * outward, outward]) for c in centres]
    raster = replace(town.raster, classes=town.raster.classes.copy())
    for c in centres:
        px = raster.to_pixel_polygon(c[None, :])[0]
        cv2.circle(raster.classes, (int(px[0]), int(px[1])), int(curb_r / raster.cell_m), FREE, -1)
    parks = np.array([[c[0], c[1], veg_r, veg_r, 0.0] for c in centres])
    return replace(
        town,
        curbs=np.concatenate([town.curbs, *curbs]),
        poles=np.concatenate([town.poles, centres]),
        parks=np.concatenate([town.parks, parks]),
        raster=raster,
        _node_ids=dict(town._node_ids),
    )
