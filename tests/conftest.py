"""Shared fixtures: locations of the real radar samples in ../shared/data, and a data root
where the small simulated sequences (`synthetic/tiny`, `synthetic/tiny_loop`) are generated once
per test session."""

from __future__ import annotations

import dataclasses
from importlib.util import find_spec
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray
from raplace_scenes import oxford_scans

from radar_slam.cli import main
from radar_slam.datasets import OxfordSequence, open_sequence
from radar_slam.datasets.frame import RadarFrame, RadarSequence

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
OXFORD_SEQ = SHARED_DATA / "oxford" / "2019-01-10-14-36-48-partial"
MULRAN_RAW = SHARED_DATA / "mulran" / "raw_scan"


def _require(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"real radar samples not found at {path} (see ../shared/data/README.md)")
    return path


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The folder of real radar samples; skips the test when absent."""
    return _require(SHARED_DATA)


@pytest.fixture(scope="session")
def oxford_dir() -> Path:
    """The partial Oxford Radar RobotCar sequence (7 scans + GT odometry)."""
    return _require(OXFORD_SEQ)


@pytest.fixture(scope="session")
def mulran_raw_dir() -> Path:
    """One real MulRan scan: raw CSV and the polar PNG."""
    return _require(MULRAN_RAW)


@pytest.fixture(scope="module")
def oxford(oxford_dir: Path) -> OxfordSequence:
    """The partial Oxford sequence, opened once per test module."""
    return OxfordSequence(oxford_dir)


@pytest.fixture(scope="module")
def oxford_snapshot(oxford: OxfordSequence) -> RadarFrame:
    """The first Oxford scan without azimuth times: an instantaneous picture of the world."""
    return dataclasses.replace(oxford[0], azimuth_times_ns=None)


@pytest.fixture(scope="module")
def oxford_polar_scans(
    oxford_dir: Path,
) -> list[tuple[NDArray[np.uint8], NDArray[np.float64], float]]:
    """(polar, CCW azimuths [rad], range resolution [m]) of every partial Oxford scan, read
    once per test module (see `raplace_scenes.oxford_scans`)."""
    return oxford_scans(oxford_dir)


@pytest.fixture(scope="session")
def metric_keys() -> frozenset[str]:
    """The keys of a flat metrics record (`TrajectoryMetrics.to_dict`, `radar-slam eval --json`)."""
    return frozenset(
        {
            "ate_rmse_m",
            "ate_origin_rmse_m",
            "rpe_trans_rmse_m",
            "drift_trans_pct",
            "drift_rot_deg_per_100m",
            "poses_matched",
            "end_point_error_pct",
            "drift_min_segment_m",
        }
    )


@pytest.fixture(scope="session")
def synthetic_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A data root shared by the session's tests: `synthetic/<scenario>` is generated into it on
    first use (by a fixture below or by a CLI run) and reused afterwards."""
    return tmp_path_factory.mktemp("data")


@pytest.fixture(scope="session")
def tiny(synthetic_root: Path) -> RadarSequence:
    """`synthetic/tiny`: 60 scans of 1024 bins (generated in about a second)."""
    return open_sequence("synthetic/tiny", synthetic_root)


@pytest.fixture(scope="session")
def tiny_loop(synthetic_root: Path) -> RadarSequence:
    """`synthetic/tiny_loop`: a small loop with a revisit, 177 scans of 1024 bins (generated in a
    few seconds)."""
    return open_sequence("synthetic/tiny_loop", synthetic_root)


@pytest.fixture(scope="session")
def tiny_loop_runs(
    tiny_loop: RadarSequence, synthetic_root: Path, tmp_path_factory: pytest.TempPathFactory
) -> Path:
    """`run` on synthetic/tiny_loop (with a viewer recording) and on its ROS 1 bag export:
    <tmp>/folder/, <tmp>/bag/, <tmp>/viewer.rrd (when rerun-sdk is installed)."""
    tmp = tmp_path_factory.mktemp("tiny_loop_runs")
    bag = tmp / "tiny_loop.bag"
    root = ["--data-root", str(synthetic_root)]
    assert main(["export", "synthetic/tiny_loop", "--bag", str(bag), *root]) == 0
    folder_run = ["run", "synthetic/tiny_loop", "--out", str(tmp / "folder"), *root]
    viewer = ["--viewer", str(tmp / "viewer.rrd")] if find_spec("rerun") is not None else []
    assert main([*folder_run, *viewer]) == 0
    assert main(["run", str(bag), "--out", str(tmp / "bag")]) == 0
    return tmp


@pytest.fixture()
def workdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty current folder (a default results/ folder would be written here)."""
    monkeypatch.chdir(tmp_path)
    return tmp_path
