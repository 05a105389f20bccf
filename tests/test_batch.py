"""`radar-slam batch`: a local Dask cluster of 2 workers gives the same metrics as separate `run`s;
a failed run is a row with its error; a grid of two configurations doubles the rows; bad input is
rejected before any task starts."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import pytest
from distributed import LocalCluster

from radar_slam.batch import SUMMARY_COLUMNS, parse_grid, read_grid
from radar_slam.cli import main
from radar_slam.datasets.frame import RadarSequence
from radar_slam.errors import ConfigError

MAX_FRAMES = 160
"""Enough of tiny_loop to reach its revisit (loops from about scan 140)."""
THIRD_SEED, THIRD_FRAMES = 12, 30
"""A third small sequence: `tiny` simulated with another seed, written as a plain folder."""
TIMING_KEYS = {"seconds", "frames_per_second"}


def read_rows(folder: Path) -> list[dict[str, str]]:
    with (folder / "summary.csv").open() as handle:
        return list(csv.DictReader(handle))


@pytest.fixture(scope="module")
def third_sequence(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("third") / "tiny_seed12"
    args = ["simulate", "tiny", "--out", str(folder), "--seed", str(THIRD_SEED)]
    assert main([*args, "--frames", str(THIRD_FRAMES)]) == 0
    return folder


def test_batch_equals_separate_runs(
    synthetic_root: Path, third_sequence: Path, tmp_path: Path
) -> None:
    specs = ["synthetic/tiny", "synthetic/tiny_loop", str(third_sequence)]
    common = ["--data-root", str(synthetic_root), "--max-frames", str(MAX_FRAMES)]
    batch = tmp_path / "batch"
    assert main(["batch", *specs, *common, "--workers", "2", "--out", str(batch)]) == 0
    rows = read_rows(batch)
    assert [r["sequence"] for r in rows] == [
        "synthetic/tiny",
        "synthetic/tiny_loop",
        "synthetic/tiny_seed12",
    ]
    assert all(r["status"] == "ok" and r["config"] == "default" for r in rows)
    assert (batch / "summary.md").read_text().count("| ok |") == 3
    assert (batch / "summary.png").stat().st_size > 0
    for spec, row in zip(specs, rows, strict=True):
        single = tmp_path / f"single_{Path(spec).name}"
        assert main(["run", spec, *common, "--out", str(single)]) == 0
        expected = json.loads((single / "metrics.json").read_text())
        got = json.loads((Path(row["folder"]) / "metrics.json").read_text())
        assert set(got) == set(expected)
        for key in set(expected) - TIMING_KEYS:
            if expected[key] is None or isinstance(expected[key], dict):
                assert got[key] == expected[key], key
            else:
                assert got[key] == pytest.approx(expected[key], rel=1e-9, abs=1e-12), key
        assert float(row["ate_slam_m"]) == pytest.approx(expected["ate_slam_m"])
        assert int(row["loops_accepted"]) == expected["loops_accepted"]
        assert float(row["scans_per_s"]) > 0
    tiny_loop = json.loads((Path(rows[1]["folder"]) / "metrics.json").read_text())
    assert tiny_loop["loops_accepted"] >= 3
    assert tiny_loop["loops_accepted_true"] == tiny_loop["loops_accepted"]


def damaged_copy(source: Path, destination: Path) -> Path:
    """A copy of a sequence whose 6th scan is truncated (found, but unreadable mid-run)."""
    shutil.copytree(source, destination)
    scans = sorted((destination / "sensor_data" / "radar" / "polar").glob("*.png"))
    scans[5].write_bytes(scans[5].read_bytes()[:100])
    return destination


def test_failed_run_is_a_row_and_grid_doubles_rows_on_a_scheduler(
    synthetic_root: Path, tiny: RadarSequence, tmp_path: Path
) -> None:
    damaged = damaged_copy(synthetic_root / "synthetic" / "tiny", tmp_path / "damaged")
    grid = tmp_path / "grid.yaml"
    grid.write_text("configs:\n  near: {}\n  far:\n    loop_closure: {query_spacing_m: 8.0}\n")
    out = tmp_path / "batch"
    args = ["batch", "synthetic/tiny", str(damaged), "--grid", str(grid), "--out", str(out)]
    # An existing cluster, reached by its tcp:// address (as a cluster of machines would be).
    with LocalCluster(
        n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tcp://")
        args += ["--data-root", str(synthetic_root), "--max-frames", "12"]
        code = main([*args, "--scheduler", address])
    assert code == 1  # some runs failed: reported after the summary is written
    rows = read_rows(out)
    assert list(rows[0]) == list(SUMMARY_COLUMNS)
    assert [(r["sequence"], r["config"], r["status"]) for r in rows] == [
        ("synthetic/tiny", "near", "ok"),
        ("synthetic/tiny", "far", "ok"),
        ("synthetic/damaged", "near", "failed"),
        ("synthetic/damaged", "far", "failed"),
    ]
    for row in rows[2:]:
        assert "cannot decode PNG" in row["error"] and "\n" not in row["error"]
        assert row["folder"] == "" and row["ate_slam_m"] == ""
    far = (out / "synthetic_tiny" / "far" / "config.yaml").read_text()
    assert "query_spacing_m: 8.0" in far
    assert float(rows[0]["ate_odometry_m"]) < 0.2
    assert not list(out.rglob(".partial-*"))  # no half-written folder left


def test_bad_input_is_rejected_before_any_task(
    synthetic_root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "never"
    root = ["--data-root", str(synthetic_root), "--out", str(out)]
    assert main(["batch", "synthetic/tiny", "mulran/NOPE", *root]) == 1
    assert "NOPE" in capsys.readouterr().err
    grid = tmp_path / "grid.yaml"
    grid.write_text("configs:\n  a:\n    odometry: {keyframe: {max_distanc: 2}}\n")
    assert main(["batch", "synthetic/tiny", "--grid", str(grid), *root]) == 1
    err = capsys.readouterr().err
    assert f"{grid}: a: odometry.keyframe: unknown key 'max_distanc'" in err
    assert len(err.strip().splitlines()) == 1
    assert main(["batch", "synthetic/tiny", "synthetic/tiny", *root]) == 1
    assert "given twice" in capsys.readouterr().err
    assert main(["batch", "synthetic/tiny", "--scheduler", "localhost", *root]) == 1
    assert "tcp://" in capsys.readouterr().err
    assert not out.exists()
    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "mine.txt").write_text("keep")
    assert main(["batch", "synthetic/tiny", "--data-root", str(synthetic_root), "--out", str(busy)])
    assert "not empty" in capsys.readouterr().err
    assert (busy / "mine.txt").read_text() == "keep"


def test_grid_product_and_named_sets() -> None:
    data = {
        "configs": {"base": None, "lm": {"graph": {"final_pass": "lm"}}},
        "product": {
            "loop_closure.max_descriptor_distance": [0.2, 0.3],
            "odometry.keyframe.max_translation_m": [3.0],
        },
    }
    points = parse_grid(data, "g.yaml")
    assert [p.name for p in points] == [
        "base+max_descriptor_distance=0.2+max_translation_m=3.0",
        "base+max_descriptor_distance=0.3+max_translation_m=3.0",
        "lm+max_descriptor_distance=0.2+max_translation_m=3.0",
        "lm+max_descriptor_distance=0.3+max_translation_m=3.0",
    ]
    assert points[3].overrides == {
        "graph": {"final_pass": "lm"},
        "loop_closure": {"max_descriptor_distance": 0.3},
        "odometry": {"keyframe": {"max_translation_m": 3.0}},
    }
    assert [p.name for p in read_grid(None)] == ["default"]
    with pytest.raises(ConfigError, match="g.yaml: unknown section 'config'"):
        parse_grid({"config": {}}, "g.yaml")
    with pytest.raises(ConfigError, match="product.graph.final_pass: expected a non-empty list"):
        parse_grid({"product": {"graph.final_pass": "lm"}}, "g.yaml")
    with pytest.raises(ConfigError, match="'a b'"):
        parse_grid({"configs": {"a b": {}}}, "g.yaml")
