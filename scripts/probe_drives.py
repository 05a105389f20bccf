"""Write the probe drives: simulated drives nothing was ever tuned on.

They differ from the named scenarios in route, town, speed and seed. Stop 19's four: a fast ring
with a U-turn and a revisit the other way (14-18 m/s), a slow staircase of narrow streets with a
three-point turn and reversing (6-9 m/s), three roundabouts and a revisit, and a long slow lattice
drive (5-9 m/s, 2.3 km). Stop 20's four: out along a street of a curved town, round a block and
back the way it came (smooth driving, 9-14 m/s); a zigzag of junction turns with a U-turn at its
end and back down it; a long street at 13-16 m/s with a U-turn, back, and round a block; and a
loop of blocks with three roundabouts, a stop and reversing, driven again in part. Each is
written in the MulRan layout under OUT/mulran/<name>, so that

    python scripts/probe_drives.py --out /data/probe
    python scripts/bench_odometry.py --data-root /data/probe --held-out mulran/probe_ring_fast ...
    radar-slam run mulran/probe_ring_fast --data-root /data/probe --stride 4 --out RUN

measure them like any sequence. They are kept out of `radar_slam.sim.scenarios` (which holds the
CI-sized scenarios and their tests); the README reports their numbers once, as a check of the
methods on driving they were not designed on.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from radar_slam.sim.driving import PlanDrivingConfig
from radar_slam.sim.generate import generate_sequence
from radar_slam.sim.manoeuvres import DrivePlan, Reverse, Roundabout, Stop, TurnAround
from radar_slam.sim.route import DrivingConfig
from radar_slam.sim.scenarios import (
    DAY_NS,
    EPOCH_NS,
    NARROW_STREETS,
    OPEN_JUNCTIONS,
    WIDE_STREETS,
    Scenario,
    Waypoints,
    plan_town,
)
from radar_slam.sim.town import TownConfig

_RING: Waypoints = (
    *((0, 0), (3, 0), (3, 2), (0, 2), (0, 0)),
    *((3, 0), (4, 0), (3, 0), (3, 2), (0, 2)),
)
"""Round a ring of blocks, on along its first street, a U-turn, round it again the other way."""
_STAIRS: Waypoints = (
    *((0, 0), (1, 0), (1, 1), (2, 1), (2, 2), (3, 2)),
    *((2, 2), (2, 1), (1, 1), (1, 0), (0, 0)),
)
"""Up a staircase of junction turns and back down it after a three-point turn."""
_ROUNDABOUTS: Waypoints = ((0, 1), (1, 1), (1, 2), (3, 2), (3, 1), (1, 1), (1, 2), (0, 2))
"""Three roundabouts, round a loop of blocks and through the first junctions again."""
_LATTICE: Waypoints = (
    *((1, 1), (4, 1), (4, 3), (1, 3), (1, 1)),
    *((4, 1), (4, 3), (6, 3), (6, 1), (4, 1)),
)
"""A loop of blocks twice in the same direction, then a block beyond it (no revisit there)."""
_BLOCK_BACK: Waypoints = (
    *((0, 2), (3, 2), (3, 3), (4, 3), (4, 2), (3, 2)),
    *((0, 2), (0, 1), (2, 1)),
)
"""Out along a street, round a block, back along the street the other way, then a turn off."""
_ZIGZAG: Waypoints = (
    *((0, 0), (1, 0), (1, 1), (2, 1), (2, 2), (3, 2), (3, 3), (4, 3)),
    *((3, 3), (3, 2), (2, 2), (2, 1)),
)
"""A staircase of junction turns, a U-turn before node (4, 3), back down the staircase."""
_STREET_BACK: Waypoints = ((0, 1), (4, 1), (0, 1), (0, 2), (2, 2), (2, 1), (3, 1))
"""A long street, a U-turn before its end, back along it, then round a block onto it again."""
_ROUND_REVERSE: Waypoints = ((0, 0), (2, 0), (2, 2), (0, 2), (0, 0), (2, 0), (3, 0))
"""Round a loop of blocks and along its first street again."""


def _probe(
    name: str,
    seed: int,
    day: int,
    route: Waypoints,
    town: TownConfig,
    plan: DrivePlan | None = None,
    driving: DrivingConfig | None = None,
    stop: int = 19,
) -> Scenario:
    return Scenario(
        name=name,
        description=f"stop-{stop} probe drive {name}",
        seed=seed,
        waypoints=route,
        town_routes=(route,),
        start_ns=EPOCH_NS + day * DAY_NS,
        town=town,
        driving=DrivingConfig() if driving is None else driving,
        plan=plan,
        held_out=True,
    )


PROBES: dict[str, Scenario] = {
    s.name: s
    for s in (
        _probe(
            "probe_ring_fast",
            71,
            40,
            _RING,
            plan_town(n_blocks=(5, 3), block_size_m=(90.0, 140.0), **WIDE_STREETS),
            DrivePlan(
                events=(Stop(2, 12.0), TurnAround(14, "u_turn", 50.0), Stop(17, 5.0)),
                driving=PlanDrivingConfig(accel_mps2=3.0, cruise_speed_mps=(14.0, 18.0)),
            ),
        ),
        _probe(
            "probe_stairs_slow",
            72,
            41,
            _STAIRS,
            plan_town(n_blocks=(4, 4), block_size_m=(50.0, 75.0), **NARROW_STREETS),
            DrivePlan(
                events=(
                    Stop(1, 15.0),
                    TurnAround(5, "three_point", 30.0),
                    Reverse(7, 38.0, 25.0),
                    Stop(9, 6.0),
                ),
                driving=PlanDrivingConfig(accel_mps2=3.0, cruise_speed_mps=(6.0, 9.0)),
            ),
        ),
        _probe(
            "probe_roundabouts",
            73,
            42,
            _ROUNDABOUTS,
            plan_town(n_blocks=(4, 3), block_size_m=(80.0, 110.0), **OPEN_JUNCTIONS),
            DrivePlan(
                events=(Roundabout(2), Roundabout(4), Stop(6, 8.0), Roundabout(7)),
                driving=PlanDrivingConfig(accel_mps2=3.0, cruise_speed_mps=(11.0, 14.0)),
            ),
        ),
        _probe(
            "probe_lattice_slow",
            74,
            43,
            _LATTICE,
            TownConfig(n_blocks=(7, 4)),
            driving=DrivingConfig(cruise_speed_mps=(5.0, 9.0)),
        ),
        _probe(
            "probe_block_back",
            81,
            50,
            _BLOCK_BACK,
            TownConfig(n_blocks=(5, 4), block_size_m=(60.0, 120.0)),
            driving=DrivingConfig(cruise_speed_mps=(9.0, 14.0), accel_mps2=2.0, decel_mps2=3.0),
            stop=20,
        ),
        _probe(
            "probe_zigzag",
            82,
            51,
            _ZIGZAG,
            plan_town(n_blocks=(5, 4), block_size_m=(55.0, 90.0), **WIDE_STREETS),
            DrivePlan(
                events=(Stop(3, 10.0), TurnAround(7, "u_turn", 35.0), Stop(10, 4.0)),
                driving=PlanDrivingConfig(accel_mps2=3.0, cruise_speed_mps=(11.0, 14.0)),
            ),
            stop=20,
        ),
        _probe(
            "probe_street_back",
            83,
            52,
            _STREET_BACK,
            plan_town(n_blocks=(5, 3), block_size_m=(100.0, 150.0), **WIDE_STREETS),
            DrivePlan(
                events=(TurnAround(4, "u_turn", 45.0), Stop(9, 8.0)),
                driving=PlanDrivingConfig(accel_mps2=3.0, cruise_speed_mps=(13.0, 16.0)),
            ),
            stop=20,
        ),
        _probe(
            "probe_round_reverse",
            84,
            53,
            _ROUND_REVERSE,
            plan_town(n_blocks=(4, 3), block_size_m=(70.0, 100.0), **OPEN_JUNCTIONS),
            DrivePlan(
                events=(
                    Roundabout(2),
                    Stop(4, 10.0),
                    Reverse(6, 50.0, 20.0),
                    Roundabout(8),
                    Roundabout(10),
                ),
                driving=PlanDrivingConfig(accel_mps2=3.0, cruise_speed_mps=(9.0, 13.0)),
            ),
            stop=20,
        ),
    )
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="data root to write into")
    parser.add_argument(
        "--only", action="append", choices=sorted(PROBES), help="write only this drive"
    )
    parser.add_argument("--workers", type=int, default=2, help="rendering processes")
    args = parser.parse_args()
    for name in args.only or sorted(PROBES):
        folder = args.out / "mulran" / name
        if folder.exists() and any(folder.iterdir()):
            parser.error(f"{folder} exists and is not empty; remove it first")
        made = generate_sequence(PROBES[name], folder, workers=args.workers)
        print(f"{name}: {made.n_frames} scans, {made.length_m:.0f} m -> {folder}")


if __name__ == "__main__":
    main()
