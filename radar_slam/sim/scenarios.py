"""Named simulation scenarios, deterministic from a seed.

Routes are lattice waypoints (see route.py); the town is laid out with every route of the
scenario's group protected, so the two sessions of `multisession` share exactly the same town.

| scenario | what | scans | route |
| --- | --- | --- | --- |
| tiny | 3 x 3 blocks, 1024 bins (61 m): unit tests | 60 | 130 m |
| tiny_loop | a small loop with a revisit, reduced bins (tiny's town), for CI | 177 | 330 m |
| loop | a two-block loop driven twice, same direction (the default) | 557 | 1.35 km |
| reverse | a figure-eight driven, then again the opposite way, lanes 3.5 m apart | 617 | 1.3 km |
| multisession_a | session A of a town shared with multisession_b | 351 | 0.9 km |
| multisession_b | another route sharing streets; cars, vegetation, traffic changed | 522 | 1.2 km |
| long | three loops, revisits in both directions: benchmarks | 1588 | 4.2 km |
| long_city | a city-length drive, revisits both ways: long-drive benchmark | 10000 | ~24 km |
"""

from __future__ import annotations

from dataclasses import dataclass, field

from radar_slam.errors import RadarSlamError
from radar_slam.sim.physics import PhysicsConfig
from radar_slam.sim.route import DrivingConfig
from radar_slam.sim.sensor import SensorConfig
from radar_slam.sim.town import TownConfig
from radar_slam.sim.world import ObjectConfig

Waypoints = tuple[tuple[int, int], ...]

EPOCH_NS = 1_567_000_000_000_000_000
"""Start of the default scenarios' clocks (late August 2019, like MulRan) [ns]."""
DAY_NS = 86_400 * 1_000_000_000
MULRAN_LIKE_ORIGIN = (353_000.0, 4_026_000.0)
"""Offset added to the town frame in global_pose.csv (UTM-like metres, as MulRan's KAIST)."""
TINY_BINS = 1024
"""Range bins of the `tiny` and `tiny_loop` scenarios (61 m at the CIR204-H bin size)."""
_TINY_SENSOR = SensorConfig(n_bins=TINY_BINS)
_TINY_TOWN = TownConfig(n_blocks=(3, 3), block_size_m=(60.0, 90.0))
"""Sensor and town of the `tiny` and `tiny_loop` scenarios."""


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


_TINY_ROUTE: Waypoints = ((1, 1), (2, 1), (2, 2), (1, 2))
_LOOP_ROUTE: Waypoints = (
    (2, 2),
    (4, 2),
    (4, 3),
    (2, 3),
    (2, 2),
    (4, 2),
    (4, 3),
    (2, 3),
    (2, 2),
    (3, 2),
)
_TINY_LOOP_ROUTE: Waypoints = ((1, 1), (2, 1), (2, 2), (1, 2), (1, 1), (2, 1), (2, 2))
"""Around one block of the tiny town and on along one and a half of its streets again."""
_REVERSE_CROSSING = (5, 2)
"""Where the figure-eight of `reverse` crosses itself (lattice node)."""
_REVERSE_ROUTE: Waypoints = (
    # Lap 1: the block on the crossing's (+i, +j) side anticlockwise, straight over the
    # crossing, the block on its (-i, -j) side clockwise.
    _REVERSE_CROSSING,
    (6, 2),
    (6, 3),
    (5, 3),
    (5, 1),
    (4, 1),
    (4, 2),
    _REVERSE_CROSSING,
    # Lap 2 (a left turn at the crossing): the same figure-eight in the opposite direction.
    (5, 3),
    (6, 3),
    (6, 2),
    (4, 2),
    (4, 1),
    (5, 1),
    _REVERSE_CROSSING,
)
"""A closed circuit (a figure-eight over two diagonal blocks) driven once, then again in the
opposite direction: every street of it is revisited the other way, in the other lane. The
crossing turns the route around with an ordinary turn (no U-turn), and every corner is driven
once as a left and once as a right turn."""
_MULTI_A: Waypoints = ((1, 1), (3, 1), (3, 3), (1, 3), (1, 1), (2, 1))
_MULTI_B: Waypoints = (
    (4, 4),
    (4, 2),
    (3, 2),
    (3, 3),
    (1, 3),
    (1, 2),
    (2, 2),
    (2, 4),
    (4, 4),
    (4, 3),
)
_LONG_ROUTE: Waypoints = (
    (1, 1),
    (4, 1),
    (4, 3),
    (1, 3),
    (1, 1),
    (4, 1),
    (7, 1),
    (7, 4),
    (4, 4),
    (4, 1),
    (1, 1),
    (1, 3),
    (4, 3),
    (4, 5),
    (1, 5),
    (1, 3),
    (2, 3),
)

_CITY_RING: Waypoints = ((1, 1), (11, 1), (11, 9), (1, 9), (1, 1))
"""The outer ring of the `long_city` town (12 x 10 blocks), anticlockwise: 3.9 km."""
_LONG_CITY_ROUTE: Waypoints = (
    *_CITY_RING,
    # A serpentine across the town along x, ending in the far corner.
    (1, 3),
    (11, 3),
    (11, 5),
    (1, 5),
    (1, 7),
    (11, 7),
    (11, 9),
    # The ring again, clockwise (every ring street revisited the other way).
    (11, 1),
    (1, 1),
    (1, 9),
    (11, 9),
    # A serpentine along y, crossing the first one at every street.
    (9, 9),
    (9, 1),
    (7, 1),
    (7, 9),
    (5, 9),
    (5, 1),
    (3, 1),
    (3, 9),
    (1, 9),
    # The x serpentine back the other way, then the ring anticlockwise once more.
    (1, 7),
    (11, 7),
    (11, 5),
    (1, 5),
    (1, 3),
    (11, 3),
    (11, 1),
    *_CITY_RING,
)
"""About 26 km of streets through a 12 x 10 block town (the first 10,000 scans, ~24 km, are
driven at 8-12 m/s): three laps of the ring (two directions) and two
serpentines crossing each other and the ring, so most streets are revisited, some in reverse."""
LONG_CITY_FRAMES = 10_000

SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in (
        Scenario(
            name="tiny",
            description="3 x 3 blocks, 1024 bins (61 m), 60 scans: for unit tests",
            seed=11,
            waypoints=_TINY_ROUTE,
            town_routes=(_TINY_ROUTE,),
            max_frames=60,
            start_ns=EPOCH_NS + 1 * DAY_NS,
            sensor=_TINY_SENSOR,
            town=_TINY_TOWN,
        ),
        Scenario(
            name="tiny_loop",
            description="a small loop with a revisit, reduced bins (1024, 61 m): for CI",
            seed=11,
            waypoints=_TINY_LOOP_ROUTE,
            town_routes=(_TINY_LOOP_ROUTE,),
            start_ns=EPOCH_NS + 1 * DAY_NS,
            sensor=_TINY_SENSOR,
            town=_TINY_TOWN,
        ),
        Scenario(
            name="loop",
            description="a two-block loop driven twice in the same direction (~2 min)",
            seed=7,
            waypoints=_LOOP_ROUTE,
            town_routes=(_LOOP_ROUTE,),
            start_ns=EPOCH_NS + 2 * DAY_NS,
        ),
        Scenario(
            name="reverse",
            description="a figure-eight driven once, then again in the opposite direction in the "
            "other lane (3.5 m offset)",
            seed=5,
            waypoints=_REVERSE_ROUTE,
            town_routes=(_REVERSE_ROUTE,),
            start_ns=EPOCH_NS + 3 * DAY_NS,
        ),
        Scenario(
            name="multisession_a",
            description="session A of a town shared with multisession_b",
            seed=9,
            waypoints=_MULTI_A,
            town_routes=(_MULTI_A, _MULTI_B),
            session=0,
            start_ns=EPOCH_NS + 4 * DAY_NS,
        ),
        Scenario(
            name="multisession_b",
            description="session B: another route a day later; parked cars, vegetation and "
            "traffic changed",
            seed=9,
            waypoints=_MULTI_B,
            town_routes=(_MULTI_A, _MULTI_B),
            session=1,
            start_ns=EPOCH_NS + 5 * DAY_NS,
        ),
        Scenario(
            name="long",
            description="4.5 km through a larger town: three loops, revisits in both directions",
            seed=3,
            waypoints=_LONG_ROUTE,
            town_routes=(_LONG_ROUTE,),
            start_ns=EPOCH_NS + 6 * DAY_NS,
            town=TownConfig(n_blocks=(8, 7)),
        ),
        Scenario(
            name="long_city",
            description="~24 km, 10,000 scans through a 12 x 10 block town, revisits both ways: "
            "the long-drive benchmark (scripts/bench_long.py)",
            seed=13,
            waypoints=_LONG_CITY_ROUTE,
            town_routes=(_LONG_CITY_ROUTE,),
            max_frames=LONG_CITY_FRAMES,
            start_ns=EPOCH_NS + 7 * DAY_NS,
            town=TownConfig(n_blocks=(12, 10)),
            driving=DrivingConfig(cruise_speed_mps=(8.0, 12.0)),
        ),
    )
}
"""Every scenario by name."""

GROUPS: dict[str, tuple[str, ...]] = {"multisession": ("multisession_a", "multisession_b")}
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
