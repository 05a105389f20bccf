"""How the command line ends on a signal: Ctrl-C (SIGINT) with exit code 130, SIGTERM with 143,
one line on stderr and no traceback, whenever it arrives (while the modules load too).

SIGTERM is turned into the same `KeyboardInterrupt` as Ctrl-C, so that every clean-up written
for an interruption (temporary folders, partial files) runs for it too; `interrupted()` then
tells the two apart by the signal that arrived. Only `radar_slam.cli` installs the handlers;
the library only starts helper processes (batch's Dask workers) deaf to SIGINT
(`children_ignore_sigint`), since a Ctrl-C in a terminal reaches every process of the group and
the parent ends them itself.
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

Handlers = dict[int, Callable[[int, FrameType | None], Any] | int | None]

SIGINT_EXIT_CODE = 128 + signal.SIGINT
"""Exit code after Ctrl-C (130), as shells report it."""
SIGTERM_EXIT_CODE = 128 + signal.SIGTERM
"""Exit code after SIGTERM (143)."""

_received: list[int] = []


def _interrupt(signum: int, frame: FrameType | None) -> None:
    _received.append(signum)
    raise KeyboardInterrupt


def install() -> Handlers:
    """Turn SIGINT and SIGTERM into `KeyboardInterrupt`, remembering which arrived (a SIGINT
    that the shell set to be ignored, as for a background job, stays ignored); returns the
    previous handlers for `restore`. Outside the main thread nothing changes."""
    _received.clear()
    if threading.current_thread() is not threading.main_thread():
        return {}
    previous: Handlers = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        current = signal.getsignal(signum)
        if signum == signal.SIGINT and current is signal.SIG_IGN:
            continue
        previous[signum] = current
        signal.signal(signum, _interrupt)
    return previous


def restore(previous: Handlers) -> None:
    """Put back the handlers `install` replaced (when `main` is called inside a program)."""
    for signum, handler in previous.items():
        signal.signal(signum, handler)


@contextmanager
def children_ignore_sigint() -> Iterator[None]:
    """Processes started inside this block never see SIGINT.

    SIGINT is ignored while the block runs: an ignored signal stays ignored across fork and
    exec, and a Python process that starts with SIGINT ignored keeps it so, whichever thread
    spawns it (a blocked-signal mask would be per thread: a library's own thread would spawn
    children that see it). A Ctrl-C pressed meanwhile is lost, so the block should be short (the
    start of worker processes). Outside the main thread nothing changes.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def was_interrupted() -> bool:
    """True once SIGINT or SIGTERM has arrived through the installed handlers."""
    return bool(_received)


def interrupted() -> int:
    """Say so on stderr and return the exit code of the signal that arrived (130 by default,
    e.g. for a Ctrl-C seen as `KeyboardInterrupt` without the handlers)."""
    terminated = bool(_received) and _received[-1] == signal.SIGTERM
    sys.stderr.write(f"radar-slam: {'terminated' if terminated else 'interrupted'}\n")
    return SIGTERM_EXIT_CODE if terminated else SIGINT_EXIT_CODE
