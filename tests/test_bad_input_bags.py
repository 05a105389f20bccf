"""Bags that contradict an option or themselves: an export's own scan info against `--layout`,
an image geometry that changes mid-bag, no usable image topic, and `--topic` naming a topic of
another type. Each is one line naming the bag (and the message, option or topics) before any
work, and nothing is written."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from bad_input_support import assert_refused, run_cli
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_typestore

from radar_slam.datasets.frame import RadarSequence

TYPESTORE = get_typestore(Stores.ROS1_NOETIC)
IMAGE = "sensor_msgs/msg/Image"
STRING = "std_msgs/msg/String"
CHANGED = 3
"""The message of the geometry-changing bag whose image is narrower."""


def image_message(stamp_ns: int, image: np.ndarray) -> bytes:
    types = TYPESTORE.types
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    header = types["std_msgs/msg/Header"](
        seq=0, stamp=types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id="r"
    )
    message = types[IMAGE](
        header=header,
        height=image.shape[0],
        width=image.shape[1],
        encoding="mono8",
        is_bigendian=0,
        step=image.shape[1],
        data=np.ascontiguousarray(image).ravel(),
    )
    return TYPESTORE.serialize_ros1(message, IMAGE)


def string_message(text: str) -> bytes:
    return TYPESTORE.serialize_ros1(TYPESTORE.types[STRING](data=text), STRING)


def write_navtech_bag(path: Path, tiny: RadarSequence, empty_radar: bool = False) -> Path:
    """Navtech-driver layout scans of tiny on /radar (the CHANGED-th one narrower), or an empty
    /radar; and a /chatter String topic."""
    with Writer(path) as writer:
        radar = writer.add_connection("/radar", IMAGE, typestore=TYPESTORE)
        chatter = writer.add_connection("/chatter", STRING, typestore=TYPESTORE)
        writer.write(chatter, int(tiny.timestamps_ns[0]), string_message("hello"))
        for index in range(0 if empty_radar else 6):
            frame = tiny[index]
            polar = frame.polar if index != CHANGED else frame.polar[:, :-100]
            writer.write(radar, frame.timestamp_ns, image_message(frame.timestamp_ns, polar))
    return path


@pytest.fixture(scope="module")
def exported(
    tiny: RadarSequence, synthetic_root: Path, tmp_path_factory: pytest.TempPathFactory
) -> Path:
    bag = tmp_path_factory.mktemp("bags") / "tiny.bag"
    args = ["export", "synthetic/tiny", "--bag", str(bag), "--max-frames", "6"]
    from radar_slam.cli import main

    assert main([*args, "--data-root", str(synthetic_root)]) == 0
    return bag


@pytest.mark.parametrize("command", ["run", "odometry"])
def test_layout_contradicting_the_exported_scan_info_is_refused(
    command: str, exported: Path, workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args: list[str | Path] = [command, exported, "--layout", "mulran"]
    line = assert_refused(capsys, (workdir, exported.parent), args, str(exported), "--layout")
    assert "'mulran'" in line and "'radar-slam'" in line and "/radar_slam/scan_info" in line


def test_layout_agreeing_with_the_scan_info_is_taken(
    exported: Path, workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    outcome = run_cli(capsys, "odometry", exported, "--layout", "radar-slam", "--out", "res")
    assert outcome.code == 0, outcome.stderr


def test_image_geometry_changing_mid_bag_names_the_message(
    tiny: RadarSequence, workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = write_navtech_bag(workdir / "changing.bag", tiny)
    args: list[str | Path] = ["run", bag]
    assert_refused(capsys, (workdir,), args, str(bag), f"message {CHANGED}", "mid-bag")


def test_empty_mono8_topic_says_what_the_bag_holds(
    tiny: RadarSequence, workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = write_navtech_bag(workdir / "empty.bag", tiny, empty_radar=True)
    expected = ["/radar (no messages)", "/chatter (std_msgs/msg/String)", "--topic"]
    assert_refused(capsys, (workdir,), ["run", bag], str(bag), *expected)


def test_topic_of_another_type_names_its_type(
    tiny: RadarSequence, workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = write_navtech_bag(workdir / "scans.bag", tiny)
    args: list[str | Path] = ["run", bag, "--topic", "/chatter"]
    assert_refused(capsys, (workdir,), args, str(bag), "/chatter", STRING, IMAGE)
