"""The Rerun live viewer: a recording of synthetic/tiny_loop read back, and everything working
without rerun-sdk (the viewer says in one line how to install it)."""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from radar_slam.cli import main
from radar_slam.datasets import Sequence
from radar_slam.trajectory import read_tum
from radar_slam.viewer import INSTALL_HINT, viewer_argv
from raplace.warp import CartesianGrid, CartesianWarper

rerun_chunk = pytest.importorskip("rerun.chunk", reason="rerun-sdk (the viewer extra) missing")


def read_recording(path: Path) -> dict[str, list[dict[str, object]]]:
    """Rows of every entity of an .rrd file, by entity path, in logging order."""
    store = rerun_chunk.RrdReader(path).store()
    rows: dict[str, list[dict[str, object]]] = {}
    for chunk in store.stream():
        rows.setdefault(chunk.entity_path, []).extend(chunk.to_record_batch().to_pylist())
    for entity in rows.values():
        entity.sort(key=lambda row: (row.get("scan", -1), str(row.get("rerun.controls.RowId"))))
    return rows


def last_strip(rows: list[dict[str, object]]) -> np.ndarray:
    strips = rows[-1]["LineStrips2D:strips"]
    assert isinstance(strips, list) and len(strips) == 1
    return np.array(strips[0], dtype=np.float64)


def test_recording_holds_one_image_per_scan_and_the_final_trajectories(
    tiny_loop_runs: Path, tiny_loop: Sequence
) -> None:
    rows = read_recording(tiny_loop_runs / "viewer.rrd")
    images = rows["/radar/scan"]
    assert len(images) == 177  # one Cartesian image per scan
    assert sorted(row["scan"] for row in images) == list(range(177))
    assert images[0]["EncodedImage:media_type"] == ["image/jpeg"]
    # The first image is scan 0 in the vehicle frame, forward up, covering its full range.
    first = next(row for row in images if row["scan"] == 0)
    blob = np.array(first["EncodedImage:blob"][0], dtype=np.uint8)  # type: ignore[index]
    decoded = cv2.imdecode(blob, cv2.IMREAD_GRAYSCALE).astype(np.float32)
    frame = tiny_loop[0]
    warper = CartesianWarper(CartesianGrid(frame.max_range_m / 256, 512))
    ours = warper(frame.polar, frame.azimuths_rad, frame.range_resolution_m)
    assert decoded.shape == (512, 512)
    assert np.corrcoef(decoded.ravel(), np.clip(ours, 0, 255).ravel())[0, 1] > 0.95
    run = tiny_loop_runs / "folder"
    for entity, tum in (("/world/odometry", "odometry.tum"), ("/world/slam", "slam.tum")):
        final = last_strip(rows[entity])
        expected = read_tum(run / tum).poses[:, :2]
        assert final.shape == expected.shape
        np.testing.assert_allclose(final, expected, atol=1e-3)  # float32 in the recording
    gt = last_strip(rows["/world/gt"])
    assert gt.shape == (177, 2)
    np.testing.assert_allclose(gt[0], 0.0, atol=1e-6)  # anchored at the first odometry pose
    loops = [line.split(",") for line in (run / "loops.csv").read_text().splitlines()[1:]]
    accepted = sum(1 for row in loops if row[6] == "true")
    assert accepted > 0 and last_strip_count(rows["/world/loops/accepted"]) == accepted
    rejected = last_strip_count(rows["/world/loops/rejected"])
    assert rejected == sum(1 for row in loops if row[6] == "false")
    assert len(rows["/world/keyframes"]) >= 10


def last_strip_count(rows: list[dict[str, object]]) -> int:
    strips = rows[-1]["LineStrips2D:strips"]
    assert isinstance(strips, list)
    return len(strips)


def test_viewer_argument_takes_a_value_only_when_it_is_a_recording() -> None:
    assert viewer_argv(["run", "--viewer", "synthetic/loop"]) == [
        "run",
        "--viewer=spawn",
        "synthetic/loop",
    ]
    assert viewer_argv(["run", "synthetic/loop", "--viewer"]) == [
        "run",
        "synthetic/loop",
        "--viewer=spawn",
    ]
    assert viewer_argv(["run", "s", "--viewer", "a.rrd"]) == ["run", "s", "--viewer", "a.rrd"]


def test_without_rerun_everything_else_works_and_viewer_says_how_to_install(
    tiny: Sequence,
    synthetic_root: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    for name in [m for m in sys.modules if m == "rerun" or m.startswith("rerun.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "rerun", None)  # import rerun -> ImportError
    root = ["--data-root", str(synthetic_root)]
    out = tmp_path / "run"
    for viewer in (["--viewer"], ["--viewer", str(tmp_path / "rec.rrd")]):
        assert main(["run", "synthetic/tiny", "--out", str(out), *viewer, *root]) == 1
        error = capsys.readouterr().err.strip()
        assert error == f"radar-slam: error: {INSTALL_HINT}"
        assert "pip install 'radar-slam[viewer]'" in error and "\n" not in error
        assert not out.exists() and not (tmp_path / "rec.rrd").exists()  # no work started
    assert main(["run", "synthetic/tiny", "--out", str(out), "--max-frames", "20", *root]) == 0
    assert (out / "slam.tum").is_file()
    assert main(["export", "synthetic/tiny", "--bag", str(tmp_path / "t.bag"), *root]) == 0
