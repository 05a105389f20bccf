"""`batch` interrupted (Ctrl-C reaching the whole process group, as in a terminal) or with an
unreachable scheduler: exit code 130 or one line, no traceback, and no `--out` left to block a
re-run."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest
from bad_input_support import assert_refused

from radar_slam.datasets.frame import RadarSequence
from radar_slam.signals import SIGINT_EXIT_CODE

TIMEOUT_S = 180.0
POLL_S = 0.05
SETTLE_S = 1.0
UNREACHABLE = "tcp://127.0.0.1:9"
"""The discard port: nothing listens there."""

pytest.importorskip("distributed", reason="dask.distributed (the batch extra) missing")


def test_unreachable_scheduler_leaves_nothing(
    tiny: RadarSequence, synthetic_root: Path, workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args: list[str | Path] = ["batch", "synthetic/tiny", "--scheduler", UNREACHABLE]
    args += ["--out", workdir / "b", "--data-root", synthetic_root, "--max-frames", "2"]
    assert_refused(capsys, (workdir, synthetic_root), args, UNREACHABLE, "cannot connect")


def _worker_started(pid: int) -> bool:
    """True once a worker process (a multiprocessing child of the batch) runs and the batch no
    longer ignores SIGINT (it does while its workers start, so that they never see it)."""
    try:
        children = psutil.Process(pid).children(recursive=True)
        status = Path(f"/proc/{pid}/status").read_text()
    except (psutil.Error, OSError):
        return False
    ignored = int(next(line for line in status.splitlines() if line.startswith("SigIgn:"))[7:], 16)
    sigint_ignored = bool(ignored & (1 << (signal.SIGINT - 1)))
    return not sigint_ignored and any("spawn_main" in " ".join(c.cmdline()) for c in children)


def _new_group_default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    os.setpgrp()


def test_ctrl_c_ends_a_batch_without_tracebacks_or_leftovers(
    tiny: RadarSequence, synthetic_root: Path, tmp_path: Path
) -> None:
    work = tmp_path / "work"
    work.mkdir()
    log = tmp_path / "stderr.txt"
    args = ["batch", "synthetic/tiny", "--workers", "1", "--out", "b"]
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    with log.open("wb") as stderr:
        process = subprocess.Popen(
            [sys.executable, "-m", "radar_slam.cli", *args, "--data-root", str(synthetic_root)],
            cwd=work,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=stderr,
            preexec_fn=_new_group_default_sigint,
        )
        deadline = time.monotonic() + TIMEOUT_S
        # a Ctrl-C while the workers start is ignored: wait for the worker process to be up
        while not _worker_started(process.pid) and process.poll() is None:
            assert time.monotonic() < deadline
            time.sleep(POLL_S)
        time.sleep(SETTLE_S)  # the cluster is up and the task running on the worker
        if process.poll() is not None:
            pytest.skip("the batch ended before the signal")
        os.killpg(process.pid, signal.SIGINT)
        process.wait(timeout=TIMEOUT_S)
    text = log.read_text(errors="replace")
    assert process.returncode == SIGINT_EXIT_CODE, text
    assert "Traceback" not in text and "ERROR" not in text, text
    assert "radar-slam: interrupted" in text
    assert list(work.iterdir()) == []
