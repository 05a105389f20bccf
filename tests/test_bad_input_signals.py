"""Signals at any time, start-up included: SIGINT ends with exit code 130 and SIGTERM with 143,
one line on stderr, no traceback, and nothing left under --out."""

from __future__ import annotations

import signal
import time
from pathlib import Path

import pytest
from bad_input_support import start

from radar_slam.datasets.frame import RadarSequence
from radar_slam.signals import SIGINT_EXIT_CODE, SIGTERM_EXIT_CODE

TIMEOUT_S = 120.0
EXIT_CODES = {signal.SIGINT: SIGINT_EXIT_CODE, signal.SIGTERM: SIGTERM_EXIT_CODE}


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("delay_s", [0.3, 4.0], ids=["early", "later"])
def test_signal_ends_with_its_exit_code_and_one_line(
    sig: signal.Signals,
    delay_s: float,
    tiny: RadarSequence,
    synthetic_root: Path,
    tmp_path: Path,
) -> None:
    out = tmp_path / "res"
    args: list[str | Path] = ["run", "synthetic/tiny", "--data-root", synthetic_root, "--out", out]
    process = start(args, tmp_path)
    time.sleep(delay_s)
    if process.poll() is not None:
        pytest.skip("the run ended before the signal")
    process.send_signal(sig)
    _, stderr = process.communicate(timeout=TIMEOUT_S)
    text = stderr.decode()
    assert process.returncode == EXIT_CODES[sig], text
    assert "Traceback" not in text
    lines = [line for line in text.splitlines() if line.strip() and "%|" not in line]
    assert lines[-1:] == [
        "radar-slam: " + ("terminated" if sig == signal.SIGTERM else "interrupted")
    ]
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == []
