"""Signals at any time, start-up included: SIGINT ends with exit code 130 and SIGTERM with 143,
one line on stderr, no traceback, and nothing left under --out."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from radar_slam.datasets.frame import RadarSequence
from radar_slam.signals import SIGINT_EXIT_CODE, SIGTERM_EXIT_CODE

TIMEOUT_S = 120.0
POLL_S = 0.01
STARTUP_S = 0.3
"""Well inside the loading of the app's modules (several seconds on a busy machine)."""
EXIT_CODES = {signal.SIGINT: SIGINT_EXIT_CODE, signal.SIGTERM: SIGTERM_EXIT_CODE}
RECORDING_STARTED_BYTES = 100_000
"""A viewer recording this large holds a few scans: the run is working."""


def _recording_started(work: Path) -> bool:
    staged = list(work.glob(".out.rrd.partial-*"))
    return bool(staged) and staged[0].stat().st_size > RECORDING_STARTED_BYTES


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)  # as in a terminal, not a background job


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("when", ["start-up", "working"])
def test_signal_ends_with_its_exit_code_and_one_line(
    sig: signal.Signals,
    when: str,
    tiny: RadarSequence,
    synthetic_root: Path,
    tmp_path: Path,
) -> None:
    work = tmp_path / "work"
    work.mkdir()
    log = tmp_path / "stderr.txt"
    args = ["run", "synthetic/tiny", "--data-root", str(synthetic_root), "--out", "res"]
    if when == "working":  # the temporary recording shows when the scans are being processed
        pytest.importorskip("rerun", reason="rerun-sdk (the viewer extra) missing")
        args += ["--viewer", "out.rrd"]
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    with log.open("wb") as stderr:
        process = subprocess.Popen(
            [sys.executable, "-m", "radar_slam.cli", *args],
            cwd=work,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=stderr,
            preexec_fn=_default_sigint,
        )
        deadline = time.monotonic() + (STARTUP_S if when == "start-up" else TIMEOUT_S)
        while time.monotonic() < deadline and process.poll() is None:
            if when == "working" and _recording_started(work):
                break
            time.sleep(POLL_S)
        if process.poll() is not None:
            pytest.skip("the run ended before the signal")
        process.send_signal(sig)
        process.wait(timeout=TIMEOUT_S)
    if when == "start-up" and process.returncode < 0:  # died by a signal while starting
        pytest.skip("the signal arrived before the handlers were in place (a busy machine)")
    text = log.read_text(errors="replace")
    assert process.returncode == EXIT_CODES[sig], text
    assert "Traceback" not in text
    lines = [line for line in re.split(r"[\r\n]", text) if line.strip() and "%|" not in line]
    word = "terminated" if sig == signal.SIGTERM else "interrupted"
    assert lines == [f"radar-slam: {word}"], text
    assert list(work.iterdir()) == []
