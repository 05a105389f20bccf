"""The `radar-slam` Typer app: one module per command group (`radar_slam.cli` starts it).

Each module in `radar_slam/commands/` has `register(app)`. A command line that names a command
loads only the module of that command (`COMMANDS`): `radar-slam run` does not import the
simulator, the batch runner or the other commands' modules. User errors (RadarSlamError and the
pure packages' error classes) become one line on stderr and exit code 1.
"""

from __future__ import annotations

import functools
import importlib
import logging
from typing import Any

import typer
from typer._click.exceptions import ClickException, NoArgsIsHelpError, UsageError

from odometry import OdometryError
from radar_slam import __version__
from radar_slam.errors import RadarSlamError
from radar_slam.signals import SIGINT_EXIT_CODE, interrupted
from radar_slam.viewer import viewer_argv
from raplace import RaPlaceError

COMMANDS = {
    "data": ("list", "info"),
    "evaluate": ("eval",),
    "simulate": ("simulate",),
    "placerec": ("pr",),
    "run": ("run", "odometry"),
    "loops": ("loops",),
    "export": ("export",),
    "batch": ("batch",),
    "maps": ("localize", "map"),
}
"""Each module of `radar_slam/commands/` (in the order of the help's command list) and the names
of the commands its `register` adds."""


def _version(value: bool) -> None:
    if value:
        typer.echo(f"radar-slam {__version__}")
        raise typer.Exit()


def _root(
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Print the version and exit."
    ),
    verbose: bool = typer.Option(False, "--verbose", "-v", help="Log progress details."),
) -> None:
    logging.basicConfig(
        level=logging.INFO if verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )


def make_app(command: str | None = None) -> typer.Typer:
    """The app with every command, or with only the module of `command` when it names one."""
    app = typer.Typer(
        name="radar-slam",
        help="Radar SLAM for scanning FMCW radar: odometry, RaPlace loop closure, pose graph.",
        no_args_is_help=True,
        add_completion=False,
        pretty_exceptions_enable=False,
    )
    app.callback()(_root)
    modules = [module for module, names in COMMANDS.items() if command in names]
    for module in modules or COMMANDS:
        importlib.import_module(f"radar_slam.commands.{module}").register(app)
    return app


def command_of(argv: list[str]) -> str | None:
    """The command `argv` names: its first argument that is not an option (the app's own
    options, `--version`, `--verbose`, `--help`, take no value); None when there is none."""
    return next((argument for argument in argv if not argument.startswith("-")), None)


@functools.cache
def _full_app() -> typer.Typer:
    return make_app()


def __getattr__(name: str) -> Any:
    """`app`: the app with every command (for tools that inspect it), made on first use."""
    if name == "app":
        return _full_app()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def run_app(argv: list[str]) -> int:
    """Run the app on `argv`; returns the exit code.

    User errors, a bad option value included, become one line on stderr and exit code 1;
    an interruption (Ctrl-C, or SIGTERM as `radar_slam.cli` turns it) exits with `interrupted()`;
    anything else is a bug and keeps its traceback.
    """
    arguments = viewer_argv(argv)
    app = make_app(command_of(arguments))
    try:
        code = app(args=arguments, standalone_mode=False)
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except NoArgsIsHelpError as exc:
        exc.show()
        return exc.exit_code
    except UsageError as exc:  # a bad option or argument: one line too
        command = exc.ctx.command_path if exc.ctx is not None else "radar-slam"
        typer.echo(f"radar-slam: error: {command}: {_one_line(exc.format_message())}", err=True)
        return 1
    except ClickException as exc:
        typer.echo(f"radar-slam: error: {_one_line(exc.format_message())}", err=True)
        return 1
    except (typer.Abort, KeyboardInterrupt):
        return interrupted()
    except (RadarSlamError, RaPlaceError, OdometryError) as exc:
        typer.echo(f"radar-slam: error: {exc}", err=True)
        return 1
    if code == SIGINT_EXIT_CODE:  # Typer's answer to a KeyboardInterrupt in a command
        return interrupted()
    return code if isinstance(code, int) else 0


def _one_line(text: str) -> str:
    return " ".join(text.split())
