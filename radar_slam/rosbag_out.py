"""Writing ROS bags: any sequence we read, and a run's trajectories (`radar-slam export`).

Output format by name: `OUT.bag` is a ROS 1 bag (`OUT.BAG` is refused); any other name is a
ROS 2 bag folder whose storage is MCAP (the ROS 2 default since Iron) or sqlite3. Written with
`rosbags` (rosbag2 metadata version 8), atomically: into a temporary sibling, renamed into place
at the end; an existing OUT is never touched, and a killed export's leftovers are removed by the
next export into the same folder.

A sequence bag holds:

    /radar_slam/scan_info      std_msgs/String, one JSON message (layout "radar-slam", range
                               resolution, sensor, source, topics): `BagSequence` reads it
    /radar/polar               sensor_msgs/Image mono8, one per scan: one row per azimuth, an
                               11-byte Oxford-form header per row (int64 LE azimuth time [ns],
                               0 when unknown; uint16 LE encoder count of 5600, clockwise;
                               valid byte 255), then the range bins. header.stamp = scan time
    /radar_slam/ground_truth   nav_msgs/Odometry at each scan with finite GT (frame "world",
                               child "radar")

A trajectory bag holds, for each TUM file of a result folder (odometry, slam, gt):
`/radar_slam/<name>/odometry` nav_msgs/Odometry per pose and `/radar_slam/<name>/path` one
nav_msgs/Path with every pose, stamped at the last pose.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from radar_slam.datasets._io import encode_oxford_form
from radar_slam.datasets.frame import RadarFrame, Sequence
from radar_slam.datasets.navtech import ENCODER_TICKS_PER_REV, encoder_to_azimuth_ccw
from radar_slam.datasets.rosbag import IMAGE_TYPE, ROS1_SUFFIX, SCAN_INFO_TOPIC
from radar_slam.errors import ResultsError
from radar_slam.results import remove_stale_partials
from radar_slam.trajectory import Trajectory, quaternion_from_yaw
from raplace import NS_PER_S

logger = logging.getLogger(__name__)

Storage = Literal["mcap", "sqlite3"]
SCAN_TOPIC = "/radar/polar"
GT_TOPIC = "/radar_slam/ground_truth"
STRING_TYPE = "std_msgs/msg/String"
ODOMETRY_TYPE = "nav_msgs/msg/Odometry"
PATH_TYPE = "nav_msgs/msg/Path"
WORLD_FRAME = "world"
RADAR_FRAME = "radar"
ROS2_VERSION: Literal[8] = 8
PARTIAL = ".partial-"


class BagOut:
    """A bag being written: ROS 1 or ROS 2, with the matching type store and serializer.

    Use `open_bag`; `message(type, **fields)` builds a message, `write(topic, stamp, msg)`
    serializes and stores it (the topic's connection is added on first use).
    """

    def __init__(self, path: Path, storage: Storage) -> None:
        self.ros1 = path.suffix == ROS1_SUFFIX
        self.typestore = get_typestore(Stores.ROS1_NOETIC if self.ros1 else Stores.ROS2_HUMBLE)
        self._writer: Writer1 | Writer2
        if self.ros1:
            self._writer = Writer1(path)
        else:
            plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
            self._writer = Writer2(path, version=ROS2_VERSION, storage_plugin=plugin)
        self._connections: dict[str, Any] = {}
        self._seq = 0

    def __enter__(self) -> BagOut:
        self._writer.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self._writer.close()

    def message(self, msgtype: str, **fields: Any) -> Any:
        return self.typestore.types[msgtype](**fields)

    def header(self, stamp_ns: int, frame_id: str) -> Any:
        """A std_msgs/Header (ROS 1 headers also carry a sequence number)."""
        sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
        stamp = self.message("builtin_interfaces/msg/Time", sec=sec, nanosec=nanosec)
        if not self.ros1:
            return self.message("std_msgs/msg/Header", stamp=stamp, frame_id=frame_id)
        self._seq += 1
        return self.message("std_msgs/msg/Header", seq=self._seq, stamp=stamp, frame_id=frame_id)

    def pose(self, pose: NDArray[np.float64]) -> Any:
        """A geometry_msgs/Pose of an SE(2) pose (x, y, yaw) at z = 0."""
        qx, qy, qz, qw = quaternion_from_yaw(pose[2])
        return self.message(
            "geometry_msgs/msg/Pose",
            position=self.message("geometry_msgs/msg/Point", x=pose[0], y=pose[1], z=0.0),
            orientation=self.message("geometry_msgs/msg/Quaternion", x=qx, y=qy, z=qz, w=qw),
        )

    def odometry(self, stamp_ns: int, pose: NDArray[np.float64], child: str) -> Any:
        """A nav_msgs/Odometry with `pose` in the world frame, zero twist and covariances."""
        zero = self.message("geometry_msgs/msg/Vector3", x=0.0, y=0.0, z=0.0)
        return self.message(
            ODOMETRY_TYPE,
            header=self.header(stamp_ns, WORLD_FRAME),
            child_frame_id=child,
            pose=self.message(
                "geometry_msgs/msg/PoseWithCovariance",
                pose=self.pose(pose),
                covariance=np.zeros(36),
            ),
            twist=self.message(
                "geometry_msgs/msg/TwistWithCovariance",
                twist=self.message("geometry_msgs/msg/Twist", linear=zero, angular=zero),
                covariance=np.zeros(36),
            ),
        )

    def write(self, topic: str, stamp_ns: int, message: Any) -> None:
        msgtype = message.__msgtype__
        if topic not in self._connections:
            self._connections[topic] = self._writer.add_connection(
                topic, msgtype, typestore=self.typestore
            )
        if self.ros1:
            data = self.typestore.serialize_ros1(message, msgtype)
        else:
            data = self.typestore.serialize_cdr(message, msgtype)
        self._writer.write(self._connections[topic], int(stamp_ns), data)


def check_bag_out(out: Path) -> None:
    """Fail before any work unless the bag `out` can be created: it does not exist, and its
    folder exists and is writable.

    Raises:
        ResultsError: one line naming `out` and what stands in the way.
    """
    out = Path(out)
    if out.exists() or out.is_symlink():
        raise ResultsError(f"{out}: exists already; choose another --bag (never overwritten)")
    if out.suffix.lower() == ROS1_SUFFIX and out.suffix != ROS1_SUFFIX:
        raise ResultsError(
            f"{out}: a ROS 1 bag is named *{ROS1_SUFFIX} in lower case (ROS tools read no other); "
            f"choose {out.with_suffix(ROS1_SUFFIX).name}, or a name without it for a ROS 2 bag"
        )
    folder = out.parent
    if not folder.exists():
        raise ResultsError(f"{out}: folder {folder} does not exist (--bag)")
    if not folder.is_dir():
        raise ResultsError(f"{out}: {folder} is not a folder (--bag)")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ResultsError(f"{out}: folder {folder} is not writable (--bag)")


@contextmanager
def open_bag(out: Path, storage: Storage = "mcap") -> Iterator[BagOut]:
    """Write a bag at `out` atomically (temporary sibling, renamed when complete); leftovers of
    an export killed earlier next to it (`.<name>.partial-<pid>` of a dead process) are removed.

    Raises:
        ResultsError: `out` exists already, or its folder is missing or not writable.
    """
    out = Path(out)
    check_bag_out(out)
    remove_stale_partials(out.parent)  # what a killed export left next to it
    staging = out.parent / f".{out.name}{PARTIAL}{os.getpid()}"
    staging.mkdir()
    try:
        with BagOut(staging / out.name, storage) as bag:
            yield bag
        (staging / out.name).rename(out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def scan_encoders(frame: RadarFrame) -> NDArray[np.int64]:
    """Encoder counts (of 5600, clockwise) of a frame's azimuths; warns when they are not exact."""
    ticks = np.round(-frame.azimuths_rad * ENCODER_TICKS_PER_REV / (2.0 * np.pi))
    encoders = np.mod(ticks, ENCODER_TICKS_PER_REV).astype(np.int64)
    if not np.allclose(
        np.mod(encoder_to_azimuth_ccw(encoders) - frame.azimuths_rad + np.pi, 2 * np.pi) - np.pi,
        0.0,
        atol=1e-9,
    ):
        logger.warning("azimuths of scan %d rounded to whole encoder ticks", frame.timestamp_ns)
    return encoders


def scan_image(bag: BagOut, frame: RadarFrame) -> Any:
    """The sensor_msgs/Image (mono8, Oxford-form rows) of one scan."""
    times = frame.azimuth_times_ns
    if times is None:
        times = np.zeros(frame.n_azimuths, dtype=np.int64)
    image = encode_oxford_form(frame.polar, scan_encoders(frame), times)
    return bag.message(
        IMAGE_TYPE,
        header=bag.header(frame.timestamp_ns, RADAR_FRAME),
        height=image.shape[0],
        width=image.shape[1],
        encoding="mono8",
        is_bigendian=0,
        step=image.shape[1],
        data=image.ravel(),
    )


def write_sequence_bag(
    sequence: Sequence,
    out: Path,
    storage: Storage = "mcap",
    max_frames: int | None = None,
    progress: Callable[[int], None] | None = None,
) -> int:
    """Write the scans (and GT) of `sequence` as a bag; returns the number of scans written.

    Args:
        sequence: any opened sequence.
        out: `*.bag` (ROS 1) or a ROS 2 bag folder to create.
        storage: ROS 2 storage ("mcap" or "sqlite3"); ignored for ROS 1.
        max_frames: write only the first scans.
        progress: called with the number of scans written after each one.
    """
    count = len(sequence) if max_frames is None else min(max_frames, len(sequence))
    gt = sequence.ground_truth
    with open_bag(out, storage) as bag:
        first = sequence[0] if count else None
        info = {
            "layout": "radar-slam",
            "range_resolution_m": first.range_resolution_m if first else None,
            "sensor": first.sensor if first else None,
            "source": f"{sequence.family}/{sequence.name}",
            "scan_topic": SCAN_TOPIC,
            "gt_topic": GT_TOPIC if gt is not None else None,
        }
        start = int(sequence.timestamps_ns[0]) if count else 0
        bag.write(SCAN_INFO_TOPIC, start, bag.message(STRING_TYPE, data=json.dumps(info)))
        for index in range(count):
            frame = first if index == 0 and first is not None else sequence[index]
            bag.write(SCAN_TOPIC, frame.timestamp_ns, scan_image(bag, frame))
            if gt is not None and np.all(np.isfinite(gt[index])):
                odometry = bag.odometry(frame.timestamp_ns, gt[index], RADAR_FRAME)
                bag.write(GT_TOPIC, frame.timestamp_ns, odometry)
            if progress is not None:
                progress(index + 1)
    return count


def write_trajectories_bag(
    trajectories: dict[str, Trajectory], out: Path, storage: Storage = "mcap"
) -> None:
    """Write trajectories as nav_msgs/Odometry streams and one nav_msgs/Path each.

    Args:
        trajectories: by name (e.g. "odometry", "slam", "gt"), poses of the radar in the world.
        out: `*.bag` (ROS 1) or a ROS 2 bag folder to create.
        storage: ROS 2 storage ("mcap" or "sqlite3").
    """
    with open_bag(out, storage) as bag:
        for name, trajectory in trajectories.items():
            if not len(trajectory):
                continue
            poses = []
            for stamp, pose in zip(trajectory.timestamps_ns, trajectory.poses, strict=True):
                bag.write(f"/radar_slam/{name}/odometry", stamp, bag.odometry(stamp, pose, name))
                poses.append(
                    bag.message(
                        "geometry_msgs/msg/PoseStamped",
                        header=bag.header(stamp, WORLD_FRAME),
                        pose=bag.pose(pose),
                    )
                )
            last = int(trajectory.timestamps_ns[-1])
            path = bag.message(PATH_TYPE, header=bag.header(last, WORLD_FRAME), poses=poses)
            bag.write(f"/radar_slam/{name}/path", last, path)
