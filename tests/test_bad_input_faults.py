"""Faults: `simulate` and `run` killed (SIGINT, SIGKILL) at several points, as subprocesses on
the tiny synthetic sequence. Afterwards `latest` is the previous complete result or the new
complete one, no visible result folder is half written, and a half-written simulated sequence
is refused with one line (and replaced by `simulate --force`)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from bad_input_support import assert_one_line_error, run_cli, start

from radar_slam.datasets import open_sequence
from radar_slam.datasets.frame import RadarSequence
from radar_slam.outputs import SLAM_RESULT_FILES
from radar_slam.results import PARTIAL_SUFFIX

POLL_S = 0.002
TIMEOUT_S = 120.0
RUN_FRAMES = "6"
# the killed "running" case: the whole of `tiny`, so that writing starts seconds after the kill
RUNNING_FRAMES = "60"


def kill_when(
    process: subprocess.Popen[bytes], ready: Callable[[], bool], sig: signal.Signals
) -> bool:
    """Send `sig` once `ready()` holds; False when the process ended first (nothing killed)."""
    deadline = time.monotonic() + TIMEOUT_S
    while not ready():
        if process.poll() is not None:
            return False
        assert time.monotonic() < deadline, "the awaited file never appeared"
        time.sleep(POLL_S)
    process.send_signal(sig)
    process.wait(timeout=TIMEOUT_S)
    return True


def scans_written(folder: Path, count: int) -> Callable[[], bool]:
    polar = folder / "sensor_data" / "radar" / "polar"
    return lambda: polar.is_dir() and sum(1 for _ in polar.glob("*.png")) >= count


def after(seconds: float) -> Callable[[], bool]:
    deadline = time.monotonic() + seconds
    return lambda: time.monotonic() >= deadline


def staging_present(parent: Path) -> Callable[[], bool]:
    return lambda: parent.is_dir() and any(PARTIAL_SUFFIX in p.name for p in parent.iterdir())


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGKILL], ids=["SIGINT", "SIGKILL"])
@pytest.mark.parametrize("scans", [1, 8], ids=["first-scan", "mid-sequence"])
def test_interrupted_simulate_is_refused_then_replaced(
    sig: signal.Signals, scans: int, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "sim"
    process = start(["simulate", "tiny", "--out", out, "--frames", "20"], tmp_path)
    killed = kill_when(process, scans_written(out, scans), sig)
    marker = json.loads((out / "sim_complete.json").read_text())
    if killed and marker["complete"] is not True:
        assert process.returncode != 0
        assert_one_line_error(run_cli(capsys, "info", out), str(out), "incomplete")
        assert_one_line_error(run_cli(capsys, "run", out), str(out), "incomplete")
        # and re-simulating without --force is refused, also with one line
        refused = run_cli(capsys, "simulate", "tiny", "--out", out, "--frames", "3")
        assert_one_line_error(refused, str(out), "--force")
    redone = run_cli(capsys, "simulate", "tiny", "--out", out, "--frames", "3", "--force")
    assert redone.code == 0, redone.stderr
    assert len(open_sequence(out)) == 3
    assert not list(tmp_path.glob(".*"))  # no stray temporary files


def complete(folder: Path) -> bool:
    return all((folder / name).is_file() for name in SLAM_RESULT_FILES)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGKILL], ids=["SIGINT", "SIGKILL"])
@pytest.mark.parametrize("point", ["running", "writing"])
def test_killed_run_leaves_latest_on_a_complete_result(
    sig: signal.Signals,
    point: str,
    tiny: RadarSequence,
    synthetic_root: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.chdir(tmp_path)

    def args(frames: str) -> list[str | Path]:
        return [
            "run",
            "synthetic/tiny",
            "--data-root",
            synthetic_root,
            "--max-frames",
            frames,
            "--no-loops",
        ]

    first = run_cli(capsys, *args(RUN_FRAMES))
    assert first.code == 0, first.stderr
    parent = tmp_path / "results" / "synthetic_tiny"
    previous = (parent / "latest").resolve()
    assert complete(previous)

    process = start(args(RUNNING_FRAMES if point == "running" else RUN_FRAMES), tmp_path)
    ready = after(1.0) if point == "running" else staging_present(parent)
    killed = kill_when(process, ready, sig)

    latest = (parent / "latest").resolve()
    assert complete(latest)
    visible = [p for p in parent.iterdir() if not p.name.startswith(".") and p.name != "latest"]
    assert all(complete(folder) for folder in visible)
    assert latest in [folder.resolve() for folder in visible]
    if killed:
        assert process.returncode != 0
    if killed and point == "running":  # killed before writing: nothing new at all
        assert latest == previous
        assert len(visible) == 1
    if (point, sig) != ("writing", signal.SIGKILL):
        return
    # the next run removes what a killed one left behind and moves `latest` to its result
    again = run_cli(capsys, *args(RUN_FRAMES))
    assert again.code == 0, again.stderr
    assert not [p for p in parent.iterdir() if PARTIAL_SUFFIX in p.name]
    assert (parent / "latest").resolve() not in (previous, latest)
    assert complete((parent / "latest").resolve())


def test_interrupted_writer_leaves_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C in the middle of writing a result folder (deterministic, in-process)."""
    from radar_slam.results import write_result_dir

    monkeypatch.chdir(tmp_path)
    good = write_result_dir("f", "s", lambda f: (f / "a.txt").write_text("a"))
    latest = tmp_path / "results" / "f_s" / "latest"
    assert latest.resolve() == good.resolve()

    def half_then_interrupt(folder: Path) -> None:
        (folder / "a.txt").write_text("half")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_result_dir("f", "s", half_then_interrupt)
    assert latest.resolve() == good.resolve()
    assert sorted(p.name for p in latest.parent.iterdir()) == sorted([good.name, "latest"])
    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        write_result_dir("f", "s", half_then_interrupt, out=out)
    assert not out.exists() and not list(tmp_path.glob(".out*"))


def test_next_writer_removes_a_killed_writers_leftovers(tmp_path: Path) -> None:
    """`.<name>.partial-<pid>` of a dead process is removed by the next writer of <name>; other
    names' leftovers are not its business."""
    from radar_slam.results import write_text_atomically

    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    mine = tmp_path / f".m.json{PARTIAL_SUFFIX}{dead}"
    other = tmp_path / f".other.g2o{PARTIAL_SUFFIX}{dead}"
    mine.write_text("half")
    other.write_text("half")
    write_text_atomically(tmp_path / "m.json", "{}\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == [other.name, "m.json"]
