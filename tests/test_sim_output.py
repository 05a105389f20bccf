"""Simulated sequences on disk: MulRan layout, loader round trip, determinism, the `synthetic`
family (generate once, reuse, regenerate half-written folders) and the `simulate` command."""

from __future__ import annotations

import os
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from radar_slam.commands import simulate as simulate_command
from radar_slam.datasets import MulRanSequence, open_sequence
from radar_slam.datasets.navtech import MULRAN_T_BASE_RADAR
from radar_slam.sim.family import PARTIAL_SUFFIX, resolve_synthetic
from radar_slam.sim.generate import build_scene, generate_sequence
from radar_slam.sim.scenarios import TINY_BINS, get_scenario
from radar_slam.sim.writer import (
    COMPLETE_MARKER,
    GLOBAL_POSE_FILE,
    POLAR_DIR,
    STAMP_FILE,
    WORLD_FILE,
)
from raplace import se2

TINY = get_scenario("tiny")
FRAMES = 12
PERIOD_NS = 250_000_000
GT_TOLERANCE_M = 1e-3
TINY_MAX_SECONDS = 10.0


@pytest.fixture(scope="module")
def tiny_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("sim") / "tiny"
    generate_sequence(TINY, folder, frames=FRAMES)
    return folder


def test_mulran_layout(tiny_folder: Path) -> None:
    pngs = sorted((tiny_folder / POLAR_DIR).glob("*.png"))
    assert len(pngs) == FRAMES
    image = cv2.imread(str(pngs[0]), cv2.IMREAD_UNCHANGED)
    assert image.dtype == np.uint8 and image.shape == (TINY_BINS, 400)  # rows = bins
    stamps = np.loadtxt(tiny_folder / STAMP_FILE, dtype=np.int64)
    assert [int(p.stem) for p in pngs] == stamps.tolist()
    assert np.all(np.diff(stamps) == PERIOD_NS)
    assert stamps[0] == TINY.start_ns + PERIOD_NS  # name = end of the first sweep
    gt = np.loadtxt(tiny_folder / GLOBAL_POSE_FILE, delimiter=",", dtype=np.float64)
    assert gt.shape[1] == 13 and len(gt) > 2 * FRAMES  # denser than the scans
    assert np.allclose(gt[:, 12], 0.0) and np.allclose(gt[:, 11], 1.0)  # z = 0, R33 = 1
    assert (tiny_folder / WORLD_FILE).is_file() and (tiny_folder / COMPLETE_MARKER).is_file()


def test_mulran_loader_reads_it_and_gt_matches_simulated_radar_poses(tiny_folder: Path) -> None:
    sequence = MulRanSequence(tiny_folder, n_bins=TINY_BINS)
    assert len(sequence) == FRAMES
    frame = sequence[3]
    assert frame.polar.shape == (400, TINY_BINS)
    assert frame.azimuth_times_ns is not None and frame.azimuth_times_ns[-1] == frame.timestamp_ns
    scene = build_scene(TINY)
    simulated = scene.radar_poses(sequence.timestamps_ns - TINY.start_ns)
    gt = sequence.ground_truth
    assert gt is not None
    assert np.abs(gt[:, :2] - simulated[:, :2]).max() < GT_TOLERANCE_M
    assert np.abs(se2.wrap_angle(gt[:, 2] - simulated[:, 2])).max() < 1e-6
    # global_pose.csv holds the base: radar = base * T_base_radar.
    base = scene.base_poses(sequence.timestamps_ns - TINY.start_ns)
    assert np.allclose(se2.compose(base, MULRAN_T_BASE_RADAR), simulated, atol=1e-9)


def test_generation_is_deterministic(tiny_folder: Path, tmp_path: Path) -> None:
    again = tmp_path / "again"
    generate_sequence(TINY, again, frames=FRAMES)
    for relative in (GLOBAL_POSE_FILE, STAMP_FILE):
        assert (again / relative).read_bytes() == (tiny_folder / relative).read_bytes()
    for png in sorted((tiny_folder / POLAR_DIR).glob("*.png"))[:4]:
        first = cv2.imread(str(png), cv2.IMREAD_UNCHANGED)
        second = cv2.imread(str(again / POLAR_DIR / png.name), cv2.IMREAD_UNCHANGED)
        assert np.array_equal(first, second)
    other_seed = tmp_path / "seed"
    generate_sequence(TINY, other_seed, seed=TINY.seed + 1, frames=2)
    png = sorted((other_seed / POLAR_DIR).glob("*.png"))[0]
    assert not np.array_equal(
        cv2.imread(str(png), cv2.IMREAD_UNCHANGED),
        cv2.imread(str(tiny_folder / POLAR_DIR / png.name), cv2.IMREAD_UNCHANGED),
    )


def test_tiny_generates_well_under_ten_seconds(tmp_path: Path) -> None:
    started = time.perf_counter()
    summary = generate_sequence(TINY, tmp_path / "tiny")
    assert summary.n_frames == TINY.max_frames
    assert time.perf_counter() - started < TINY_MAX_SECONDS


def test_synthetic_family_generates_reuses_and_repairs(tmp_path: Path) -> None:
    root = tmp_path / "data"
    sequence = open_sequence("synthetic/tiny", root)
    assert sequence.family == "synthetic" and len(sequence) == TINY.max_frames
    folder = root / "synthetic" / "tiny"
    marker_time = (folder / COMPLETE_MARKER).stat().st_mtime_ns
    assert resolve_synthetic(root, "tiny") == folder
    assert (folder / COMPLETE_MARKER).stat().st_mtime_ns == marker_time  # reused, not regenerated
    # An interrupted run: the marker is missing and scans are lost; it must be regenerated.
    (folder / COMPLETE_MARKER).unlink()
    for png in sorted((folder / POLAR_DIR).glob("*.png"))[10:]:
        png.unlink()
    stale = root / "synthetic" / f".tiny{PARTIAL_SUFFIX}999999999"  # a dead generator's temp folder
    stale.mkdir()
    assert len(open_sequence("synthetic/tiny", root)) == TINY.max_frames
    assert (folder / COMPLETE_MARKER).is_file()
    assert not stale.exists()
    assert sorted(p.name for p in (root / "synthetic").iterdir()) == ["tiny"]


def test_unknown_scenario_is_a_clear_error(tmp_path: Path) -> None:
    from radar_slam.errors import DatasetNotFoundError

    with pytest.raises(DatasetNotFoundError, match="no such scenario.*simulate --help"):
        open_sequence("synthetic/nope", tmp_path)


def _app() -> typer.Typer:
    app = typer.Typer()

    @app.callback()
    def _root() -> None:
        """radar-slam (test app)."""

    simulate_command.register(app)
    return app


def test_simulate_command(tmp_path: Path) -> None:
    out = tmp_path / "out"
    result = CliRunner().invoke(
        _app(), ["simulate", "tiny", "--out", str(out), "--frames", "6", "--seed", "3"]
    )
    assert result.exit_code == 0, result.output
    assert len(list((out / POLAR_DIR).glob("*.png"))) == 6
    again = CliRunner().invoke(_app(), ["simulate", "tiny", "--out", str(out)])
    assert again.exit_code != 0 and "not empty" in str(again.exception)
    too_many = CliRunner().invoke(
        _app(), ["simulate", "tiny", "--out", str(tmp_path / "x"), "--frames", "100000"]
    )
    assert too_many.exit_code != 0 and "provides" in str(too_many.exception)


def test_pid_of_running_generation_is_kept(tmp_path: Path) -> None:
    root = tmp_path / "data"
    running = root / "synthetic" / f".tiny{PARTIAL_SUFFIX}{os.getppid()}"  # a live process
    running.mkdir(parents=True)
    resolve_synthetic(root, "tiny")
    assert running.exists()
