"""Simulator of Navtech scanning-radar sequences in the MulRan layout.

Modules, in pipeline order:
    town.py       street lattice, curved roads, buildings, street furniture, parks (geometry)
    world.py      radar scatterers and occluders of a town; parked cars, vegetation, traffic
    route.py      the ego vehicle's drive through the streets (5-15 m/s, smooth turns)
    driving.py    drives of constant-curvature legs: reverse gear, stops, stepped curvature
    manoeuvres.py plans: a route plus stops, roundabouts, U-turns, three-point turns, reversing
    sensor.py     scan geometry and timing (CIR204-H by default)
    physics.py    every physical effect as a named, configurable dataclass
    render.py     vectorised rendering of one polar scan
    scenarios.py  named scenarios: tiny, tiny_loop, loop, reverse, multisession_a/_b, long, and
                  the driving scenarios (turn_around ... reverse_gear, held out: heldout_*)
    generate.py   build a scene and write a sequence
    writer.py     the files (polar PNGs, global_pose.csv, stamps, world.json, marker)
    figure.py     overview figure (matplotlib)

Entry points: `generate.generate_sequence(scenario, folder)`, the `synthetic` dataset family
(`radar_slam.datasets.synthetic`) and `radar-slam simulate`.
"""
