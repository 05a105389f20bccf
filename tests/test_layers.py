"""The layers hold at run time: importing a lower layer loads nothing above it (new interpreter)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest


def loaded_after(statement: str) -> set[str]:
    """Top-level packages and our modules in sys.modules after `statement` in a new interpreter."""
    code = f"{statement}\nimport json, sys\nprint(json.dumps(sorted(sys.modules)))"
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    return set(json.loads(out.splitlines()[-1]))


def under(modules: set[str], *packages: str) -> set[str]:
    return {m for m in modules if m.split(".")[0] in packages}


@pytest.mark.parametrize(
    ("statement", "forbidden"),
    [
        ("import raplace", ("odometry", "radar_slam", "gtsam")),
        ("import odometry", ("radar_slam", "gtsam")),
        ("import radar_slam", ("gtsam", "odometry", "raplace")),
        ("from radar_slam.loops import LoopDetector", ("gtsam",)),
        ("from radar_slam import LoopDetector, LoopConstraint", ("gtsam",)),
    ],
)
def test_import_loads_no_upper_layer(statement: str, forbidden: tuple[str, ...]) -> None:
    assert under(loaded_after(statement), *forbidden) == set()


def test_loop_detector_loads_no_dataset_loader_or_simulator() -> None:
    modules = loaded_after("import radar_slam.loops")
    assert "radar_slam.loops.detector" in modules
    assert {m for m in modules if m.startswith(("radar_slam.datasets", "radar_slam.sim"))} == set()


def test_datasets_load_the_simulator_only_as_a_plug_in() -> None:
    assert under(loaded_after("import radar_slam.datasets"), "gtsam") == set()
    assert "radar_slam.sim" not in loaded_after("import radar_slam.datasets")
    assert "radar_slam.sim.family" in loaded_after(
        "from radar_slam.datasets import families\nassert 'synthetic' in families()"
    )


def test_the_run_command_loads_the_end_of_run_modules_on_first_use() -> None:
    modules = loaded_after("import radar_slam.commands.run")
    assert "radar_slam.commands.run" in modules
    assert under(modules, "matplotlib", "evo") == set()
    assert {"matplotlib", "evo"} <= loaded_after(
        "from radar_slam.lazy import preload\n"
        "from radar_slam.commands.run import END_OF_RUN_MODULES\n"
        "preload(END_OF_RUN_MODULES).join()"
    )
