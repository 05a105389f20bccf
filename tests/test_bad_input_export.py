"""`export` into unusable locations (one line before any work, nothing created), a `.BAG` name
(refused: not silently a ROS 2 folder), and a killed export's leftovers (removed by the next)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from bad_input_support import assert_refused, run_cli

from radar_slam.datasets.frame import RadarSequence
from radar_slam.results import PARTIAL_SUFFIX


def _export(root: Path, bag: Path) -> list[str | Path]:
    return ["export", "synthetic/tiny", "--bag", bag, "--max-frames", "3", "--data-root", root]


@pytest.mark.parametrize("name", ["out.bag", "out_ros2"])
@pytest.mark.parametrize("where", ["under a file", "in a missing folder"])
def test_export_location_is_checked_before_any_work(
    name: str,
    where: str,
    tiny: RadarSequence,
    synthetic_root: Path,
    workdir: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    (workdir / "somefile").write_text("mine")
    parent, expected = {
        "under a file": (workdir / "somefile", "not a folder"),
        "in a missing folder": (workdir / "nodir", "does not exist"),
    }[where]
    bag = parent / name
    args = _export(synthetic_root, bag)
    assert_refused(capsys, (workdir, synthetic_root), args, str(bag), expected)


def test_upper_case_bag_name_is_refused(
    tiny: RadarSequence, synthetic_root: Path, workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Not silently a ROS 2 folder named x.BAG: ROS tools read only *.bag as ROS 1."""
    bag = workdir / "x.BAG"
    roots = (workdir, synthetic_root)
    assert_refused(capsys, roots, _export(synthetic_root, bag), str(bag), "x.bag", "lower case")


def test_next_export_removes_a_killed_exports_leftovers(
    tiny: RadarSequence, synthetic_root: Path, workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    finished = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        check=True,
        capture_output=True,
        text=True,
    )
    leftover = workdir / f".old.bag{PARTIAL_SUFFIX}{finished.stdout.strip()}"
    leftover.mkdir()
    (leftover / "old.bag").write_bytes(b"half a bag")
    outcome = run_cli(capsys, *_export(synthetic_root, workdir / "new.bag"))
    assert outcome.code == 0, outcome.stderr
    assert sorted(p.name for p in workdir.iterdir()) == ["new.bag"]
