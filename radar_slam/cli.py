"""The `radar-slam` console script: installs the signal handlers, then loads and runs the app
(`radar_slam.cli_app`).

The app's modules (NumPy, GTSAM, every command) load inside `main`, after the handlers are in
place, so that Ctrl-C or SIGTERM during start-up ends like one during the work: one line, exit
code 130 or 143, no traceback (`radar_slam.signals`).
"""

from __future__ import annotations

import sys
from typing import Any

from radar_slam import signals


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the exit code (see `cli_app.run_app`)."""
    previous = signals.install()
    try:
        from radar_slam.cli_app import run_app

        return run_app(sys.argv[1:] if argv is None else argv)
    except KeyboardInterrupt:
        return signals.interrupted()
    except ImportError:
        if signals.was_interrupted():  # some packages re-raise an interrupt as ImportError
            return signals.interrupted()
        raise
    finally:
        signals.restore(previous)


def __getattr__(name: str) -> Any:
    """`app` (the Typer app), loaded on first use."""
    if name == "app":
        from radar_slam.cli_app import app

        return app
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


if __name__ == "__main__":
    sys.exit(main())
