"""What several commands share: CLI options and the progress bar."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

import typer
from tqdm import tqdm

if TYPE_CHECKING:  # types only: `radar-slam list` need not load the pipeline
    from radar_slam.pipeline import Progress

DATA_ROOT_OPTION = typer.Option(
    None,
    "--data-root",
    help="Folder holding <family>/<sequence> folders (default: $RADAR_SLAM_DATA, else ./data).",
)
OUT_OPTION = typer.Option(
    None,
    "--out",
    help="Result folder (must be absent or empty); default results/<family>_<seq>/<timestamp>/.",
    file_okay=False,
)
CONFIG_OPTION = typer.Option(
    None,
    "--config",
    help="YAML overrides applied on top of the defaults and configs/<family>.yaml.",
    exists=True,
    dir_okay=False,
)
MAX_FRAMES_OPTION = typer.Option(
    None, "--max-frames", min=1, help="Process only the first N scans."
)


class RunProgress:
    """A tqdm bar driven by pipeline `Progress` reports (frames/s, loops accepted/rejected), which
    also names what follows the last scan (`step`), so that no step of seconds runs unseen."""

    def __init__(self, bar: tqdm, loops: bool) -> None:
        self.bar = bar
        self.loops = loops
        self._postfix: dict[str, object] = {}

    def __call__(self, progress: Progress) -> None:
        self.bar.update(progress.done - self.bar.n)
        if self.loops:
            self._postfix.update(loops=progress.loops_accepted, rejected=progress.loops_rejected)
        if progress.step:
            self.step(progress.step)
        elif self.loops:
            self.bar.set_postfix(self._postfix, refresh=False)

    def step(self, name: str) -> None:
        """Show that `name` (e.g. "map") runs now, after the last scan."""
        self._postfix["step"] = name
        self.bar.set_postfix(self._postfix, refresh=True)

    def done(self) -> None:
        """Every step has finished: the bar names none any more."""
        if self._postfix.pop("step", None) is not None:
            self.bar.set_postfix(self._postfix, refresh=False)


@contextmanager
def progress_bar(total: int, description: str, loops: bool = True) -> Iterator[RunProgress]:
    """A `RunProgress` bar over `total` scans.

    Shown only when stderr is a terminal (a log file gets no bar), and erased on an error so
    that the error is the one line left.
    """
    with tqdm(total=total, desc=description, unit="frame", dynamic_ncols=True, disable=None) as bar:
        progress = RunProgress(bar, loops)
        try:
            yield progress
        except BaseException:
            bar.leave = False
            raise
        progress.done()
