"""What several commands share: CLI options and the progress bar."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

import typer
from tqdm import tqdm

if TYPE_CHECKING:  # types only: `radar-slam list` need not load the pipeline
    from radar_slam.pipeline import Progress, ProgressCallback

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


@contextmanager
def progress_bar(total: int, description: str, loops: bool = True) -> Iterator[ProgressCallback]:
    """A tqdm bar (frames/s, and loops accepted/rejected) driven by pipeline `Progress` reports.

    Shown only when stderr is a terminal (a log file gets no bar), and erased on an error so
    that the error is the one line left.
    """
    with tqdm(total=total, desc=description, unit="frame", dynamic_ncols=True, disable=None) as bar:

        def update(progress: Progress) -> None:
            bar.update(progress.done - bar.n)
            if loops:
                bar.set_postfix(
                    loops=progress.loops_accepted, rejected=progress.loops_rejected, refresh=False
                )

        try:
            yield update
        except BaseException:
            bar.leave = False
            raise
