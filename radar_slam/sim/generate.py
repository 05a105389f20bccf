"""Generate a simulated sequence: lay out the town, populate it, drive, render, write.

`generate_sequence` writes the MulRan layout (see writer.py) into a folder; everything is
deterministic for a scenario and seed (town, contents, route speeds, speckle, noise), and each
scan has its own random stream, so any frame can be re-rendered alone.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from radar_slam.errors import RadarSlamError
from radar_slam.sim.manoeuvres import drive_plan, with_roundabout_islands
from radar_slam.sim.render import Renderer
from radar_slam.sim.reversal import drive_route
from radar_slam.sim.route import Trajectory, route_edges
from radar_slam.sim.scatterers import World
from radar_slam.sim.scenarios import SIM_VERSION, Scenario
from radar_slam.sim.town import Town
from radar_slam.sim.townplan import generate_town, street_plan
from radar_slam.sim.world import build_world
from radar_slam.sim.writer import (
    COMPLETE_MARKER,
    WORLD_FILE,
    ScanWriter,
    write_global_pose,
    write_json,
    write_stamps,
)
from raplace import NS_PER_S

logger = logging.getLogger(__name__)

GT_PERIOD_NS = 10_000_000
"""global_pose.csv is sampled at 100 Hz, plus a row at every scan time [ns]."""
ROUTE_STREAM, FRAME_STREAM = 2, 3
"""Random streams (with the seed and session) of the route speeds and of each scan."""


@dataclass
class Scene:
    """Everything needed to render a scenario.

    Attributes:
        scenario: the scenario.
        seed: the seed used.
        town: the layout.
        world: scatterers, occluders and traffic of the scenario's session.
        trajectory: the ego vehicle's base poses over time (town frame).
        n_frames: number of scans the route provides (after the scenario's cap).
    """

    scenario: Scenario
    seed: int
    town: Town
    world: World
    trajectory: Trajectory
    n_frames: int

    @property
    def period_ns(self) -> int:
        return self.scenario.sensor.scan_period_ns

    def scan_end_offsets_ns(self, n_frames: int) -> NDArray[np.int64]:
        """(n,) end-of-sweep times of the first n scans relative to the start [ns]."""
        return (np.arange(n_frames, dtype=np.int64) + 1) * self.period_ns

    def radar_poses(self, offsets_ns: NDArray[np.int64]) -> NDArray[np.float64]:
        """T_world_radar (n, 3) at times relative to the start [ns], dataset world frame."""
        poses = self.trajectory.radar_poses(offsets_ns.astype(np.float64) / NS_PER_S)
        poses[:, :2] += self.scenario.origin_xy
        return poses

    def base_poses(self, offsets_ns: NDArray[np.int64]) -> NDArray[np.float64]:
        """T_world_base (n, 3) at times relative to the start [ns], dataset world frame."""
        poses = self.trajectory.base_poses(offsets_ns.astype(np.float64) / NS_PER_S)
        poses[:, :2] += self.scenario.origin_xy
        return poses


def frame_rng(scene: Scene, index: int) -> np.random.Generator:
    """The random stream of scan `index` (speckle, noise, ghost phases)."""
    return np.random.default_rng([scene.seed, scene.scenario.session, FRAME_STREAM, index])


def render_frame(scene: Scene, renderer: Renderer, index: int) -> NDArray[np.uint8]:
    """Scan `index` (n_azimuths, n_bins) exactly as `generate_sequence` writes it."""
    end_s = float(scene.scan_end_offsets_ns(index + 1)[-1]) / NS_PER_S
    return renderer.scan(end_s, frame_rng(scene, index))


def make_renderer(scene: Scene) -> Renderer:
    """The renderer of a scene."""
    return Renderer(scene.world, scene.trajectory, scene.scenario.sensor, scene.scenario.physics)


def lay_out(scenario: Scenario, seed: int) -> tuple[Town, Trajectory]:
    """The town of a scenario (with its route's streets protected) and the ego drive through it
    (smooth lattice drive, or the scenario's plan); no world contents, no rendering."""
    town = generate_town(seed, scenario.town, _protected_edges(scenario))
    if scenario.plan is not None:
        town = with_roundabout_islands(town, list(scenario.waypoints), scenario.plan)
    return town, _drive_through(scenario, town, seed)


def ego_drive(scenario: Scenario, seed: int | None = None) -> Trajectory:
    """The ego drive of `lay_out` (the same poses) through the town's streets alone: fast."""
    seed = scenario.seed if seed is None else int(seed)
    town = street_plan(seed, scenario.town, _protected_edges(scenario))
    return _drive_through(scenario, town, seed)


def _protected_edges(scenario: Scenario) -> set[frozenset[tuple[int, int]]]:
    return set().union(*(route_edges(list(r)) for r in scenario.town_routes))


def _drive_through(scenario: Scenario, town: Town, seed: int) -> Trajectory:
    route_rng = np.random.default_rng([seed, scenario.session, ROUTE_STREAM])
    if scenario.plan is None:
        return drive_route(town, list(scenario.waypoints), scenario.driving, route_rng)
    return drive_plan(town, list(scenario.waypoints), scenario.plan, route_rng)


def build_scene(scenario: Scenario, seed: int | None = None) -> Scene:
    """Lay out, populate and drive a scenario (no rendering)."""
    seed = scenario.seed if seed is None else int(seed)
    town, trajectory = lay_out(scenario, seed)
    world = build_world(
        town, scenario.objects, seed, scenario.session, duration_s=trajectory.duration_s
    )
    available = int(round(trajectory.duration_s * NS_PER_S)) // scenario.sensor.scan_period_ns
    n_frames = available if scenario.max_frames is None else min(available, scenario.max_frames)
    return Scene(scenario, seed, town, world, trajectory, n_frames)


@dataclass(frozen=True)
class GeneratedSequence:
    """Summary of a written sequence.

    Attributes:
        folder: the sequence folder.
        scenario: scenario name.
        seed: seed used.
        n_frames: scans written.
        duration_s: time span of the scans [s].
        length_m: distance driven during the scans [m].
        seconds: wall time of the generation [s].
        build_seconds: part of it spent laying out the town and driving (before rendering) [s].
    """

    folder: Path
    scenario: str
    seed: int
    n_frames: int
    duration_s: float
    length_m: float
    seconds: float
    build_seconds: float


def checked_frame_count(scene: Scene, frames: int | None) -> int:
    """`frames`, or the whole route when None.

    Raises:
        RadarSlamError: more frames requested than the route provides, or fewer than 1.
    """
    n_frames = scene.n_frames if frames is None else int(frames)
    if not 0 < n_frames <= scene.n_frames:
        raise RadarSlamError(
            f"scenario {scene.scenario.name!r} provides 1 to {scene.n_frames} frames, "
            f"{n_frames} requested"
        )
    return n_frames


def write_scans(
    scene: Scene,
    folder: Path,
    n_frames: int,
    workers: int,
    on_frame: Callable[[int, int], None] | None,
) -> NDArray[np.int64]:
    """Render and write the first `n_frames` scans and their stamps; returns the scans' end
    offsets from the scenario start [ns]."""
    renderer = make_renderer(scene)
    ends = scene.scan_end_offsets_ns(n_frames)
    stamps = scene.scenario.start_ns + ends
    with ScanWriter(folder, workers) as writer:
        for k in range(n_frames):
            writer.write(int(stamps[k]), render_frame(scene, renderer, k))
            if on_frame is not None:
                on_frame(k + 1, n_frames)
    write_stamps(folder, stamps)
    return ends


def write_ground_truth(scene: Scene, folder: Path, ends: NDArray[np.int64]) -> float:
    """Write global_pose.csv (every GT_PERIOD_NS and at every scan end); returns the path
    length driven [m]."""
    gt_offsets = np.union1d(np.arange(0, int(ends[-1]) + 1, GT_PERIOD_NS, dtype=np.int64), ends)
    base = scene.base_poses(gt_offsets)
    write_global_pose(folder, scene.scenario.start_ns + gt_offsets, base)
    return float(np.hypot(*np.diff(base[:, :2], axis=0).T).sum())


def world_description(scene: Scene, summary: GeneratedSequence) -> dict[str, object]:
    """world.json: the scenario, its settings, the route and statistics of the world."""
    scenario = scene.scenario
    n_frames = summary.n_frames
    description: dict[str, object] = {
        "simulator_version": SIM_VERSION,
        "scenario": scenario.name,
        "description": scenario.description,
        "seed": scene.seed,
        "session": scenario.session,
        "frames": n_frames,
        "start_ns": scenario.start_ns,
        "duration_s": summary.duration_s,
        "length_m": summary.length_m,
        "route_length_m": scene.trajectory.length_m,
        "origin_xy": scenario.origin_xy,
        "waypoints": scenario.waypoints,
        "frames_convention": "file name = time of the last azimuth; poses in global_pose.csv are "
        "the vehicle base; T_world_radar = T_world_base * MULRAN_T_BASE_RADAR",
        "sensor": scenario.sensor,
        "physics": scenario.physics,
        "town": scenario.town,
        "objects": scenario.objects,
        "driving": scenario.driving,
        "world_stats": {
            "scatterers": len(scene.world.scatterers),
            "occluders": len(scene.world.occluders.loss_db),
            "buildings": len(scene.town.buildings),
            "roads": len(scene.town.roads),
            "moving_vehicles": len(scene.world.traffic),
        },
    }
    if scenario.plan is not None:
        description["plan"] = {
            "events": [{"event": type(e).__name__, **asdict(e)} for e in scenario.plan.events],
            "driving": scenario.plan.driving,
        }
    if scenario.held_out:
        description["held_out"] = True
    return description


def generate_sequence(
    scenario: Scenario,
    folder: Path,
    seed: int | None = None,
    frames: int | None = None,
    workers: int = 1,
    on_frame: Callable[[int, int], None] | None = None,
    scene: Scene | None = None,
) -> GeneratedSequence:
    """Generate `scenario` into `folder` (created; files in it are overwritten).

    The completion marker is written first saying "complete": false and rewritten last saying
    true, so a half-written sequence says so.

    Args:
        scenario: what to simulate.
        folder: the sequence folder.
        seed: seed (default: the scenario's).
        frames: number of scans (default: the whole route, or the scenario's cap).
        workers: background PNG writer threads (0: write inline).
        on_frame: called with (frames done, total) after each scan.
        scene: the scene of `scenario` and `seed` when already built (`build_scene`).

    Raises:
        RadarSlamError: more frames requested than the route provides.
    """
    started = time.perf_counter()
    scene = build_scene(scenario, seed) if scene is None else scene
    build_seconds = time.perf_counter() - started
    n_frames = checked_frame_count(scene, frames)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    marker = {
        "simulator_version": SIM_VERSION,
        "scenario": scenario.name,
        "seed": scene.seed,
        "frames": n_frames,
    }
    write_json(folder / COMPLETE_MARKER, {**marker, "complete": False})  # until the end
    logger.info(
        "generating %s (seed %d): %d scans into %s", scenario.name, scene.seed, n_frames, folder
    )
    ends = write_scans(scene, folder, n_frames, workers, on_frame)
    moved = write_ground_truth(scene, folder, ends)
    summary = GeneratedSequence(
        folder=folder,
        scenario=scenario.name,
        seed=scene.seed,
        n_frames=n_frames,
        duration_s=float(ends[-1]) / NS_PER_S,
        length_m=moved,
        seconds=time.perf_counter() - started,
        build_seconds=build_seconds,
    )
    write_json(folder / WORLD_FILE, world_description(scene, summary))
    write_json(folder / COMPLETE_MARKER, {**marker, "complete": True})
    logger.info(
        "%s: %d scans, %.0f m in %.1f s", folder, n_frames, summary.length_m, summary.seconds
    )
    return summary
