"""Simulator of Navtech scanning-radar sequences in the MulRan layout.

Modules, in pipeline order:
    town.py       layout records (roads, buildings, raster), the warped street lattice
    townplan.py   generate_town: streets, then buildings, street furniture, parking, parks
    scatterers.py the world's data model: scatterers, occluders, traffic, World
    world.py      a town populated with scatterers: facades, cars, vegetation, traffic
    route.py      the ego vehicle's drive through the streets (5-15 m/s, smooth turns)
    driving.py    drives of constant-curvature legs: reverse gear, stops, steering transitions
    manoeuvres.py plans: a route plus stops, roundabouts, U-turns, three-point turns, reversing
    sensor.py     scan geometry and timing (CIR204-H by default)
    physics.py    every physical effect as a named, configurable dataclass
    render.py     vectorised rendering of one polar scan
    scenarios.py  named scenarios: tiny, tiny_loop, loop, reverse, multisession_a/_b, long, and
                  the driving scenarios (turn_around ... reverse_gear, held out: heldout_*)
    waypoints.py  the scenarios' routes (lattice waypoints)
    generate.py   build a scene and write a sequence
    writer.py     the files (polar PNGs, global_pose.csv, stamps, world.json, marker)
    figure.py     overview figure (matplotlib)
    family.py     the `synthetic` dataset family (a plug-in of the dataset registry)

Entry points: `generate.generate_sequence(scenario, folder)`, the `synthetic` dataset family
(`radar_slam.sim.family`) and `radar-slam simulate`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from radar_slam.lazy import lazy_exports

_EXPORTS = {
    "SCENARIOS": "radar_slam.sim.scenarios",
    "GeneratedSequence": "radar_slam.sim.generate",
    "Scenario": "radar_slam.sim.scenarios",
    "Scene": "radar_slam.sim.generate",
    "build_scene": "radar_slam.sim.generate",
    "generate_sequence": "radar_slam.sim.generate",
    "get_scenario": "radar_slam.sim.scenarios",
}
"""Public name -> its module, loaded on first use (the `synthetic` family opens a sequence
already generated without loading the generator)."""

__all__ = [
    "SCENARIOS",
    "GeneratedSequence",
    "Scenario",
    "Scene",
    "build_scene",
    "generate_sequence",
    "get_scenario",
]

if TYPE_CHECKING:
    from radar_slam.sim.generate import GeneratedSequence, Scene, build_scene, generate_sequence
    from radar_slam.sim.scenarios import SCENARIOS, Scenario, get_scenario


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
