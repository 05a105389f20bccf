"""The `radar-slam` command line: one Typer app, one module per command group.

Each module in `radar_slam/commands/` has `register(app)`. User errors (RadarSlamError and the
pure packages' error classes) become one line on stderr and exit code 1.
"""

from __future__ import annotations

import importlib
import logging
import sys

import typer

from odometry import OdometryError
from radar_slam import __version__
from radar_slam.errors import RadarSlamError
from raplace import RaPlaceError

COMMAND_MODULES = ("data", "evaluate", "simulate", "placerec", "run", "loops", "batch")

app = typer.Typer(
    name="radar-slam",
    help="Radar SLAM for scanning FMCW radar: odometry, RaPlace loop closure, pose graph.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"radar-slam {__version__}")
        raise typer.Exit()


@app.callback()
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


for _name in COMMAND_MODULES:
    importlib.import_module(f"radar_slam.commands.{_name}").register(app)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the exit code.

    Typer's standalone mode prints usage errors itself (exit code 2); user errors raised by the
    commands become one line on stderr and exit code 1; anything else is a bug and keeps its
    traceback.
    """
    try:
        app(args=argv, standalone_mode=True)
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except (RadarSlamError, RaPlaceError, OdometryError) as exc:
        typer.echo(f"radar-slam: error: {exc}", err=True)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
