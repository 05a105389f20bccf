"""`radar-slam export SEQ --bag OUT`: a sequence, or a result folder's trajectories, as a ROS bag.

SEQ is anything `run` accepts (family/name, a folder, a bag), written as scans plus ground truth;
or a result folder of `run` / `odometry` (holding odometry.tum), whose TUM trajectories are
written as nav_msgs/Odometry and nav_msgs/Path. OUT ending in `.bag` is a ROS 1 bag (`.BAG` is
refused), anything else a ROS 2 bag folder (`--storage mcap` or `sqlite3`). The layout is in
`radar_slam.rosbag_out`. A killed export's hidden leftovers are removed by the next one.
"""

from __future__ import annotations

from pathlib import Path

import typer
from tqdm import tqdm

from radar_slam.commands.bag_options import (
    GT_TOPIC_OPTION,
    LAYOUT_OPTION,
    TOPIC_OPTION,
    bag_overrides,
)
from radar_slam.commands.options import DATA_ROOT_OPTION
from radar_slam.errors import ResultsError
from radar_slam.pipeline import open_configured
from radar_slam.trajectory import read_tum

TRAJECTORY_FILES = ("odometry", "slam", "gt")
"""TUM files of a result folder written to a trajectory bag, when present."""


def is_result_folder(path: Path) -> bool:
    """True for a result folder of `run` or `odometry` (it holds odometry.tum)."""
    return path.is_dir() and (path / "odometry.tum").is_file()


def export_command(
    sequence: str = typer.Argument(
        ..., help="Sequence (family/name, folder, bag) or a result folder of run/odometry."
    ),
    bag: Path = typer.Option(
        ..., "--bag", help="Bag to create: OUT.bag (ROS 1) or a ROS 2 bag folder."
    ),
    storage: str = typer.Option(
        "mcap", "--storage", help="ROS 2 storage: mcap or sqlite3 (ignored for .bag)."
    ),
    max_frames: int | None = typer.Option(
        None, "--max-frames", min=1, help="Export only the first N scans."
    ),
    config: Path | None = typer.Option(
        None, "--config", exists=True, dir_okay=False, help="YAML overrides (dataset: section)."
    ),
    topic: str | None = TOPIC_OPTION,
    gt_topic: str | None = GT_TOPIC_OPTION,
    layout: str | None = LAYOUT_OPTION,
    data_root: Path | None = DATA_ROOT_OPTION,
) -> None:
    """Write a sequence (scans + ground truth) or a run's trajectories as a ROS 1/2 bag."""
    from radar_slam.rosbag_out import (  # the bag writers only for this command
        Storage,
        check_bag_out,
        write_sequence_bag,
        write_trajectories_bag,
    )

    if storage not in ("mcap", "sqlite3"):
        raise ResultsError(f"--storage {storage!r}: choose mcap or sqlite3")
    chosen: Storage = "mcap" if storage == "mcap" else "sqlite3"
    check_bag_out(bag)
    folder = Path(sequence)
    if is_result_folder(folder):
        trajectories = {
            name: read_tum(folder / f"{name}.tum")
            for name in TRAJECTORY_FILES
            if (folder / f"{name}.tum").is_file()
        }
        write_trajectories_bag(trajectories, bag, chosen)
        typer.echo(f"{', '.join(trajectories)} trajectories of {folder} -> {bag}")
        return
    bag_options = bag_overrides(topic, gt_topic, layout)
    seq, settings = open_configured(sequence, data_root, config, bag_options)
    total = len(seq) if max_frames is None else min(max_frames, len(seq))
    with tqdm(total=total, desc=f"{seq.family}/{seq.name}", unit="scan") as bar:
        written = write_sequence_bag(
            seq, bag, chosen, max_frames, progress=lambda done: bar.update(done - bar.n)
        )
    gt = "with" if seq.ground_truth is not None else "without"
    typer.echo(f"{seq.family}/{seq.name}: {written} scans {gt} ground truth -> {bag}")


def register(app: typer.Typer) -> None:
    """Add `export` to the CLI app."""
    app.command("export")(export_command)
