"""Command-line options of ROS bag input (`--topic`, `--gt-topic`, `--layout`), shared by `run`,
`odometry` and `export`. They set the `dataset:` config keys of the same names, so the
config.yaml of a result folder records them."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TypeVar

import typer

from radar_slam.datasets import DatasetConfig, Sequence, open_sequence
from radar_slam.datasets.rosbag import LAYOUT_PRESETS

TOPIC_OPTION = typer.Option(
    None,
    "--topic",
    help="ROS bag: the radar image topic (default: the only mono8 sensor_msgs/Image topic).",
)
GT_TOPIC_OPTION = typer.Option(
    None,
    "--gt-topic",
    help="ROS bag: ground truth from this nav_msgs/Odometry or geometry_msgs/PoseStamped topic.",
)
LAYOUT_OPTION = typer.Option(
    None,
    "--layout",
    help=f"ROS bag: image layout preset ({', '.join(LAYOUT_PRESETS)}): radar-slam is what "
    "`radar-slam export` writes (recognised without this option); navtech, the default otherwise, "
    "the Navtech ROS driver's radar_data/b_scan_image (rows are azimuths, clockwise from forward; "
    "0.0438 m bins); mulran the MulRan player's /Navtech/Polar (rows are range bins, 0.05952 m). "
    "Finer keys (rows, azimuth_direction, range_resolution_m) go in the dataset: section of "
    "--config.",
)

ConfigT = TypeVar("ConfigT")


def with_bag_options(
    config: ConfigT, topic: str | None, gt_topic: str | None, layout: str | None
) -> ConfigT:
    """`config` (a config with a `dataset: DatasetConfig` section) with the given bag options."""
    if topic is None and gt_topic is None and layout is None:
        return config
    dataset: DatasetConfig = config.dataset  # type: ignore[attr-defined]
    dataset = dataclasses.replace(
        dataset,
        topic=topic or dataset.topic,
        gt_topic=gt_topic or dataset.gt_topic,
        layout=layout or dataset.layout,
    )
    return dataclasses.replace(config, dataset=dataset)  # type: ignore[type-var]


def reopen_with_bag_options(
    spec: str,
    data_root: Path | None,
    sequence: Sequence,
    config: ConfigT,
    topic: str | None,
    gt_topic: str | None,
    layout: str | None,
) -> tuple[Sequence, ConfigT]:
    """(sequence, config) with the bag options applied; the sequence is reopened when any is
    given (a non-bag sequence then fails with a ConfigError naming the option)."""
    updated = with_bag_options(config, topic, gt_topic, layout)
    if updated is config:
        return sequence, config
    dataset: DatasetConfig = updated.dataset  # type: ignore[attr-defined]
    return open_sequence(spec, data_root, dataset), updated
