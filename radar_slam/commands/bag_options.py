"""Command-line options of ROS bag input (`--topic`, `--gt-topic`, `--layout`), shared by `run`,
`odometry` and `export`. They set the `dataset:` config keys of the same names, so the
config.yaml of a result folder records them."""

from __future__ import annotations

from typing import Any

import typer

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


def bag_overrides(
    topic: str | None, gt_topic: str | None, layout: str | None
) -> dict[str, Any] | None:
    """Config overrides (`dataset:` keys) of the given bag options, for `open_configured`
    (applied on top of the config files; None when no option is given). A sequence that is no
    bag then fails with a ConfigError naming the option."""
    given = {"topic": topic, "gt_topic": gt_topic, "layout": layout}
    dataset = {key: value for key, value in given.items() if value is not None}
    return {"dataset": dataset} if dataset else None
