"""CLI smoke runs: `radar-slam run` end to end on a short simulated revisit (`synthetic/tiny_loop`),
`--no-loops`, the default result folder, `radar-slam odometry`, `radar-slam loops`, and user
errors. `synthetic_root` (conftest.py) is the session's data root, where the sequences are
generated on first use."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from slam_bars import loops_corrected

from radar_slam.cli import main
from radar_slam.datasets import open_sequence
from radar_slam.g2o import G2oEdge, G2oGraph, read_g2o, write_g2o
from radar_slam.outputs import LOOPS_CSV_COLUMNS, SLAM_RESULT_FILES
from radar_slam.pipeline import SlamMetrics, load_config, run_odometry
from radar_slam.trajectory import read_kitti, read_tum
from raplace.se2 import between

METRICS_KEYS = {
    "frames",
    "seconds",
    "frames_per_second",
    "loops_proposed",
    "loops_accepted",
    "loops_accepted_true",
    "ate_odometry_m",
    "ate_slam_m",
    "ate_reduction",
    "drift_odometry_pct",
    "drift_slam_pct",
    "ate_origin_odometry_m",
    "ate_origin_slam_m",
}


def lines(path: Path) -> list[str]:
    return [line for line in path.read_text().splitlines() if line and not line.startswith("#")]


def test_run_end_to_end_closes_the_loop(synthetic_root: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    code = main(
        ["run", "synthetic/tiny_loop", "--data-root", str(synthetic_root), "--out", str(out)]
    )
    assert code == 0
    for name in (*SLAM_RESULT_FILES, "gt.tum"):
        assert (out / name).is_file(), name
    metrics = json.loads((out / "metrics.json").read_text())
    assert METRICS_KEYS <= set(metrics)
    fields = {f.name for f in SlamMetrics.__dataclass_fields__.values()}
    assert set(metrics) == fields | {"ground_truth"}
    # The simulator's GT shares the radar's clock: the estimated offset is within a few scans' ms.
    assert abs(metrics["ground_truth"]["time_offset"]["offset_s"]) < 0.05
    assert metrics["ground_truth"]["accuracy_m"] == 0.0
    frames = metrics["frames"]
    assert frames == len(open_sequence("synthetic/tiny_loop", synthetic_root))
    for stem in ("odometry", "slam"):
        assert len(lines(out / f"{stem}.tum")) == frames
        assert len(lines(out / f"{stem}.kitti")) == frames
        tum = read_tum(out / f"{stem}.tum")
        np.testing.assert_allclose(
            read_kitti(out / f"{stem}.kitti", tum.timestamps_ns).poses, tum.poses, atol=1e-6
        )
    with (out / "loops.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert tuple(rows[0].keys()) == LOOPS_CSV_COLUMNS
    assert len(rows) == metrics["loops_proposed"]
    accepted = [r for r in rows if r["accepted"] == "true"]
    assert len(accepted) == metrics["loops_accepted"] >= 3
    assert all(r["true_loop"] == "true" for r in accepted)
    assert all(r["reason"] for r in rows)
    assert metrics["loops_accepted_true"] == metrics["loops_accepted"]
    assert loops_corrected(metrics["ate_slam_m"], metrics["ate_odometry_m"])
    graph = read_g2o(out / "graph.g2o")
    assert len(graph.vertices) == frames
    assert len(graph.edges) == frames - 1 + metrics["loops_accepted"]
    # The written config reads back as the config used.
    assert load_config(None, out / "config.yaml") == load_config("synthetic")
    assert "loops" in (out / "summary.txt").read_text()


def test_run_without_loops_and_default_folder(
    synthetic_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    code = main(["run", "synthetic/tiny", "--data-root", str(synthetic_root), "--no-loops"])
    assert code == 0
    latest = tmp_path / "results" / "synthetic_tiny" / "latest"
    assert latest.is_symlink() and (latest / "metrics.json").is_file()
    slam, odo = read_tum(latest / "slam.tum"), read_tum(latest / "odometry.tum")
    np.testing.assert_allclose(slam.poses, odo.poses, atol=1e-6)
    assert "enabled: false" in (latest / "config.yaml").read_text()
    assert lines(latest / "loops.csv") == [",".join(LOOPS_CSV_COLUMNS)]


def test_odometry_command(
    synthetic_root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "odo"
    args = ["odometry", "synthetic/tiny", "--data-root", str(synthetic_root), "--out", str(out)]
    assert main([*args, "--max-frames", "40"]) == 0
    assert "ATE" in capsys.readouterr().out
    for name in ("odometry.tum", "odometry.kitti", "gt.tum", "metrics.json", "trajectory.png"):
        assert (out / name).is_file(), name
    assert len(lines(out / "odometry.tum")) == len(lines(out / "odometry.kitti")) == 40
    metrics = json.loads((out / "metrics.json").read_text())
    assert {"frames", "frames_per_second", "ate_rmse_m", "ate_origin_rmse_m"} <= set(metrics)
    assert "drift_trans_pct" in metrics and metrics["frames"] == 40
    assert 1.0 <= metrics["registrations_per_scan"] <= 4.0  # counted by the odometry itself
    sequence = open_sequence("synthetic/tiny", synthetic_root)
    stamps = read_tum(out / "odometry.tum").timestamps_ns
    np.testing.assert_array_equal(stamps, sequence.timestamps_ns[:40])


def odometry_g2o(synthetic_root: Path, path: Path, frames: int | None = None) -> int:
    """Write a g2o graph made from our odometry of synthetic/tiny; returns its vertex count."""
    run = run_odometry(open_sequence("synthetic/tiny", synthetic_root), max_frames=frames)
    poses = run.trajectory.poses
    info = np.linalg.inv(np.diag([0.05**2, 0.05**2, np.deg2rad(0.2) ** 2]))
    edges = [
        G2oEdge(k, k + 1, between(poses[k], poses[k + 1]), info) for k in range(len(poses) - 1)
    ]
    write_g2o(path, G2oGraph(dict(enumerate(poses)), edges, [0]))
    return len(poses)


def test_loops_command(
    synthetic_root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    graph = tmp_path / "odometry.g2o"
    vertices = odometry_g2o(synthetic_root, graph)
    out = tmp_path / "closed.g2o"
    args = [
        "loops",
        str(graph),
        "synthetic/tiny",
        "--data-root",
        str(synthetic_root),
        "--out",
        str(out),
    ]
    assert main(args) == 0
    assert "accepted" in capsys.readouterr().out
    result = read_g2o(out)
    assert len(result.vertices) == vertices and len(result.edges) >= vertices - 1
    assert main(args) == 1  # refuses to overwrite
    assert "--force" in capsys.readouterr().err
    assert main([*args, "--force"]) == 0
    short = tmp_path / "short.g2o"
    odometry_g2o(synthetic_root, short, frames=10)
    code = main(["loops", str(short), "synthetic/tiny", "--data-root", str(synthetic_root),
                 "--out", str(tmp_path / "x.g2o")])  # fmt: skip
    assert code == 1 and "one vertex per scan" in capsys.readouterr().err


def test_user_errors_are_one_line(
    synthetic_root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["run", "synthetic/nosuch", "--data-root", str(synthetic_root)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("radar-slam: error:") and "nosuch" in err
    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "keep.txt").write_text("mine")
    assert (
        main(["run", "synthetic/tiny", "--data-root", str(synthetic_root), "--out", str(busy)]) == 1
    )
    assert "not empty" in capsys.readouterr().err
    typo = tmp_path / "typo.yaml"
    typo.write_text("loop_closure: {verfication: {}}\n")
    args = ["odometry", "synthetic/tiny", "--data-root", str(synthetic_root), "--config", str(typo)]
    assert main([*args, "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err
    assert "unknown key 'verfication'" in err and len(err.strip().splitlines()) == 1
