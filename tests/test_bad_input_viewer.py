"""`run --viewer` on a machine without a display, into an unusable location, and a recording
killed mid-run: one line before any work, or a complete recording under its final name only."""

from __future__ import annotations

import subprocess
import sys
import threading
from pathlib import Path

import pytest
from bad_input_support import assert_refused, run_cli

from radar_slam.datasets.frame import RadarSequence
from radar_slam.results import PARTIAL_SUFFIX

pytest.importorskip("rerun", reason="rerun-sdk (the viewer extra) missing")

FRAMES = "4"


def _run(root: Path, *extra: str | Path) -> list[str | Path]:
    return ["run", "synthetic/tiny", "--data-root", root, "--max-frames", FRAMES, *extra]


def test_viewer_without_a_display_is_refused_before_any_work(
    tiny: RadarSequence,
    synthetic_root: Path,
    workdir: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    roots = (workdir, synthetic_root)
    line = assert_refused(capsys, roots, _run(synthetic_root, "--viewer"), "no display")
    assert "--viewer out.rrd" in line and "--web-viewer" in line


@pytest.mark.parametrize("where", ["under a file", "in a missing folder", "exists"])
def test_viewer_recording_location_is_checked_before_any_work(
    where: str,
    tiny: RadarSequence,
    synthetic_root: Path,
    workdir: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    (workdir / "somefile").write_text("mine")
    (workdir / "old.rrd").write_text("mine")
    target, expected = {
        "under a file": (workdir / "somefile" / "out.rrd", "not a folder"),
        "in a missing folder": (workdir / "nodir" / "out.rrd", "does not exist"),
        "exists": (workdir / "old.rrd", "exists"),
    }[where]
    args = _run(synthetic_root, "--viewer", target)
    assert_refused(capsys, (workdir, synthetic_root), args, str(target), expected)


def test_recording_appears_only_when_complete_and_leftovers_are_removed(
    tiny: RadarSequence,
    synthetic_root: Path,
    workdir: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A killed run's `.out.rrd.partial-<pid>` is removed by the next recording run, which
    writes out.rrd and prints its path."""
    gone = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        check=True,
        capture_output=True,
        text=True,
    )
    leftover = workdir / f".out.rrd{PARTIAL_SUFFIX}{gone.stdout.strip()}"
    leftover.write_bytes(b"half a recording")
    target = workdir / "out.rrd"
    outcome = run_cli(capsys, *_run(synthetic_root, "--viewer", target, "--out", workdir / "r"))
    assert outcome.code == 0, outcome.stderr
    assert f"viewer recording in {target}" in outcome.stdout
    assert target.is_file() and target.stat().st_size > 0
    assert not [p for p in workdir.iterdir() if PARTIAL_SUFFIX in p.name]


def test_interrupted_run_leaves_no_recording(
    tiny: RadarSequence,
    synthetic_root: Path,
    workdir: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from radar_slam.viewer import RerunViewer

    def interrupted(*args: object) -> None:
        raise KeyboardInterrupt  # Ctrl-C while the first scan is being logged

    monkeypatch.setattr(RerunViewer, "on_scan", interrupted)
    target = workdir / "out.rrd"
    outcome = run_cli(capsys, *_run(synthetic_root, "--viewer", target, "--out", workdir / "r"))
    assert outcome.code == 130
    assert "Traceback" not in outcome.stderr
    assert list(workdir.iterdir()) == []
    assert not [t for t in threading.enumerate() if t.name == "loop-detector" and t.is_alive()]
