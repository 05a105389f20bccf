"""Named simulation scenarios, deterministic from a seed.

Routes are lattice waypoints (waypoints.py, driven as route.py says); the town is laid out with
every route of the scenario's group protected, so the two sessions of `multisession` share
exactly the same town.

| scenario | what | scans | route |
| --- | --- | --- | --- |
| tiny | 3 x 3 blocks, 1024 bins (61 m): unit tests | 60 | 130 m |
| tiny_loop | a small loop with a revisit, reduced bins (tiny's town), for CI | 177 | 330 m |
| loop | a two-block loop driven twice, same direction (the default) | 939 | 2.6 km |
| reverse | a figure-eight driven, then again the opposite way, lanes 3.5 m apart | 1009 | 2.5 km |
| multisession_a | session A of a town shared with multisession_b | 662 | 1.8 km |
| multisession_b | another route sharing streets; cars, vegetation, traffic changed | 830 | 2.2 km |
| long | three loops, revisits in both directions: benchmarks | 2815 | 7.9 km |
| multisession_reverse_a | a loop around blocks: map session of a reverse pair | 680 | 1.9 km |
| multisession_reverse_b | the same streets the other way, other lane, next day | 697 | 1.9 km |
| tiny_reverse_a, _b | tiny's block one way, then the other way (session 1): CI | 90 | 165 m |
| long_city | a city-length drive, revisits both ways: long-drive benchmark | 10000 | ~24 km |

Driving scenarios (`DRIVING_SCENARIOS`, each also as `tiny_<name>` at 1024 bins for CI):
turn_around, u_turn, three_point_turn, roundabout, stop_and_go, junction_turns, reverse_gear,
roundabouts (six in a row, a tuning scenario for yaw-rate reversals), and the held-out
heldout_town, heldout_mixed, heldout_junctions, heldout_revisits and heldout_fast (`HELD_OUT`:
benchmarks report them separately and nobody tunes on them). All but turn_around drive a plan
(manoeuvres.py): legs of constant curvature joined by steering transitions.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

from radar_slam.errors import RadarSlamError
from radar_slam.sim.driving import PlanDrivingConfig
from radar_slam.sim.manoeuvres import DrivePlan, Reverse, Roundabout, Stop, TurnAround
from radar_slam.sim.physics import PhysicsConfig
from radar_slam.sim.route import DrivingConfig
from radar_slam.sim.sensor import SensorConfig
from radar_slam.sim.town import TownConfig
from radar_slam.sim.waypoints import (
    HELD_OUT_JUNCTIONS_ROUTE,
    HELD_OUT_MIXED_ROUTE,
    HELD_OUT_REVISITS_ROUTE,
    HELD_OUT_TOWN_ROUTE,
    JUNCTION_ROUTE,
    LONG_CITY_ROUTE,
    LONG_ROUTE,
    LOOP_ROUTE,
    MULTI_A,
    MULTI_B,
    REVERSE_GEAR_ROUTE,
    REVERSE_ROUTE,
    REVERSE_SESSION_A,
    REVERSE_SESSION_B,
    ROUNDABOUT_ROUTE,
    ROUNDABOUTS_ROUTE,
    STOP_AND_GO_ROUTE,
    THREE_POINT_ROUTE,
    TINY_BLOCK,
    TINY_LOOP_ROUTE,
    TINY_ROUTE,
    TURN_AROUND_ROUTE,
    U_TURN_ROUTE,
    Waypoints,
)
from radar_slam.sim.world import ObjectConfig
from raplace import NS_PER_S

SIM_VERSION = "1.5"
"""Bump when the output for a given scenario and seed changes (regenerates cached sequences).
1.5: longer blocks (default and held-out towns); the minimum speed yields to a car's grip."""

EPOCH_NS = 1_567_000_000_000_000_000
"""Start of the default scenarios' clocks (late August 2019, like MulRan) [ns]."""
DAY_NS = 86_400 * NS_PER_S
MULRAN_LIKE_ORIGIN = (353_000.0, 4_026_000.0)
"""Offset added to the town frame in global_pose.csv (UTM-like metres, as MulRan's KAIST)."""
TINY_BINS = 1024
"""Range bins of the `tiny` and `tiny_loop` scenarios (61 m at the CIR204-H bin size)."""
_TINY_SENSOR = SensorConfig(n_bins=TINY_BINS)
_TINY_TOWN = TownConfig(n_blocks=(3, 3), block_size_m=(60.0, 90.0))
"""Sensor and town of the `tiny` and `tiny_loop` scenarios."""
TINY_REVERSE_FRAMES = 90
"""Scans of `tiny_reverse_a` and `_b`."""


@dataclass(frozen=True)
class Scenario:
    """A named, seeded simulation.

    Attributes:
        name: scenario (and sequence folder) name.
        description: one line for humans.
        seed: default seed of the town, its contents and the noise.
        waypoints: the ego route (lattice indices).
        town_routes: every route whose streets the town must keep (the group's routes).
        session: session index (parked cars, vegetation, traffic and noise differ per session).
        max_frames: cap on the number of scans (None: as long as the route lasts).
        start_ns: time of the first scan's first column [ns].
        origin_xy: offset of the town frame in the written poses [m].
        sensor, physics, town, objects, driving: configuration sections.
        plan: events and driving of a drive of constant-curvature legs (manoeuvres.py) in a town
            with straight streets; None: the smooth lattice drive of route.py with `driving`.
        held_out: a benchmark scenario nobody tunes on (benchmarks report it separately).
    """

    name: str
    description: str
    seed: int
    waypoints: Waypoints
    town_routes: tuple[Waypoints, ...]
    session: int = 0
    max_frames: int | None = None
    start_ns: int = EPOCH_NS
    origin_xy: tuple[float, float] = MULRAN_LIKE_ORIGIN
    sensor: SensorConfig = field(default_factory=SensorConfig)
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    town: TownConfig = field(default_factory=TownConfig)
    objects: ObjectConfig = field(default_factory=ObjectConfig)
    driving: DrivingConfig = field(default_factory=DrivingConfig)
    plan: DrivePlan | None = None
    held_out: bool = False


LONG_CITY_FRAMES = 10_000

_BASE_SCENARIOS: tuple[Scenario, ...] = (
    Scenario(
        name="tiny",
        description="3 x 3 blocks, 1024 bins (61 m), 60 scans: for unit tests",
        seed=11,
        waypoints=TINY_ROUTE,
        town_routes=(TINY_ROUTE,),
        max_frames=60,
        start_ns=EPOCH_NS + 1 * DAY_NS,
        sensor=_TINY_SENSOR,
        town=_TINY_TOWN,
    ),
    Scenario(
        name="tiny_loop",
        description="a small loop with a revisit, reduced bins (1024, 61 m): for CI",
        seed=11,
        waypoints=TINY_LOOP_ROUTE,
        town_routes=(TINY_LOOP_ROUTE,),
        start_ns=EPOCH_NS + 1 * DAY_NS,
        sensor=_TINY_SENSOR,
        town=_TINY_TOWN,
    ),
    Scenario(
        name="loop",
        description="a two-block loop driven twice in the same direction (~4 min)",
        seed=7,
        waypoints=LOOP_ROUTE,
        town_routes=(LOOP_ROUTE,),
        start_ns=EPOCH_NS + 2 * DAY_NS,
    ),
    Scenario(
        name="reverse",
        description="a figure-eight driven once, then again in the opposite direction in the "
        "other lane (3.5 m offset)",
        seed=5,
        waypoints=REVERSE_ROUTE,
        town_routes=(REVERSE_ROUTE,),
        start_ns=EPOCH_NS + 3 * DAY_NS,
    ),
    Scenario(
        name="multisession_a",
        description="session A of a town shared with multisession_b",
        seed=9,
        waypoints=MULTI_A,
        town_routes=(MULTI_A, MULTI_B),
        session=0,
        start_ns=EPOCH_NS + 4 * DAY_NS,
    ),
    Scenario(
        name="multisession_b",
        description="session B: another route a day later; parked cars, vegetation and "
        "traffic changed",
        seed=9,
        waypoints=MULTI_B,
        town_routes=(MULTI_A, MULTI_B),
        session=1,
        start_ns=EPOCH_NS + 5 * DAY_NS,
    ),
    Scenario(
        name="long",
        description="8 km through a larger town: three loops, revisits in both directions",
        seed=3,
        waypoints=LONG_ROUTE,
        town_routes=(LONG_ROUTE,),
        start_ns=EPOCH_NS + 6 * DAY_NS,
        town=TownConfig(n_blocks=(8, 7)),
    ),
    Scenario(
        name="long_city",
        description="~24 km, 10,000 scans through a 12 x 10 block town, revisits both ways: "
        "the long-drive benchmark (scripts/bench_long.py)",
        seed=13,
        waypoints=LONG_CITY_ROUTE,
        town_routes=(LONG_CITY_ROUTE,),
        max_frames=LONG_CITY_FRAMES,
        start_ns=EPOCH_NS + 30 * DAY_NS,
        town=TownConfig(n_blocks=(12, 10)),
        driving=DrivingConfig(cruise_speed_mps=(8.0, 12.0)),
    ),
)


_MAP_SCENARIOS: tuple[Scenario, ...] = (
    Scenario(  # a reverse-direction session pair for maps
        name="multisession_reverse_a",
        description="the map session of a reverse pair: a loop around town blocks",
        seed=13,
        waypoints=REVERSE_SESSION_A,
        town_routes=(REVERSE_SESSION_A,),
        session=0,
        start_ns=EPOCH_NS + 7 * DAY_NS,
    ),
    Scenario(
        name="multisession_reverse_b",
        description="the same streets the other way round, in the other lane, a day later; "
        "parked cars, vegetation and traffic changed",
        seed=13,
        waypoints=REVERSE_SESSION_B,
        town_routes=(REVERSE_SESSION_A,),
        session=1,
        start_ns=EPOCH_NS + 8 * DAY_NS,
    ),
    Scenario(  # the reverse pair at reduced bins, for CI
        name="tiny_reverse_a",
        description="once around a block of the tiny town, reduced bins: map tests",
        seed=11,
        waypoints=TINY_BLOCK,
        town_routes=(TINY_BLOCK,),
        max_frames=TINY_REVERSE_FRAMES,
        start_ns=EPOCH_NS + 9 * DAY_NS,
        sensor=_TINY_SENSOR,
        town=_TINY_TOWN,
    ),
    Scenario(
        name="tiny_reverse_b",
        description="the same block the other way round, other lane, another session",
        seed=11,
        waypoints=tuple(reversed(TINY_BLOCK)),
        town_routes=(TINY_BLOCK,),
        session=1,
        max_frames=TINY_REVERSE_FRAMES,
        start_ns=EPOCH_NS + 10 * DAY_NS,
        sensor=_TINY_SENSOR,
        town=_TINY_TOWN,
    ),
)
"""Session pairs for maps: a reverse-direction pair and its reduced-bin version."""


def plan_town(**overrides: Any) -> TownConfig:
    """A town with straight streets (plans need them) of 70-110 m blocks, 4 x 3 of them."""
    return TownConfig(
        **{"n_blocks": (4, 3), "block_size_m": (70.0, 110.0), "warp_amplitude_m": 0.0, **overrides}
    )


WIDE_STREETS = {"road_half_width_m": (6.8, 7.6)}
"""Carriageways wide enough for a U-turn at full lock."""
OPEN_JUNCTIONS = {"road_half_width_m": (6.8, 7.6), "sidewalk_m": (3.5, 5.0)}
"""Junctions with room for a roundabout (building lines >= 11 m from the street centre)."""
NARROW_STREETS = {"road_half_width_m": (4.8, 5.4)}
"""Carriageways that need a three-point turn."""
HELD_OUT_BLOCKS = {"block_size_m": TownConfig.block_size_m}
"""The held-out towns' blocks: the default town's long ones (short blocks make places far
easier to tell apart than real streets are, docs/benchmarks.md)."""
_HELD_OUT_TOWN_EVENTS = (
    Stop(2, 10.0),
    Stop(8, 5.0),
    Stop(11, 10.0),
    TurnAround(12, "u_turn", 45.0),
)
"""The stops and U-turn along `HELD_OUT_TOWN_ROUTE` (heldout_town, heldout_fast)."""
_CI = " Reduced bins (1024, 61 m) for CI."
_URBAN_SMOOTH = DrivingConfig(min_speed_mps=3.0, cruise_speed_mps=(9.0, 13.5))
"""The smooth lattice drive at urban speeds (<= 14 m/s), slowing for tight corners."""


DRIVING_SCENARIOS: tuple[Scenario, ...] = (
    Scenario(
        name="turn_around",
        description="out along a street, round a block, back along the same street the other way",
        seed=31,
        waypoints=TURN_AROUND_ROUTE,
        town_routes=(TURN_AROUND_ROUTE,),
        start_ns=EPOCH_NS + 7 * DAY_NS,
        town=TownConfig(n_blocks=(4, 3), block_size_m=(70.0, 110.0)),
        driving=_URBAN_SMOOTH,
    ),
    Scenario(
        name="u_turn",
        description="a U-turn at full lock in a wide street and back along it",
        seed=32,
        waypoints=U_TURN_ROUTE,
        town_routes=(U_TURN_ROUTE,),
        start_ns=EPOCH_NS + 8 * DAY_NS,
        town=plan_town(**WIDE_STREETS),
        plan=DrivePlan(events=(TurnAround(3, "u_turn", 40.0),)),
    ),
    Scenario(
        name="three_point_turn",
        description="a three-point turn (forward, reverse, forward at full lock) in a narrow "
        "street",
        seed=33,
        waypoints=THREE_POINT_ROUTE,
        town_routes=(THREE_POINT_ROUTE,),
        start_ns=EPOCH_NS + 9 * DAY_NS,
        town=plan_town(**NARROW_STREETS),
        plan=DrivePlan(events=(TurnAround(2, "three_point", 35.0),)),
    ),
    Scenario(
        name="roundabout",
        description="into a roundabout, 210 degrees round it at constant yaw rate, out left",
        seed=34,
        waypoints=ROUNDABOUT_ROUTE,
        town_routes=(ROUNDABOUT_ROUTE,),
        start_ns=EPOCH_NS + 10 * DAY_NS,
        town=plan_town(**OPEN_JUNCTIONS),
        plan=DrivePlan(events=(Roundabout(2),)),
    ),
    Scenario(
        name="stop_and_go",
        description="three junction stops (10 s, 3 s, 10 s), braking and accelerating at 3 m/s^2",
        seed=35,
        waypoints=STOP_AND_GO_ROUTE,
        town_routes=(STOP_AND_GO_ROUTE,),
        start_ns=EPOCH_NS + 11 * DAY_NS,
        town=plan_town(),
        plan=DrivePlan(
            events=(Stop(1, 10.0), Stop(2, 3.0), Stop(3, 10.0)),
            driving=PlanDrivingConfig(accel_mps2=3.0, decel_mps2=3.0),
        ),
    ),
    Scenario(
        name="junction_turns",
        description="five sharp 90-degree junction turns, curvature 0 -> 1/R -> 0 within metres, "
        "12-14 m/s between them",
        seed=36,
        waypoints=JUNCTION_ROUTE,
        town_routes=(JUNCTION_ROUTE,),
        start_ns=EPOCH_NS + 12 * DAY_NS,
        town=plan_town(),
        plan=DrivePlan(driving=PlanDrivingConfig(cruise_speed_mps=(12.0, 14.0))),
    ),
    Scenario(
        name="reverse_gear",
        description="stop, reverse 30 m along the street in reverse gear, stop, drive on",
        seed=37,
        waypoints=REVERSE_GEAR_ROUTE,
        town_routes=(REVERSE_GEAR_ROUTE,),
        start_ns=EPOCH_NS + 13 * DAY_NS,
        town=plan_town(),
        plan=DrivePlan(events=(Reverse(1, 60.0, 30.0),)),
    ),
    Scenario(
        name="roundabouts",
        description="six roundabouts in a row (straight on, left, right), at 12-14 m/s between "
        "them: the yaw rate reverses at every entry and exit",
        seed=38,
        waypoints=ROUNDABOUTS_ROUTE,
        town_routes=(ROUNDABOUTS_ROUTE,),
        start_ns=EPOCH_NS + 17 * DAY_NS,
        town=plan_town(**OPEN_JUNCTIONS),
        plan=DrivePlan(
            events=tuple(Roundabout(node) for node in range(1, 7)),
            driving=PlanDrivingConfig(accel_mps2=3.0, cruise_speed_mps=(12.0, 14.0)),
        ),
    ),
    Scenario(
        name="heldout_town",
        description="HELD OUT: 2.5 km through another town: sharp junction turns, a turn back "
        "round a block, three stops, a U-turn",
        seed=41,
        waypoints=HELD_OUT_TOWN_ROUTE,
        town_routes=(HELD_OUT_TOWN_ROUTE,),
        start_ns=EPOCH_NS + 14 * DAY_NS,
        town=plan_town(n_blocks=(5, 5), **HELD_OUT_BLOCKS, **WIDE_STREETS),
        plan=DrivePlan(
            events=_HELD_OUT_TOWN_EVENTS,
            driving=PlanDrivingConfig(cruise_speed_mps=(11.0, 14.0)),
        ),
        held_out=True,
    ),
    Scenario(
        name="heldout_mixed",
        description="HELD OUT: stops, sharp turns, a roundabout, a three-point turn and "
        "reversing in another town",
        seed=42,
        waypoints=HELD_OUT_MIXED_ROUTE,
        town_routes=(HELD_OUT_MIXED_ROUTE,),
        start_ns=EPOCH_NS + 15 * DAY_NS,
        town=plan_town(n_blocks=(5, 4), **HELD_OUT_BLOCKS, **OPEN_JUNCTIONS),
        plan=DrivePlan(
            events=(
                Stop(1, 10.0),
                Roundabout(2),
                Stop(4, 4.0),
                TurnAround(5, "three_point", 30.0),
                Reverse(7, 70.0, 25.0),
                Stop(9, 10.0),
            ),
            driving=PlanDrivingConfig(accel_mps2=3.0),
        ),
        held_out=True,
    ),
    Scenario(
        name="heldout_junctions",
        description="HELD OUT: a junction-dense staircase in a third town, a U-turn, reversing, "
        "two stops",
        seed=43,
        waypoints=HELD_OUT_JUNCTIONS_ROUTE,
        town_routes=(HELD_OUT_JUNCTIONS_ROUTE,),
        start_ns=EPOCH_NS + 16 * DAY_NS,
        town=plan_town(n_blocks=(5, 5), block_size_m=(70.0, 90.0), **WIDE_STREETS),
        plan=DrivePlan(
            events=(
                Stop(2, 6.0),
                TurnAround(7, "u_turn", 35.0),
                Reverse(9, 35.0, 20.0),
                Stop(12, 8.0),
            ),
            driving=PlanDrivingConfig(accel_mps2=2.5, cruise_speed_mps=(10.0, 13.0)),
        ),
        held_out=True,
    ),
    Scenario(
        name="heldout_revisits",
        description="HELD OUT: round a ring of blocks in a fourth town, a U-turn, and back round "
        "it the other way; two stops",
        seed=44,
        waypoints=HELD_OUT_REVISITS_ROUTE,
        town_routes=(HELD_OUT_REVISITS_ROUTE,),
        start_ns=EPOCH_NS + 18 * DAY_NS,
        town=plan_town(n_blocks=(4, 4), **HELD_OUT_BLOCKS, **WIDE_STREETS),
        plan=DrivePlan(
            events=(Stop(3, 8.0), TurnAround(11, "u_turn", 40.0), Stop(15, 6.0)),
            driving=PlanDrivingConfig(accel_mps2=3.0, cruise_speed_mps=(12.0, 14.0)),
        ),
        held_out=True,
    ),
    Scenario(
        name="heldout_fast",
        description="HELD OUT: heldout_town's route in a fifth town at arterial speeds (16-20 "
        "m/s, up to 20 m between scans at 1 Hz)",
        seed=51,
        waypoints=HELD_OUT_TOWN_ROUTE,
        town_routes=(HELD_OUT_TOWN_ROUTE,),
        start_ns=EPOCH_NS + 19 * DAY_NS,
        town=plan_town(n_blocks=(5, 5), **HELD_OUT_BLOCKS, **WIDE_STREETS),
        plan=DrivePlan(
            events=_HELD_OUT_TOWN_EVENTS,
            driving=PlanDrivingConfig(accel_mps2=3.0, cruise_speed_mps=(16.0, 20.0)),
        ),
        held_out=True,
    ),
)
"""Scenarios of urban driving the smooth lattice drive lacks: turning round, gear
changes, roundabouts, stops, sharp turns; and the held-out benchmark scenarios."""


def reduced_bin_versions() -> list[Scenario]:
    """`tiny_<name>`: each driving scenario at 1024 bins (same town, route and seed), for CI."""
    return [
        replace(s, name=f"tiny_{s.name}", description=s.description + _CI, sensor=_TINY_SENSOR)
        for s in DRIVING_SCENARIOS
    ]


SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in (
        *_BASE_SCENARIOS,
        *_MAP_SCENARIOS,
        *DRIVING_SCENARIOS,
        *reduced_bin_versions(),
    )
}
"""Every scenario by name."""
HELD_OUT: tuple[str, ...] = tuple(name for name, s in SCENARIOS.items() if s.held_out)
"""Scenarios reserved for evaluation: report them separately and never tune on them."""

GROUPS: dict[str, tuple[str, ...]] = {
    "multisession": ("multisession_a", "multisession_b"),
    "multisession_reverse": ("multisession_reverse_a", "multisession_reverse_b"),
}
"""Names that stand for several sequences generated together."""

DEFAULT_SCENARIO = "loop"


def get_scenario(name: str) -> Scenario:
    """The scenario called `name`.

    Raises:
        RadarSlamError: unknown name (the message lists the known ones).
    """
    try:
        return SCENARIOS[name]
    except KeyError:
        known = ", ".join(list(SCENARIOS) + list(GROUPS))
        raise RadarSlamError(f"unknown scenario {name!r}; known scenarios: {known}") from None


def expand(name: str) -> list[Scenario]:
    """The scenarios a name stands for: itself, or the members of a group."""
    if name in GROUPS:
        return [get_scenario(member) for member in GROUPS[name]]
    return [get_scenario(name)]
