"""`radar-slam batch SEQ... [--grid FILE] [--scheduler ADDRESS] [--workers N]`: many runs on Dask.

Everything is checked before any task is submitted (sequences found, grid and config valid, the
output folder absent or empty and writable). Each (sequence, configuration) then runs as one
Dask task into `<out>/<family>_<name>/<configuration>/` (the files of `radar-slam run`); a failed
run is a row with its error. The batch folder gets summary.csv, summary.md and summary.png. It
is written under a hidden temporary name and renamed when complete, so an interrupted batch
leaves nothing behind.
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import replace
from pathlib import Path

import typer
from tqdm import tqdm

from radar_slam.batch import (
    BatchRow,
    check_scheduler,
    markdown_text,
    place_jobs,
    plan_jobs,
    read_grid,
    run_batch,
    write_summary,
)
from radar_slam.commands.options import DATA_ROOT_OPTION
from radar_slam.errors import RadarSlamError
from radar_slam.results import check_result_location, final_of_staging, write_result_dir

BATCH_FAMILY = "batch"
DASK_LOGGERS = ("distributed", "tornado", "bokeh", "asyncio")
"""Logger families of Dask and what it runs on, quiet below ERROR unless -v."""


def quiet_dask_logging() -> None:
    """Dask's INFO chatter off (its import sets its loggers' levels, so this comes after it)."""
    import distributed  # noqa: F401  (heavy; only batch needs it)

    for name in list(logging.root.manager.loggerDict):
        if name.split(".")[0] in DASK_LOGGERS:
            logging.getLogger(name).setLevel(logging.ERROR)
    warnings.filterwarnings("ignore", category=UserWarning, module="distributed")


def batch_command(
    sequences: list[str] = typer.Argument(
        ..., help="Sequences: family/name (synthetic/loop, mulran/KAIST01) or folders."
    ),
    grid: Path | None = typer.Option(
        None,
        "--grid",
        help="YAML grid of config overrides (sections configs:, product:).",
        dir_okay=False,
    ),
    scheduler: str | None = typer.Option(
        None,
        "--scheduler",
        help="Address of an existing Dask scheduler (tcp://host:8786); default: a local cluster.",
    ),
    workers: int = typer.Option(
        2, "--workers", min=1, help="Worker processes of the local cluster (1 thread each)."
    ),
    config: Path | None = typer.Option(
        None, "--config", help="YAML overrides applied before the grid's.", dir_okay=False
    ),
    out: Path | None = typer.Option(
        None,
        "--out",
        help="Batch folder (absent or empty); default results/batch_<grid>/<time>/.",
        file_okay=False,
    ),
    max_frames: int | None = typer.Option(
        None, "--max-frames", min=1, help="Process only the first N scans of each sequence."
    ),
    data_root: Path | None = DATA_ROOT_OPTION,
) -> None:
    """Run SLAM over many sequences (x a grid of configurations) as Dask tasks; writes each
    run's result folder and a summary table (CSV, Markdown) and plot."""
    if scheduler is not None:
        check_scheduler(scheduler)
    if config is not None and not config.is_file():
        raise RadarSlamError(f"{config}: config file not found")
    points = read_grid(grid)
    name = "default" if grid is None else grid.stem
    check_result_location(BATCH_FAMILY, name, out)
    planned = plan_jobs(sequences, points, config, data_root, max_frames)
    if not logging.getLogger().isEnabledFor(logging.INFO):  # without -v
        quiet_dask_logging()
    where = scheduler or f"a local cluster of {workers} workers"
    typer.echo(
        f"{len(planned)} runs ({len(sequences)} sequences x {len(points)} configs) on {where}"
    )
    rows: list[BatchRow] = []

    def write(staging: Path) -> None:
        jobs = place_jobs(planned, staging)
        with tqdm(total=len(jobs), desc="batch", unit="run", dynamic_ncols=True) as bar:

            def on_done(row: BatchRow, done: int, total: int) -> None:
                bar.update(done - bar.n)
                bar.set_postfix_str(f"{row.sequence} [{row.config}] {row.status}", refresh=True)

            done = run_batch(jobs, scheduler, workers, on_done)
        final = final_of_staging(staging.absolute())
        rows.extend(
            row if not row.folder else replace(row, folder=str(final / relative))
            for row, relative in zip(done, (job.folder for job in planned), strict=True)
        )
        write_summary(staging, rows)

    # the batch folder appears when complete: an interrupted batch, or one whose scheduler
    # cannot be reached, leaves nothing that blocks its re-run
    folder = write_result_dir(BATCH_FAMILY, name, write, out)
    typer.echo(markdown_text(rows), nl=False)
    typer.echo(f"summary in {folder} (summary.csv, summary.md, summary.png)")
    failed = sum(not row.ok for row in rows)
    if failed:
        raise RadarSlamError(f"{failed} of {len(rows)} runs failed (errors in {folder}/summary.md)")


def register(app: typer.Typer) -> None:
    """Add the `batch` command to `app`."""
    app.command("batch")(batch_command)
