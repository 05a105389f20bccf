"""Helpers of the bad-input and fault tests: run the CLI in-process, snapshot folder trees."""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from radar_slam.cli import main

ERROR_PREFIX = "radar-slam: error: "


@dataclass(frozen=True)
class CliOutcome:
    code: int
    stdout: str
    stderr: str


def run_cli(capsys: pytest.CaptureFixture[str], *args: str | Path | int) -> CliOutcome:
    """`radar-slam ARGS` in this process (a bug would propagate as its exception)."""
    capsys.readouterr()
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return CliOutcome(code, captured.out, captured.err)


def tree_state(*roots: Path) -> dict[str, tuple[str, int, str]]:
    """Every entry under `roots`: path -> (kind, size, content hash or link target).

    Folders are recorded too (a created or removed folder is a change); their mtimes are not
    compared, since only what they hold matters.
    """
    state: dict[str, tuple[str, int, str]] = {}
    for root in roots:
        if not root.exists():
            continue
        for dirpath, dirnames, filenames in os.walk(root):
            for name in dirnames + filenames:
                path = Path(dirpath) / name
                if path.is_symlink():
                    state[str(path)] = ("link", 0, os.readlink(path))
                elif path.is_dir():
                    state[str(path)] = ("dir", 0, "")
                else:
                    data = path.read_bytes()
                    digest = hashlib.sha1(data).hexdigest()
                    state[str(path)] = ("file", len(data), f"{digest}:{path.stat().st_mtime_ns}")
    return state


def assert_one_line_error(outcome: CliOutcome, *expected: str) -> str:
    """Exit code 1, nothing on stdout, exactly one stderr line naming every `expected` text."""
    lines = [line for line in outcome.stderr.splitlines() if line.strip()]
    assert outcome.code == 1, (outcome.code, outcome.stderr)
    assert outcome.stdout == "", outcome.stdout
    assert len(lines) == 1, outcome.stderr
    assert lines[0].startswith(ERROR_PREFIX), lines[0]
    assert "Traceback" not in outcome.stderr
    for text in expected:
        assert text in lines[0], (text, lines[0])
    return lines[0]


def assert_refused(
    capsys: pytest.CaptureFixture[str],
    roots: tuple[Path, ...],
    args: list[str | Path],
    *expected: str,
) -> str:
    """`radar-slam ARGS` fails with one line naming `expected` and changes nothing under
    `roots`; returns the line."""
    before = tree_state(*roots)
    line = assert_one_line_error(run_cli(capsys, *args), *expected)
    assert tree_state(*roots) == before
    return line


def _default_sigint() -> None:
    # A test runner started as a background job inherits SIGINT ignored, and so would the
    # child: restore the default so that SIGINT acts as Ctrl-C in a terminal.
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def start(args: list[str | Path], cwd: Path) -> subprocess.Popen[bytes]:
    """`radar-slam ARGS` as a subprocess in `cwd` (stderr piped), to be sent signals."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    return subprocess.Popen(
        [sys.executable, "-m", "radar_slam.cli", *map(str, args)],
        cwd=cwd,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        preexec_fn=_default_sigint,
    )
