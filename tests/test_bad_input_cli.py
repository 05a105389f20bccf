"""Bad command lines, output locations, datasets and trajectory files: exit code 1, one line
naming the file (or option), no traceback, and no file changed or created anywhere."""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest
from bad_input_support import (
    assert_refused,
)

from radar_slam.datasets.frame import RadarSequence

Setup = Callable[[Path, Path], tuple[list[str | Path], list[str]]]
"""(work folder, synthetic data root) -> (arguments, texts the error line must contain)."""

TUM_OK = "".join(f"{k}.0 {k}.0 0 0 0 0 0 1\n" for k in range(5))


def _file(path: Path, text: str = "mine\n") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def _tum(work: Path, name: str, text: str) -> Path:
    return _file(work / name, text)


def _bytes(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def _tiny_with(change: Callable[[Path], object], command: str = "run") -> Setup:
    """A copy of synthetic/tiny altered by `change(folder)`, given to `command`."""

    def setup(work: Path, root: Path) -> tuple[list[str | Path], list[str]]:
        folder = work / "seq"
        shutil.copytree(root / "synthetic" / "tiny", folder)
        expected = change(folder)
        return [command, folder, "--out", work / "res"], [str(expected)]

    return setup


def _append(relative: str, text: str) -> Callable[[Path], object]:
    def change(folder: Path) -> object:
        with (folder / relative).open("a") as handle:
            handle.write(text)
        return relative

    return change


def _remove(relative: str) -> Callable[[Path], object]:
    def change(folder: Path) -> object:
        (folder / relative).unlink()
        return folder.name

    return change


def _results_is_a_file(command: str) -> Setup:
    def setup(work: Path, root: Path) -> tuple[list[str | Path], list[str]]:
        _file(work / "results")
        return [command, "synthetic/tiny", "--data-root", root], ["results", "not a folder"]

    return setup


CASES: dict[str, Setup] = {
    # ---- numbers on the command line
    "run --max-frames 0": lambda w, r: (
        ["run", "synthetic/tiny", "--max-frames", "0", "--data-root", r],
        ["--max-frames"],
    ),
    "run --max-frames -3": lambda w, r: (
        ["run", "synthetic/tiny", "--max-frames", "-3", "--data-root", r],
        ["--max-frames"],
    ),
    "run --max-frames abc": lambda w, r: (
        ["run", "synthetic/tiny", "--max-frames", "abc", "--data-root", r],
        ["--max-frames"],
    ),
    "odometry --max-frames 0": lambda w, r: (
        ["odometry", "synthetic/tiny", "--max-frames", "0", "--data-root", r],
        ["--max-frames"],
    ),
    "simulate --seed -1": lambda w, r: (
        ["simulate", "tiny", "--out", w / "s", "--seed", "-1"],
        ["--seed"],
    ),
    "simulate --frames 0": lambda w, r: (
        ["simulate", "tiny", "--out", w / "s", "--frames", "0"],
        ["--frames"],
    ),
    "simulate --frames too many": lambda w, r: (
        ["simulate", "tiny", "--out", w / "s", "--frames", "100000"],
        ["100000 requested"],
    ),
    "simulate unknown scenario": lambda w, r: (
        ["simulate", "nowhere", "--out", w / "s"],
        ["nowhere"],
    ),
    "eval --rpe-delta 0": lambda w, r: (
        ["eval", _tum(w, "a.tum", TUM_OK), _tum(w, "b.tum", TUM_OK), "--rpe-delta", "0"],
        ["--rpe-delta"],
    ),
    "eval --max-diff-ms -1": lambda w, r: (
        ["eval", _tum(w, "a.tum", TUM_OK), _tum(w, "b.tum", TUM_OK), "--max-diff-ms", "-1"],
        ["--max-diff-ms"],
    ),
    "eval --max-diff-ms inf": lambda w, r: (
        ["eval", _tum(w, "a.tum", TUM_OK), _tum(w, "b.tum", TUM_OK), "--max-diff-ms", "inf"],
        ["--max-diff-ms"],
    ),
    "pr --criterion inf": lambda w, r: (
        ["pr", "synthetic/tiny", "--criterion", "inf", "--data-root", r],
        ["--criterion"],
    ),
    "pr --exclude-seconds inf": lambda w, r: (
        ["pr", "synthetic/tiny", "--exclude-seconds", "inf", "--data-root", r],
        ["--exclude-seconds"],
    ),
    "pr --criterion -1": lambda w, r: (
        ["pr", "synthetic/tiny", "--criterion", "-1", "--data-root", r],
        ["--criterion"],
    ),
    "pr --exclude-recent -1": lambda w, r: (
        ["pr", "synthetic/tiny", "--exclude-recent", "-1", "--data-root", r],
        ["--exclude-recent"],
    ),
    "pr --exclude-seconds nan": lambda w, r: (
        ["pr", "synthetic/tiny", "--exclude-seconds", "nan", "--data-root", r],
        ["--exclude-seconds"],
    ),
    "unknown option": lambda w, r: (["run", "synthetic/tiny", "--frobnicate"], ["--frobnicate"]),
    "unknown command": lambda w, r: (["frobnicate"], ["frobnicate"]),
    "missing argument": lambda w, r: (["run"], ["sequence"]),
    "--config missing": lambda w, r: (
        ["run", "synthetic/tiny", "--config", w / "none.yaml", "--data-root", r],
        ["none.yaml"],
    ),
    "--config is a folder": lambda w, r: (
        ["run", "synthetic/tiny", "--config", w, "--data-root", r],
        ["--config"],
    ),
    # ---- output locations, checked before any work
    "run --out not empty": lambda w, r: (
        ["run", "synthetic/tiny", "--out", _file(w / "out" / "keep.txt").parent, "--data-root", r],
        ["out", "not empty"],
    ),
    "run --out is a file": lambda w, r: (
        ["run", "synthetic/tiny", "--out", _file(w / "file.txt"), "--data-root", r],
        ["file.txt"],
    ),
    "run --out under a file": lambda w, r: (
        ["run", "synthetic/tiny", "--out", _file(w / "file.txt") / "sub", "--data-root", r],
        ["file.txt", "not a folder"],
    ),
    "odometry --out under a file": lambda w, r: (
        ["odometry", "synthetic/tiny", "--out", _file(w / "f.txt") / "a" / "b", "--data-root", r],
        ["f.txt", "not a folder"],
    ),
    "run: results/ is a file": _results_is_a_file("run"),
    "odometry: results/ is a file": _results_is_a_file("odometry"),
    "pr --out not empty": lambda w, r: (
        ["pr", "synthetic/tiny", "--out", _file(w / "pr" / "k.txt").parent, "--data-root", r],
        ["pr", "not empty"],
    ),
    "simulate --out not empty": lambda w, r: (
        ["simulate", "tiny", "--out", _file(w / "sim" / "k.txt").parent],
        ["sim", "not empty"],
    ),
    "simulate --out is a file": lambda w, r: (
        ["simulate", "tiny", "--out", _file(w / "sim.txt")],
        ["sim.txt", "not a folder"],
    ),
    "simulate --out under a file": lambda w, r: (
        ["simulate", "tiny", "--out", _file(w / "sim.txt") / "x"],
        ["sim.txt", "not a folder"],
    ),
    "simulate --force on a user's folder": lambda w, r: (
        ["simulate", "tiny", "--out", _file(w / "mine" / "notes.txt").parent, "--force"],
        ["mine", "not a simulated sequence"],
    ),
    "eval --json into a missing folder": lambda w, r: (
        [
            "eval",
            _tum(w, "a.tum", TUM_OK),
            _tum(w, "b.tum", TUM_OK),
            "--json",
            w / "nowhere" / "m.json",
        ],
        ["m.json", "does not exist"],
    ),
    "eval --json under a file": lambda w, r: (
        [
            "eval",
            _tum(w, "a.tum", TUM_OK),
            _tum(w, "b.tum", TUM_OK),
            "--json",
            _file(w / "f.txt") / "m.json",
        ],
        ["m.json"],
    ),
    "eval --json exists": lambda w, r: (
        ["eval", _tum(w, "a.tum", TUM_OK), _tum(w, "b.tum", TUM_OK), "--json", _file(w / "m.json")],
        ["m.json", "exists"],
    ),
    "loops --out exists": lambda w, r: (
        [
            "loops",
            _file(w / "in.g2o", "VERTEX_SE2 0 0 0 0\n"),
            "synthetic/tiny",
            "--out",
            _file(w / "out.g2o"),
            "--data-root",
            r,
        ],
        ["out.g2o", "exists"],
    ),
    "loops --out in a missing folder": lambda w, r: (
        [
            "loops",
            _file(w / "in.g2o", "VERTEX_SE2 0 0 0 0\n"),
            "synthetic/tiny",
            "--out",
            w / "nowhere" / "out.g2o",
            "--data-root",
            r,
        ],
        ["out.g2o", "does not exist"],
    ),
    "synthetic under an unwritable data root": lambda w, r: (
        ["run", "synthetic/loop", "--data-root", _file(w / "root" / "synthetic").parent],
        ["synthetic", "not a folder"],
    ),
    # ---- sequences
    "unknown mulran sequence": lambda w, r: (
        ["run", "mulran/NOPE", "--data-root", w / "data"],
        ["NOPE"],
    ),
    "unknown synthetic scenario": lambda w, r: (
        ["run", "synthetic/nowhere", "--data-root", r],
        ["nowhere"],
    ),
    "folder that is no sequence": lambda w, r: (
        ["info", _file(w / "empty" / "x.txt").parent],
        ["empty"],
    ),
    "malformed global_pose.csv (before the run)": _tiny_with(_append("global_pose.csv", "1,2\n")),
    "non-numeric global_pose.csv": _tiny_with(
        _append("global_pose.csv", "9" * 19 + ",x" + ",0" * 11 + "\n"), "odometry"
    ),
    "global_pose.csv out of order": _tiny_with(
        _append("global_pose.csv", "1" + ",0" * 12 + "\n"), "odometry"
    ),
    "stamp list with text": _tiny_with(_append("sensor_data/navtech_top_stamp.csv", "soon\n")),
    "marker removed, scans kept": _tiny_with(_remove("sim_complete.json")),
    # ---- trajectory files
    "eval: one file": lambda w, r: (["eval", _tum(w, "a.tum", TUM_OK)], ["ground truth"]),
    "eval: non-numeric": lambda w, r: (
        ["eval", _tum(w, "a.tum", "0 0 0 0 0 0 0 x\n1 0 0 0 0 0 0 1\n"), _tum(w, "b.tum", TUM_OK)],
        ["a.tum"],
    ),
    "eval: wrong columns": lambda w, r: (
        ["eval", _tum(w, "a.tum", "0 0 0\n1 0 0\n"), _tum(w, "b.tum", TUM_OK)],
        ["a.tum"],
    ),
    "eval: decreasing stamps": lambda w, r: (
        ["eval", _tum(w, "a.tum", "1 0 0 0 0 0 0 1\n0 0 0 0 0 0 0 1\n"), _tum(w, "b.tum", TUM_OK)],
        ["a.tum", "increas"],
    ),
    "eval: zero quaternion": lambda w, r: (
        ["eval", _tum(w, "a.tum", "0 0 0 0 0 0 0 0\n1 0 0 0 0 0 0 1\n"), _tum(w, "b.tum", TUM_OK)],
        ["a.tum", "quaternion"],
    ),
    "eval: stamps beyond int64 ns": lambda w, r: (
        [
            "eval",
            _tum(w, "a.tum", "99999999999999999999 0 0 0 0 0 0 1\n"),
            _tum(w, "b.tum", TUM_OK),
        ],
        ["a.tum"],
    ),
    "eval: empty file": lambda w, r: (
        ["eval", _tum(w, "a.tum", ""), _tum(w, "b.tum", TUM_OK)],
        ["a.tum"],
    ),
    "eval: no common stamps": lambda w, r: (
        [
            "eval",
            _tum(w, "a.tum", "".join(f"{100 + k}.0 0 0 0 0 0 0 1\n" for k in range(5))),
            _tum(w, "b.tum", TUM_OK),
        ],
        ["a.tum"],
    ),
    "eval: a g2o pose graph": lambda w, r: (
        [
            "eval",
            _tum(w, "out.g2o", "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n"),
            _tum(w, "b.tum", TUM_OK),
        ],
        ["out.g2o", "g2o pose graph", "no timestamps"],
    ),
    "eval: not UTF-8": lambda w, r: (
        ["eval", _bytes(w / "a.tum", b"\xff\xfe\x00 1\n"), _tum(w, "b.tum", TUM_OK)],
        ["a.tum"],
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_bad_input_is_one_line_and_changes_nothing(
    case: str,
    tiny: RadarSequence,
    synthetic_root: Path,
    workdir: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    args, expected = CASES[case](workdir, synthetic_root)
    assert_refused(capsys, (workdir, synthetic_root), args, *expected)


# ---------------------------------------------------------------- simulated sequences on disk


def _copy_tiny(tiny: RadarSequence, dest: Path) -> Path:
    shutil.copytree(tiny.folder, dest)  # type: ignore[attr-defined]
    return dest


def test_incomplete_simulated_sequence_is_refused(
    tiny: RadarSequence, workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = _copy_tiny(tiny, workdir / "half")
    marker = folder / "sim_complete.json"
    marker.write_text(marker.read_text().replace('"complete": true', '"complete": false'))
    commands: list[list[str | Path]] = [["info", folder], ["run", folder, "--max-frames", "2"]]
    for command in commands:
        assert_refused(capsys, (workdir,), command, "half", "incomplete", "--force")


def test_simulated_sequence_missing_a_scan_is_refused(
    tiny: RadarSequence, workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = _copy_tiny(tiny, workdir / "gap")
    scans = sorted((folder / "sensor_data/radar/polar").glob("*.png"))
    scans[5].unlink()
    expected = (f"{len(scans) - 1} scans found", f"{len(scans)}")
    assert_refused(capsys, (workdir,), ["info", folder], "gap", *expected)


def test_simulate_force_keeps_a_users_file(
    tiny: RadarSequence, workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = _copy_tiny(tiny, workdir / "sim")
    _file(folder / "my_notes.txt")
    args: list[str | Path] = ["simulate", "tiny", "--out", folder, "--force", "--frames", "2"]
    assert_refused(capsys, (workdir,), args, "sim", "my_notes.txt")


def test_regenerating_synthetic_never_deletes_a_users_file(
    tiny: RadarSequence, workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A synthetic/<name> folder without its marker and with a user's file is not regenerated."""
    root = workdir / "data"
    folder = _copy_tiny(tiny, root / "synthetic" / "tiny")
    (folder / "sim_complete.json").unlink()
    _file(folder / "my_notes.txt")
    args: list[str | Path] = ["info", "synthetic/tiny", "--data-root", root]
    assert_refused(capsys, (workdir,), args, "tiny", "my_notes.txt")


def test_zeroed_navtech_headers_name_the_file(
    oxford_dir: Path, workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import cv2

    folder = workdir / "oxford_seq"
    shutil.copytree(oxford_dir, folder)
    first = sorted((folder / "radar").glob("*.png"))[0]
    image = cv2.imread(str(first), cv2.IMREAD_UNCHANGED)
    assert image is not None
    image[:, :11] = 0
    assert cv2.imwrite(str(first), image)
    assert_refused(capsys, (workdir,), ["info", folder], first.name, "header")


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write into read-only folders")
@pytest.mark.parametrize("command", ["run", "odometry"])
def test_read_only_output_location(
    command: str,
    tiny: RadarSequence,
    synthetic_root: Path,
    workdir: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    locked = workdir / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        args: list[str | Path] = [command, "synthetic/tiny", "--out", locked / "res"]
        roots = (workdir, synthetic_root)
        args += ["--data-root", synthetic_root]
        assert_refused(capsys, roots, args, "locked", "not writable")
    finally:
        locked.chmod(0o700)


@pytest.mark.parametrize("spec", ["tyni", "synthetic/tyni", "nothing_like_it"])
def test_mistyped_sequence_is_a_short_line_with_the_closest_names(
    spec: str,
    tiny: RadarSequence,
    synthetic_root: Path,
    workdir: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    args: list[str | Path] = ["info", spec, "--data-root", synthetic_root]
    line = assert_refused(capsys, (workdir, synthetic_root), args, spec)
    assert len(line) < 400, line
    assert "radar-slam list" in line or "simulate --help" in line
    if spec == "nothing_like_it":
        assert "closest" not in line
    else:
        assert "tiny" in line.split("closest: ")[1]
