"""`radar-slam batch SEQ... [--grid FILE] [--scheduler ADDRESS] [--workers N]`: many runs on Dask.

Everything is checked before any task is submitted (sequences found, grid and config valid, the
output folder absent or empty and writable). Each (sequence, configuration) then runs as one Dask
task into `<out>/<family>_<name>/<configuration>/` (the files of `radar-slam run`); a failed run
is a row with its error. The batch folder gets summary.csv, summary.md and summary.png.
"""

from __future__ import annotations

import logging
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
from radar_slam.errors import RadarSlamError, ResultsError
from radar_slam.results import check_out_folder, result_dir

BATCH_FAMILY = "batch"
PROBE_FILE = ".radar-slam-write-probe"


def writable_out(out: Path | None, grid: Path | None) -> Path:
    """The batch folder (`--out`, absent or empty; default results/batch_<grid>/<timestamp>/),
    created and checked writable."""
    folder = result_dir(BATCH_FAMILY, "default" if grid is None else grid.stem, out)
    probe = folder / PROBE_FILE
    try:
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise ResultsError(f"{folder}: output folder not writable ({exc.strerror})") from None
    return folder


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
    if out is not None:
        check_out_folder(out)
    planned = plan_jobs(sequences, points, config, data_root, max_frames)
    folder = writable_out(out, grid)
    jobs = place_jobs(planned, folder)
    if not logging.getLogger().isEnabledFor(logging.INFO):  # without -v: Dask's own chatter off
        logging.getLogger("distributed").setLevel(logging.ERROR)
    where = scheduler or f"a local cluster of {workers} workers"
    typer.echo(f"{len(jobs)} runs ({len(sequences)} sequences x {len(points)} configs) on {where}")
    with tqdm(total=len(jobs), desc="batch", unit="run", dynamic_ncols=True) as bar:

        def on_done(row: BatchRow, done: int, total: int) -> None:
            bar.update(done - bar.n)
            bar.set_postfix_str(f"{row.sequence} [{row.config}] {row.status}", refresh=True)

        rows = run_batch(jobs, scheduler, workers, on_done)
    write_summary(folder, rows)
    typer.echo(markdown_text(rows), nl=False)
    typer.echo(f"summary in {folder} (summary.csv, summary.md, summary.png)")
    failed = sum(not row.ok for row in rows)
    if failed:
        raise RadarSlamError(f"{failed} of {len(rows)} runs failed (errors in {folder}/summary.md)")


def register(app: typer.Typer) -> None:
    """Add the `batch` command to `app`."""
    app.command("batch")(batch_command)
