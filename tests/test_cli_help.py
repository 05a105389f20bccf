"""Every command's `--help` shows its help texts whole: Rich must not eat bracketed words."""

from __future__ import annotations

import re
from typing import Any

import pytest
import typer
from typer.testing import CliRunner

from radar_slam.cli import app
from radar_slam.cli_app import COMMANDS, command_of, make_app

BRACKETED = re.compile(r"\[[^\]\s]+\]")


def _commands() -> list[tuple[list[str], Any]]:
    root: Any = typer.main.get_command(app)  # Typer's own (vendored) Click types
    ctx = typer.Context(root)
    found: list[tuple[list[str], Any]] = []
    for name in root.list_commands(ctx):
        command = root.get_command(ctx, name)
        assert command is not None
        found.append(([name], command))
        if hasattr(command, "list_commands"):
            for sub in command.list_commands(ctx):
                subcommand = command.get_command(ctx, sub)
                assert subcommand is not None
                found.append(([name, sub], subcommand))
    return found


def _bracketed_words(command: Any) -> list[str]:
    texts = [command.help or ""] + [getattr(p, "help", None) or "" for p in command.params]
    return [w for text in texts for w in BRACKETED.findall(text.replace("\\[", "["))]


def test_some_help_texts_hold_bracketed_words() -> None:
    words = [w for _, command in _commands() for w in _bracketed_words(command)]
    assert "[m]" in words and "[viewer]" in words


@pytest.mark.parametrize("path", [p for p, _ in _commands()], ids=" ".join)
def test_help_shows_bracketed_words(path: list[str]) -> None:
    command = dict((" ".join(p), c) for p, c in _commands())[" ".join(path)]
    result = CliRunner().invoke(app, [*path, "--help"], env={"COLUMNS": "400"})
    assert result.exit_code == 0, result.output
    shown = " ".join(result.output.split())
    for word in _bracketed_words(command):
        assert word in shown, f"{' '.join(path)} --help lost {word}"


def _names(app: typer.Typer) -> list[str]:
    root: Any = typer.main.get_command(app)
    return list(root.list_commands(typer.Context(root)))


@pytest.mark.parametrize("module", list(COMMANDS))
def test_a_command_loads_only_its_module(module: str) -> None:
    for name in COMMANDS[module]:
        assert _names(make_app(name)) == list(COMMANDS[module])


def test_the_whole_app_has_every_module_s_commands() -> None:
    every = [name for names in COMMANDS.values() for name in names]
    assert sorted(_names(app)) == sorted(every)
    assert _names(make_app("no-such-command")) == _names(app)
    assert command_of(["-v", "--verbose", "run", "synthetic/loop"]) == "run"
    assert command_of(["--help"]) is None
