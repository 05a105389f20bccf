"""`loops` on graphs that carry loops of their own: a false edge, however confident, is named in
a warning and leaves the result as it was without it; a true one is kept. A file that is no g2o
graph is one line, without a warning per line before it."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
from bad_input_support import assert_refused, run_cli

from radar_slam.datasets import open_sequence
from radar_slam.datasets.frame import RadarSequence
from radar_slam.g2o import G2oEdge, G2oGraph, read_g2o, write_g2o
from radar_slam.pipeline import run_odometry
from raplace.se2 import between

FALSE_I, FALSE_J = 5, 45
"""Scans of synthetic/tiny about 60 m apart: an edge saying they coincide is false."""
ODOMETRY_INFORMATION = np.linalg.inv(np.diag([0.05**2, 0.05**2, np.deg2rad(0.2) ** 2]))


@pytest.fixture(scope="module")
def tiny_odometry(tiny: RadarSequence, synthetic_root: Path) -> np.ndarray:
    return run_odometry(open_sequence("synthetic/tiny", synthetic_root)).trajectory.poses


def write_graph(path: Path, poses: np.ndarray, extra: list[G2oEdge]) -> Path:
    edges = [
        G2oEdge(k, k + 1, between(poses[k], poses[k + 1]), ODOMETRY_INFORMATION)
        for k in range(len(poses) - 1)
    ]
    write_g2o(path, G2oGraph(dict(enumerate(poses)), edges + extra, [0]))
    return path


def close(
    capsys: pytest.CaptureFixture[str], root: Path, graph: Path, out: Path
) -> tuple[np.ndarray, str]:
    outcome = run_cli(capsys, "loops", graph, "synthetic/tiny", "--out", out, "--data-root", root)
    assert outcome.code == 0, outcome.stderr
    return read_g2o(out).poses(), outcome.stdout


def test_a_confident_false_input_loop_is_named_and_changes_nothing(
    tiny_odometry: np.ndarray,
    synthetic_root: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
) -> None:
    clean = write_graph(tmp_path / "clean.g2o", tiny_odometry, [])
    false = G2oEdge(FALSE_I, FALSE_J, np.zeros(3), np.eye(3) * 1e12)
    dirty = write_graph(tmp_path / "dirty.g2o", tiny_odometry, [false])
    expected, _ = close(capsys, synthetic_root, clean, tmp_path / "clean_out.g2o")
    with caplog.at_level(logging.WARNING):
        result, stdout = close(capsys, synthetic_root, dirty, tmp_path / "dirty_out.g2o")
    assert np.hypot(*(result[:, :2] - expected[:, :2]).T).max() < 0.1
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert [w for w in warnings if f"EDGE_SE2 {FALSE_I} {FALSE_J}" in w], warnings
    assert "input loops: 1, 1 left out" in stdout


def test_a_true_input_loop_is_kept(
    tiny_odometry: np.ndarray,
    synthetic_root: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
) -> None:
    measured = between(tiny_odometry[FALSE_I], tiny_odometry[FALSE_J])
    true = G2oEdge(FALSE_I, FALSE_J, measured, ODOMETRY_INFORMATION)
    graph = write_graph(tmp_path / "in.g2o", tiny_odometry, [true])
    with caplog.at_level(logging.WARNING):
        _, stdout = close(capsys, synthetic_root, graph, tmp_path / "out.g2o")
    assert "input loops: 1, 0 left out" in stdout
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]
    out_edges = {(e.i, e.j) for e in read_g2o(tmp_path / "out.g2o").edges}
    assert (FALSE_I, FALSE_J) in out_edges


def test_garbage_graph_is_one_line(
    tiny: RadarSequence, synthetic_root: Path, workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    garbage = workdir / "garbage.g2o"
    garbage.write_text("".join(f"word{k} {k}\n" for k in range(53)))
    args: list[str | Path] = ["loops", garbage, "synthetic/tiny", "--out", workdir / "o.g2o"]
    args += ["--data-root", synthetic_root]
    assert_refused(capsys, (workdir, synthetic_root), args, "garbage.g2o", "VERTEX_SE2")
