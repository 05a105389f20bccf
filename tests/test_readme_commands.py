"""The README's commands work: each `radar-slam` command of its bash blocks that needs no
downloaded dataset is run, in README order, in an empty folder.

A command runs when its input is a simulated sequence (`synthetic/...`, generated on first use
into the session's data root), a file an earlier README command wrote, or none (`list`,
`simulate`). Commands on a downloaded dataset or a recording of your own (`--data-root`, a
`mulran/...` sequence, `recording.bag`), on a Dask cluster (`--scheduler`) or spawning a viewer
window (a bare `--viewer`) are left out. The Quick start's full-size `synthetic/loop` runs as
`synthetic/tiny` (same code path, a fraction of the scans). A ```yaml block whose first line is
`# NAME` is written to the file NAME first, so that commands can read it.
"""

from __future__ import annotations

import re
import shlex
from importlib.util import find_spec
from pathlib import Path

import pytest

from radar_slam.cli import main

README = Path(__file__).resolve().parent.parent / "README.md"
MAX_README_LINES = 300
SMALLER = {"synthetic/loop": "synthetic/tiny"}
"""Full-size scenarios of the README and the small ones run in their place."""
COVERED = {
    "list",
    "simulate",
    "info",
    "odometry",
    "eval",
    "run",
    "pr",
    "export",
    "batch",
    "loops",
    "map",
    "localize",
}
"""Commands the README must show with an example that runs here."""
BLOCK = re.compile(r"^```(\w+)\n(.*?)^```", re.MULTILINE | re.DOTALL)


def blocks(language: str) -> list[str]:
    text = README.read_text(encoding="utf-8")
    return [body for lang, body in BLOCK.findall(text) if lang == language]


def readme_commands() -> list[str]:
    """Every `radar-slam ...` command of the README's bash blocks, in order, comments removed."""
    commands = []
    for body in blocks("bash"):
        for line in body.splitlines():
            line = line.split(" #", 1)[0].strip()
            for part in line.split("&&"):
                part = part.strip()
                if part.startswith("radar-slam "):
                    commands.append(part)
    return commands


def command_input(arguments: list[str]) -> str | None:
    """The first positional argument after the (sub)command, or None."""
    rest = arguments[2:] if arguments[0] == "map" else arguments[1:]
    return next((a for a in rest if not a.startswith("-")), None)


def runnable(arguments: list[str], folder: Path) -> bool:
    """Whether the command needs nothing but simulated data and earlier commands' output."""
    if "--data-root" in arguments or "--scheduler" in arguments:
        return False
    if "--viewer" in arguments:
        position = arguments.index("--viewer")
        bare = position + 1 == len(arguments) or arguments[position + 1].startswith("-")
        if bare or find_spec("rerun") is None:
            return False
    source = command_input(arguments)
    if arguments[0] in ("list", "simulate") or source is None:
        return True
    return source.startswith("synthetic/") or (folder / source).exists()


def test_readme_is_short_and_quick_start_has_two_commands() -> None:
    assert len(README.read_text(encoding="utf-8").splitlines()) <= MAX_README_LINES
    text = README.read_text(encoding="utf-8")
    quick = text.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    (body,) = [b for lang, b in BLOCK.findall(quick) if lang == "bash"]
    assert [line for line in body.splitlines() if line.strip()] == [
        'pip install ".[test]" && radar-slam run synthetic/loop',
        "pytest",
    ]


def test_readme_commands_run(
    synthetic_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("RADAR_SLAM_DATA", str(synthetic_root))
    for body in blocks("yaml"):
        first, _, rest = body.partition("\n")
        if first.startswith("# "):
            (tmp_path / first[2:].strip()).write_text(rest, encoding="utf-8")
    ran = set()
    for command in readme_commands():
        arguments = [SMALLER.get(a, a) for a in shlex.split(command)[1:]]
        if not runnable(arguments, tmp_path):
            continue
        assert main(arguments) == 0, f"README command failed: {command}"
        ran.add(arguments[0])
    assert COVERED <= ran, f"README commands not run: {sorted(COVERED - ran)}"
