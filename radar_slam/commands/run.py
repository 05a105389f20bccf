"""`radar-slam run SEQ` (full SLAM) and `radar-slam odometry SEQ` (odometry only).

Both write a result folder `results/<family>_<sequence>/<timestamp>/` (or `--out`, which must be
absent or empty) with a `latest` link, show a progress bar with frames/s, and print a short
summary. The files are listed in `radar_slam.outputs`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import typer
from tqdm import tqdm

from radar_slam.commands.data import DATA_ROOT_OPTION
from radar_slam.datasets.stride import strided
from radar_slam.errors import ResultsError
from radar_slam.outputs import (
    odometry_summary,
    slam_summary,
    write_odometry_results,
    write_results,
)
from radar_slam.pipeline import (
    Pipeline,
    PipelineConfig,
    Progress,
    ProgressCallback,
    frame_count,
    open_configured,
    run_odometry,
)
from radar_slam.results import result_dir

SEQUENCE_ARGUMENT = typer.Argument(
    ..., help="Sequence: family/name (mulran/KAIST01, oxford/..., synthetic/loop) or a folder."
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
STRIDE_OPTION = typer.Option(  # issue 10: strided view of the sequence
    1, "--stride", min=1, help="Use every K-th scan (4 Hz data at --stride 4 is 1 Hz)."
)


@contextmanager
def progress_bar(total: int, description: str, loops: bool = True) -> Iterator[ProgressCallback]:
    """A tqdm bar (frames/s, and loops accepted/rejected) driven by pipeline `Progress` reports."""
    with tqdm(total=total, desc=description, unit="frame", dynamic_ncols=True) as bar:

        def update(progress: Progress) -> None:
            bar.update(progress.done - bar.n)
            if loops:
                bar.set_postfix(
                    loops=progress.loops_accepted, rejected=progress.loops_rejected, refresh=False
                )

        yield update


def check_out(out: Path | None) -> None:
    """Fail before any work when `--out` exists and is not an empty folder."""
    if out is not None and out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise ResultsError(f"{out}: output folder exists and is not empty; choose another --out")


def without_loops(config: PipelineConfig) -> PipelineConfig:
    """`config` with loop closing disabled (recorded as such in config.yaml)."""
    loop_closure = dataclasses.replace(config.loop_closure, enabled=False)
    return dataclasses.replace(config, loop_closure=loop_closure)


def run_command(
    sequence: str = SEQUENCE_ARGUMENT,
    out: Path | None = OUT_OPTION,
    config: Path | None = CONFIG_OPTION,
    max_frames: int | None = MAX_FRAMES_OPTION,
    stride: int = STRIDE_OPTION,
    no_loops: bool = typer.Option(
        False, "--no-loops", help="Odometry and pose graph only, no loop closing."
    ),
    data_root: Path | None = DATA_ROOT_OPTION,
) -> None:
    """Radar SLAM: odometry, verified RaPlace loop closures, GTSAM pose graph; writes results."""
    check_out(out)
    seq, settings = open_configured(sequence, data_root, config)
    seq = strided(seq, stride)
    if no_loops:
        settings = without_loops(settings)
    total = frame_count(seq, max_frames)
    with progress_bar(total, f"{seq.family}/{seq.name}") as update:
        results = Pipeline(seq, settings, max_frames=max_frames, progress=update).run()
    folder = result_dir(seq.family, seq.name, out)
    write_results(folder, results)
    typer.echo(slam_summary(results), nl=False)
    typer.echo(f"results in {folder}")


def odometry_command(
    sequence: str = SEQUENCE_ARGUMENT,
    out: Path | None = OUT_OPTION,
    config: Path | None = CONFIG_OPTION,
    max_frames: int | None = MAX_FRAMES_OPTION,
    stride: int = STRIDE_OPTION,
    data_root: Path | None = DATA_ROOT_OPTION,
) -> None:
    """Phase-correlation radar odometry only; writes odometry.tum/.kitti and, with ground truth,
    metrics.json (ATE, KITTI drift) and trajectory.png."""
    check_out(out)
    seq, settings = open_configured(sequence, data_root, config)
    seq = strided(seq, stride)
    total = frame_count(seq, max_frames)
    with progress_bar(total, f"{seq.family}/{seq.name}", loops=False) as update:
        run = run_odometry(seq, settings, max_frames=max_frames, progress=update)
    folder = result_dir(seq.family, seq.name, out)
    write_odometry_results(folder, run)
    typer.echo(odometry_summary(run), nl=False)
    typer.echo(f"results in {folder}")


def register(app: typer.Typer) -> None:
    """Add the `run` and `odometry` commands to `app`."""
    app.command("run")(run_command)
    app.command("odometry")(odometry_command)
