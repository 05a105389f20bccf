"""Partial ground truth is never stretched, header rows are found by content, skipped files are
counted, and `eval` reads integer micro/nanosecond TUM stamps."""

from __future__ import annotations

import json
import logging
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from bad_input_support import run_cli

from radar_slam.datasets import open_sequence
from radar_slam.datasets.frame import RadarSequence
from radar_slam.datasets.oxford import OxfordSequence
from radar_slam.evaluation.metrics import evaluate
from radar_slam.trajectory import Trajectory, read_tum, write_tum

FRAMES = 10
COVERED = 6
"""Scans of the tiny sequence that the truncated global_pose.csv still covers."""


def tiny_copy(tiny: RadarSequence, dest: Path) -> Path:
    """A copy of the tiny simulated sequence (MulRan layout, 1024 bins)."""
    shutil.copytree(tiny.folder, dest)  # type: ignore[attr-defined]
    return dest


def truncate_gt(folder: Path, last_scan_ns: int) -> None:
    """Keep the global_pose.csv rows up to the time of a scan (GT ends there)."""
    path = folder / "global_pose.csv"
    rows = [r for r in path.read_text().splitlines() if int(r.split(",")[0]) <= last_scan_ns]
    path.write_text("\n".join(rows) + "\n")


def test_scans_past_the_gt_have_none_and_ate_equals_the_full_gt_one(
    tiny: RadarSequence,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Known answer: odometry ATE with GT ending after scan COVERED-1 equals the ATE of the same
    odometry over those scans with the full GT; the other scans are counted as without GT."""
    full = tiny_copy(tiny, tmp_path / "full")
    partial = tiny_copy(tiny, tmp_path / "partial")
    stamps = open_sequence(full).timestamps_ns
    truncate_gt(partial, int(stamps[COVERED - 1]))
    gt_partial = open_sequence(partial).ground_truth
    gt_full = open_sequence(full).ground_truth
    assert gt_partial is not None and gt_full is not None
    np.testing.assert_allclose(gt_partial[:COVERED], gt_full[:COVERED], atol=1e-9)
    assert np.isnan(gt_partial[COVERED:]).all()  # not the end pose, stretched

    monkeypatch.chdir(tmp_path)
    outcome = run_cli(capsys, "odometry", partial, "--max-frames", FRAMES, "--out", "res")
    assert outcome.code == 0, outcome.stderr
    metrics = json.loads((tmp_path / "res" / "metrics.json").read_text())
    assert metrics["scans_with_gt"] == COVERED
    assert metrics["scans_without_gt"] == FRAMES - COVERED
    assert len(read_tum(tmp_path / "res" / "gt.tum")) == len(
        (tmp_path / "res" / "gt.kitti").read_text().splitlines()
    )  # gt.kitti too, for `eval --format kitti`
    summary = (tmp_path / "res" / "summary.txt").read_text()
    assert f"accuracy over {COVERED} of {FRAMES} scans ({FRAMES - COVERED} without" in summary

    odometry = read_tum(tmp_path / "res" / "odometry.tum")
    reference = Trajectory(stamps[:COVERED], gt_full[:COVERED])
    expected = evaluate(odometry[:COVERED], reference).ate_rmse_m
    assert metrics["ate_rmse_m"] == pytest.approx(expected, rel=1e-9, abs=1e-12)
    # what stretching would have given: the end pose for every later scan
    stretched = np.vstack([gt_full[:COVERED], np.repeat(gt_full[COVERED - 1 : COVERED], 4, 0)])
    wrong = evaluate(odometry, Trajectory(stamps[:FRAMES], stretched)).ate_rmse_m
    assert wrong > 3 * expected + 0.05


def test_oxford_gt_without_its_header_row_keeps_its_first_row(
    oxford_dir: Path, tmp_path: Path
) -> None:
    folder = tmp_path / "seq"
    shutil.copytree(oxford_dir, folder)
    gt_file = folder / "gt" / "radar_odometry.csv"
    with_header = OxfordSequence(folder).ground_truth
    gt_file.write_text("\n".join(gt_file.read_text().splitlines()[1:]) + "\n")
    without_header = OxfordSequence(folder).ground_truth
    assert with_header is not None and without_header is not None
    assert np.isfinite(without_header).all()
    np.testing.assert_array_equal(without_header, with_header)


def test_oxford_scan_not_in_the_timestamps_is_counted(
    oxford_dir: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    folder = tmp_path / "seq"
    shutil.copytree(oxford_dir, folder)
    extra = sorted((folder / "radar").glob("*.png"))[-1]
    shutil.copyfile(extra, folder / "radar" / "1547131099999999.png")
    with caplog.at_level(logging.WARNING):
        sequence = OxfordSequence(folder)
    assert len(sequence) == 7
    lines = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(lines) == 1 and "ignored 1 scan(s)" in lines[0]
    assert "1547131099999999.png" in lines[0] and "radar.timestamps" in lines[0]


def test_scan_files_with_other_names_are_counted(
    tiny: RadarSequence, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    folder = tiny_copy(tiny, tmp_path / "seq")
    polar = folder / "sensor_data" / "radar" / "polar"
    first = sorted(polar.glob("*.png"))[0]
    shutil.copyfile(first, polar / "scan_a.png")
    shutil.copyfile(first, polar / "12x34.png")
    (polar / "notes.txt").write_text("mine")
    with caplog.at_level(logging.WARNING):
        sequence = open_sequence(folder)
    assert len(sequence) == len(tiny)
    lines = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(lines) == 1 and "ignored 3 file(s)" in lines[0] and str(polar) in lines[0]


@pytest.mark.parametrize(("unit", "per_second"), [("microseconds", 10**6), ("nanoseconds", 10**9)])
def test_eval_reads_integer_tum_stamps(
    unit: str,
    per_second: int,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The same trajectories in integer us or ns give the same ATE as in seconds."""
    start_ns = 1_564_718_976_161_407_000
    t = start_ns + np.arange(8, dtype=np.int64) * 250_000_000
    gt = Trajectory(t, np.column_stack([np.arange(8.0), np.zeros(8), np.zeros(8)]))
    error = np.column_stack([np.zeros(8), 0.1 * np.sin(np.arange(8)), np.zeros(8)])
    est = Trajectory(t, gt.poses + error)
    write_tum(tmp_path / "gt.tum", gt)
    write_tum(tmp_path / "est.tum", est)
    scale = 10**9 // per_second
    for name, trajectory in (("gt", gt), ("est", est)):
        rows = (tmp_path / f"{name}.tum").read_text().splitlines()
        (tmp_path / f"{name}_int.tum").write_text(
            "".join(
                f"{stamp // scale} {row.split(' ', 1)[1]}\n"
                for stamp, row in zip(trajectory.timestamps_ns.tolist(), rows, strict=True)
            )
        )
    seconds = run_cli(capsys, "eval", tmp_path / "est.tum", tmp_path / "gt.tum")
    with caplog.at_level(logging.WARNING):
        integers = run_cli(capsys, "eval", tmp_path / "est_int.tum", tmp_path / "gt_int.tum")
    assert seconds.code == 0 and integers.code == 0, integers.stderr
    ate = [line for line in seconds.stdout.splitlines() if line.startswith("est ")]
    ate_int = [line for line in integers.stdout.splitlines() if line.startswith("est_int ")]
    assert ate and ate_int and ate[0].split()[1:] == ate_int[0].split()[1:]
    assert f"integer timestamps read as {unit}" in caplog.text
    np.testing.assert_array_equal(read_tum(tmp_path / "gt_int.tum").timestamps_ns, t)


GT_EVERY = 25
"""Rows of tiny's 100 Hz global_pose.csv kept for a 4 Hz ground truth ..."""
GT_OFFSET = 12
"""... starting 0.12 s in, so that every scan lies between two GT samples."""


def thin_gt(folder: Path, keep: Callable[[int], bool] = lambda t: True) -> None:
    """Keep every GT_EVERY-th global_pose.csv row from GT_OFFSET on whose time passes `keep`."""
    path = folder / "global_pose.csv"
    rows = path.read_text().splitlines()[GT_OFFSET::GT_EVERY]
    path.write_text("\n".join(r for r in rows if keep(int(r.split(",")[0]))) + "\n")


@pytest.mark.parametrize("where", ["end", "outage"])
def test_scans_beyond_a_coarse_gt_have_none_and_the_ate_is_the_full_gt_one(
    where: str,
    tiny: RadarSequence,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Known answer with a 4 Hz GT (tolerance 0.25 s): GT ending 0.13 s before scan COVERED
    (which the end pose would have been held for), or an outage of 2 s; the scans there have
    no GT and are counted, and the ATE over the others is the one with the whole 4 Hz GT."""
    full = tiny_copy(tiny, tmp_path / "full")
    partial = tiny_copy(tiny, tmp_path / "partial")
    thin_gt(full)
    stamps = open_sequence(full).timestamps_ns
    if where == "end":
        last = int(stamps[COVERED - 1]) + 120_000_000
        thin_gt(partial, lambda t: t <= last)
    else:
        start, stop = int(stamps[3]) - 200_000_000, int(stamps[8]) + 200_000_000
        thin_gt(partial, lambda t: not start < t < stop)
    gt_full = open_sequence(full).ground_truth
    gt_partial = open_sequence(partial).ground_truth
    assert gt_full is not None and gt_partial is not None
    has_gt = np.isfinite(gt_partial[:FRAMES, 0])
    expected_missing = FRAMES - COVERED if where == "end" else 8  # scans 2..9
    assert int((~has_gt).sum()) == expected_missing

    monkeypatch.chdir(tmp_path)
    outcome = run_cli(capsys, "odometry", partial, "--max-frames", FRAMES, "--out", "res")
    assert outcome.code == 0, outcome.stderr
    metrics = json.loads((tmp_path / "res" / "metrics.json").read_text())
    assert metrics["scans_without_gt"] == expected_missing
    odometry = read_tum(tmp_path / "res" / "odometry.tum")
    mask = np.flatnonzero(has_gt)
    reference = Trajectory(stamps[mask], gt_full[mask])
    expected = evaluate(odometry[mask], reference).ate_rmse_m
    assert abs(metrics["ate_rmse_m"] - expected) < 1e-3
