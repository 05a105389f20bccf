"""ROS bags in and out: round trips of real Oxford scans and synthetic/tiny_loop through ROS 1,
ROS 2 sqlite3 and ROS 2 MCAP bags; foreign layouts (MulRan file player, Navtech ROS driver)
written directly with rosbags; trajectory bags from a result folder."""

from __future__ import annotations

import pickle
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from radar_slam.cli import main
from radar_slam.datasets import BagSequence, DatasetConfig, Sequence, open_sequence
from radar_slam.datasets.mulran import MulRanSequence, column_azimuths_rad
from radar_slam.errors import ConfigError, DatasetFormatError, ResultsError
from radar_slam.rosbag_out import write_sequence_bag
from radar_slam.trajectory import quaternion_from_yaw, read_tum, yaw_from_quaternion

BAG_NAMES = {"ros1": "scans.bag", "sqlite3": "scans_db3", "mcap": "scans_mcap"}


def write_bag(sequence: Sequence, folder: Path, kind: str) -> Path:
    out = folder / BAG_NAMES[kind]
    write_sequence_bag(sequence, out, "sqlite3" if kind == "sqlite3" else "mcap")
    return out


def assert_same_sequence(bag: Sequence, source: Sequence) -> None:
    """Same scans (byte-identical polar arrays), geometry, timestamps and GT."""
    assert bag.family == "rosbag" and len(bag) == len(source)
    np.testing.assert_array_equal(bag.timestamps_ns, source.timestamps_ns)
    for index in range(len(source)):
        ours, theirs = bag[index], source[index]
        assert ours.polar.dtype == np.uint8
        np.testing.assert_array_equal(ours.polar, theirs.polar)
        np.testing.assert_array_equal(ours.azimuths_rad, theirs.azimuths_rad)
        np.testing.assert_array_equal(ours.azimuth_times_ns, theirs.azimuth_times_ns)  # type: ignore[arg-type]
        assert ours.timestamp_ns == theirs.timestamp_ns
        assert ours.range_resolution_m == theirs.range_resolution_m
        assert ours.sensor == theirs.sensor
    assert bag.ground_truth is not None and source.ground_truth is not None
    np.testing.assert_allclose(bag.ground_truth, source.ground_truth, rtol=0, atol=1e-9)


@pytest.mark.realdata
@pytest.mark.parametrize("kind", ["ros1", "sqlite3", "mcap"])
def test_oxford_scans_survive_a_bag_round_trip(oxford_dir: Path, tmp_path: Path, kind: str) -> None:
    oxford = open_sequence(oxford_dir)
    bag = open_sequence(write_bag(oxford, tmp_path, kind))
    assert isinstance(bag, BagSequence) and bag.topic == "/radar/polar"
    assert_same_sequence(bag, oxford)
    assert bag[0].polar.shape == (400, 3768)


@pytest.mark.parametrize("kind", ["ros1", "sqlite3", "mcap"])
def test_tiny_loop_survives_a_bag_round_trip(
    tiny_loop: Sequence, tmp_path: Path, kind: str
) -> None:
    bag = open_sequence(write_bag(tiny_loop, tmp_path, kind))
    assert_same_sequence(bag, tiny_loop)


@pytest.mark.parametrize("kind", ["sqlite3", "mcap"])
def test_an_opened_bag_crosses_a_pickle_without_indexing_again(
    tiny: Sequence, tmp_path: Path, kind: str
) -> None:
    """A `radar-slam batch` job carries its opened sequence to a worker process by pickling."""
    bag = open_sequence(write_bag(tiny, tmp_path, kind))
    _ = bag.ground_truth
    with mock.patch.object(BagSequence, "_index_scans", autospec=True) as index:
        copy = pickle.loads(pickle.dumps(bag))
    assert index.call_count == 0
    assert_same_sequence(copy, tiny)


@pytest.mark.realdata
def test_odometry_on_an_oxford_bag_equals_odometry_on_the_folder(
    oxford_dir: Path, tmp_path: Path
) -> None:
    bag = write_bag(open_sequence(oxford_dir), tmp_path, "mcap")
    assert main(["odometry", str(oxford_dir), "--out", str(tmp_path / "folder")]) == 0
    assert main(["odometry", str(bag), "--out", str(tmp_path / "bag")]) == 0
    folder_tum = (tmp_path / "folder" / "odometry.tum").read_text()
    assert folder_tum == (tmp_path / "bag" / "odometry.tum").read_text()
    assert len(folder_tum.splitlines()) == 7


def _header(typestore: object, stamp_ns: int, ros1: bool, seq: int = 0) -> object:
    types = typestore.types  # type: ignore[attr-defined]
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    stamp = types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)
    if ros1:
        return types["std_msgs/msg/Header"](seq=seq, stamp=stamp, frame_id="radar")
    return types["std_msgs/msg/Header"](stamp=stamp, frame_id="radar")


def _image(
    typestore: object, stamp_ns: int, image: np.ndarray, encoding: str, ros1: bool
) -> object:
    types = typestore.types  # type: ignore[attr-defined]
    return types["sensor_msgs/msg/Image"](
        header=_header(typestore, stamp_ns, ros1),
        height=image.shape[0],
        width=image.shape[1],
        encoding=encoding,
        is_bigendian=0,
        step=image.shape[1],
        data=np.ascontiguousarray(image).ravel(),
    )


def _pose_stamped(typestore: object, stamp_ns: int, pose: np.ndarray, ros1: bool) -> object:
    types = typestore.types  # type: ignore[attr-defined]
    qx, qy, qz, qw = quaternion_from_yaw(pose[2])
    return types["geometry_msgs/msg/PoseStamped"](
        header=_header(typestore, stamp_ns, ros1),
        pose=types["geometry_msgs/msg/Pose"](
            position=types["geometry_msgs/msg/Point"](x=pose[0], y=pose[1], z=0.0),
            orientation=types["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
        ),
    )


def test_mulran_file_player_bag_with_pose_gt(tiny: Sequence, tmp_path: Path) -> None:
    """A ROS 1 bag as the MulRan file player publishes it (/Navtech/Polar, rows = range bins),
    with GT as PoseStamped at other times than the scans (interpolated)."""
    assert isinstance(tiny, MulRanSequence)
    typestore = get_typestore(Stores.ROS1_NOETIC)
    path = tmp_path / "mulran_player.bag"
    frames = [tiny[index] for index in range(10)]
    gt = tiny.ground_truth
    assert gt is not None
    with Writer1(path) as writer:
        scans = writer.add_connection(
            "/Navtech/Polar", "sensor_msgs/msg/Image", typestore=typestore
        )
        poses = writer.add_connection(
            "/gt_pose", "geometry_msgs/msg/PoseStamped", typestore=typestore
        )
        other = writer.add_connection("/camera", "sensor_msgs/msg/Image", typestore=typestore)
        for frame in frames:
            image = _image(typestore, frame.timestamp_ns, frame.polar.T, "mono8", ros1=True)
            data = typestore.serialize_ros1(image, "sensor_msgs/msg/Image")
            writer.write(scans, frame.timestamp_ns + 5_000_000, data)  # recorded a bit later
            colour = _image(
                typestore, frame.timestamp_ns, np.zeros((4, 12), np.uint8), "rgb8", True
            )
            writer.write(
                other, frame.timestamp_ns, typestore.serialize_ros1(colour, "sensor_msgs/msg/Image")
            )
        # GT every 2nd scan only, at the scan times.
        for index in range(0, 10, 2):
            stamp = int(tiny.timestamps_ns[index])
            message = _pose_stamped(typestore, stamp, gt[index], ros1=True)
            writer.write(
                poses, stamp, typestore.serialize_ros1(message, "geometry_msgs/msg/PoseStamped")
            )
    options = DatasetConfig(layout="mulran", gt_topic="/gt_pose", range_resolution_m=0.05952)
    bag = open_sequence(path, options=options)
    assert isinstance(bag, BagSequence) and bag.topic == "/Navtech/Polar"  # the only mono8 one
    assert len(bag) == 10
    for index, frame in enumerate(frames):
        ours = bag[index]
        np.testing.assert_array_equal(ours.polar, frame.polar)
        np.testing.assert_array_equal(ours.azimuths_rad, column_azimuths_rad())
        assert ours.timestamp_ns == frame.timestamp_ns  # the header stamp, not the record time
        # No times in the image: spread over one sweep that ends at the stamp, as MulRan's own.
        np.testing.assert_array_equal(ours.azimuth_times_ns, frame.azimuth_times_ns)
    assert bag.ground_truth is not None
    np.testing.assert_allclose(bag.ground_truth[0:9:2], gt[0:9:2], atol=1e-9)
    # Between GT samples: linear interpolation, within the synthetic car's curvature.
    np.testing.assert_allclose(bag.ground_truth[1:9:2, :2], gt[1:9:2, :2], atol=0.05)


def test_navtech_driver_bag_and_topic_choice(tiny: Sequence, tmp_path: Path) -> None:
    """A ROS 2 sqlite3 bag as the Navtech driver publishes it (8UC1, rows = azimuths, clockwise
    from forward); two radar topics make the topic choice explicit."""
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    path = tmp_path / "navtech_driver"
    frames = [tiny[index] for index in range(4)]
    with Writer2(path, version=8, storage_plugin=StoragePlugin.SQLITE3) as writer:
        connections = [
            writer.add_connection(topic, "sensor_msgs/msg/Image", typestore=typestore)
            for topic in ("/radar_data/b_scan_image", "/radar_data/copy")
        ]
        for frame in frames:
            message = _image(typestore, frame.timestamp_ns, frame.polar, "8UC1", ros1=False)
            for connection in connections:
                writer.write(
                    connection,
                    frame.timestamp_ns,
                    typestore.serialize_cdr(message, "sensor_msgs/msg/Image"),
                )
    with pytest.raises(DatasetFormatError, match="--topic"):
        open_sequence(path)
    bag = open_sequence(path, options=DatasetConfig(topic="/radar_data/b_scan_image"))
    assert isinstance(bag, BagSequence) and bag.layout.rows == "azimuths" and len(bag) == 4
    frame = bag[2]
    np.testing.assert_array_equal(frame.polar, frames[2].polar)
    expected = -2.0 * np.pi * np.arange(400) / 400  # j / 400 of a turn clockwise
    np.testing.assert_allclose(frame.azimuths_rad, expected, atol=1e-12)
    assert frame.range_resolution_m == 0.0438  # the CTS350-X default; set it per driver config
    ccw = open_sequence(
        path,
        options=DatasetConfig(topic="/radar_data/copy", azimuth_direction="ccw", rows="azimuths"),
    )
    np.testing.assert_allclose(ccw[0].azimuths_rad, -expected, atol=1e-12)
    with pytest.raises(ConfigError, match="layout"):
        open_sequence(path, options=DatasetConfig(topic="/radar_data/copy", layout="velodyne"))


def test_bag_options_do_not_apply_to_folders(tiny: Sequence, synthetic_root: Path) -> None:
    with pytest.raises(ConfigError, match="dataset.topic does not apply to the synthetic"):
        open_sequence("synthetic/tiny", synthetic_root, DatasetConfig(topic="/radar"))


def test_export_never_overwrites(tiny: Sequence, tmp_path: Path, synthetic_root: Path) -> None:
    out = tmp_path / "taken.bag"
    out.write_text("mine")
    with pytest.raises(ResultsError, match="never overwritten"):
        write_sequence_bag(tiny, out)
    args = ["export", "synthetic/tiny", "--bag", str(out), "--data-root", str(synthetic_root)]
    assert main(args) == 1
    assert out.read_text() == "mine"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def _read_topic(bag: Path, topic: str) -> list[object]:
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        connections = [c for c in reader.connections if c.topic == topic]
        return [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(connections)]


def test_run_on_a_bag_equals_run_on_the_folder(tiny_loop_runs: Path) -> None:
    folder, bag = tiny_loop_runs / "folder", tiny_loop_runs / "bag"
    for name in ("odometry.tum", "slam.tum", "loops.csv"):
        assert (folder / name).read_text() == (bag / name).read_text()
    gt_folder, gt_bag = read_tum(folder / "gt.tum"), read_tum(bag / "gt.tum")
    np.testing.assert_array_equal(gt_folder.timestamps_ns, gt_bag.timestamps_ns)
    np.testing.assert_allclose(gt_folder.poses, gt_bag.poses, rtol=0, atol=1e-9)  # via quaternions
    assert len(read_tum(bag / "slam.tum")) == 177
    assert "accepted" in (bag / "loops.csv").read_text()


def test_export_of_a_result_folder_writes_paths_and_odometry(
    tiny_loop_runs: Path, tmp_path: Path
) -> None:
    run = tiny_loop_runs / "bag"
    out = tmp_path / "trajectories"
    assert main(["export", str(run), "--bag", str(out), "--storage", "sqlite3"]) == 0
    slam = read_tum(run / "slam.tum")
    (path,) = _read_topic(out, "/radar_slam/slam/path")
    poses = path.poses  # type: ignore[attr-defined]
    xy = np.array([[p.pose.position.x, p.pose.position.y] for p in poses])
    np.testing.assert_allclose(xy, slam.poses[:, :2], atol=1e-9)
    odometry = _read_topic(out, "/radar_slam/odometry/odometry")
    assert len(odometry) == len(slam) == 177
    q = odometry[-1].pose.pose.orientation  # type: ignore[attr-defined]
    expected = read_tum(run / "odometry.tum").poses[-1, 2]
    assert abs(float(yaw_from_quaternion([q.x, q.y, q.z, q.w])) - expected) < 1e-9
    assert len(_read_topic(out, "/radar_slam/gt/path")) == 1


def test_bags_under_the_data_root_are_listed_and_opened_by_name(
    tiny: Sequence, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "rosbag").mkdir()
    write_sequence_bag(tiny, tmp_path / "rosbag" / "drive.bag", max_frames=5)
    write_sequence_bag(tiny, tmp_path / "rosbag" / "drive2", "sqlite3", max_frames=6)
    assert main(["list", "--data-root", str(tmp_path)]) == 0
    listing = capsys.readouterr().out
    assert "rosbag/drive.bag" in listing and "rosbag/drive2" in listing
    assert main(["info", "rosbag/drive.bag", "--data-root", str(tmp_path)]) == 0
    info = capsys.readouterr().out
    assert "frames:            5" in info and "first scan check:  ok" in info
    assert len(open_sequence("rosbag/drive2", tmp_path)) == 6
