"""ROS bags as radar sequences: a ROS 1 `.bag` file or a ROS 2 bag folder (sqlite3 or MCAP).

Read with `rosbags` (pure Python; no ROS installation). One `sensor_msgs/Image` topic holds the
scans (default: the only one whose encoding is `mono8` or `8UC1`); each message is one sweep, its
`header.stamp` the scan time. How the image maps to azimuths and bins is an `ImageLayout`, named
by a preset or set key by key in the `dataset:` config section:

    preset      rows      azimuths                                   source
    radar-slam  azimuths  11-byte Oxford-form header per row (int64  `radar-slam export`
                          time [ns], uint16 encoder, valid byte)
    navtech     azimuths  row j at j / n of a turn clockwise         Navtech ROS driver
                                                                     (radar_data/b_scan_image)
    mulran      bins      column j at encoder 9 + 14 j, clockwise    MulRan file player
                                                                     (/Navtech/Polar)

Bags written by `radar-slam export` carry a `std_msgs/String` topic `/radar_slam/scan_info`
(JSON: layout, range resolution, sensor, scan and GT topics), so they need no options. Ground
truth comes from a `nav_msgs/Odometry` or `geometry_msgs/PoseStamped` topic (`gt_topic`): its
(x, y, yaw) poses, taken as radar poses in their world frame, are interpolated to the scan times
(exact at equal stamps; NaN outside their span or in an outage of it).

Frames load lazily: opening indexes the scan messages (one pass reading their headers) and each
`__getitem__` seeks to one message.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import NDArray

from radar_slam.datasets._io import decode_oxford_form, frame_index
from radar_slam.datasets.frame import GroundTruthSource, RadarFrame
from radar_slam.datasets.mulran import gt_max_gap_ns, interpolate_poses
from radar_slam.datasets.navtech import (
    ENCODER_TICKS_PER_REV,
    MULRAN_FIRST_ENCODER,
    MULRAN_RANGE_RESOLUTION_M,
    OXFORD_HEADER_BYTES,
    OXFORD_RANGE_RESOLUTION_M,
    SCAN_RATE_HZ,
    encoder_to_azimuth_ccw,
)
from radar_slam.datasets.registry import Family, register
from radar_slam.datasets.sweep import SweepTimes
from radar_slam.errors import ConfigError, DatasetFormatError, DatasetNotFoundError
from radar_slam.trajectory import yaw_from_quaternion
from raplace import NS_PER_S, checks

if TYPE_CHECKING:  # rosbags loads when a bag is opened, not with every loader
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import Connection

logger = logging.getLogger(__name__)

ROSBAG_FAMILY = "rosbag"
ROSBAG_SENSOR = "navtech-rosbag"
ROS1_SUFFIX = ".bag"
ROS2_METADATA = "metadata.yaml"
IMAGE_TYPE = "sensor_msgs/msg/Image"
GT_TYPES = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped")
MONO_ENCODINGS = ("mono8", "8UC1")
SCAN_INFO_TOPIC = "/radar_slam/scan_info"
"""JSON metadata written by `radar-slam export` (std_msgs/String, one message)."""

Rows = Literal["azimuths", "bins"]
Direction = Literal["cw", "ccw"]


@dataclass(frozen=True)
class ImageLayout:
    """How a radar image message maps to the polar convention.

    Attributes:
        rows: "azimuths" (one row per azimuth) or "bins" (one row per range bin).
        azimuth_direction: "cw" or "ccw" seen from above, from the vehicle's forward axis.
        range_resolution_m: size of one bin [m]; bin k is centred at (k + 0.5) * resolution.
        first_azimuth_ticks: encoder count (of 5600 per turn) of the first azimuth.
        oxford_header: rows carry the 11-byte Oxford-form header with times in ns (then the
            azimuths come from the encoder counts and `azimuth_direction` is ignored).
    """

    rows: Rows = "azimuths"
    azimuth_direction: Direction = "cw"
    range_resolution_m: float = OXFORD_RANGE_RESOLUTION_M
    first_azimuth_ticks: int = 0
    oxford_header: bool = False

    def azimuths_rad(self, n_azimuths: int) -> NDArray[np.float64]:
        """(n_azimuths,) CCW azimuths [rad] of evenly spaced rows/columns."""
        ticks = self.first_azimuth_ticks + np.arange(n_azimuths) * (
            ENCODER_TICKS_PER_REV / n_azimuths
        )
        clockwise = encoder_to_azimuth_ccw(ticks)
        return clockwise if self.azimuth_direction == "cw" else -clockwise

    def decode(
        self, image: NDArray[np.uint8], where: Path
    ) -> tuple[NDArray[np.uint8], NDArray[np.float64], NDArray[np.int64] | None]:
        """(polar (n_azimuths, n_bins) uint8, CCW azimuths [rad], azimuth times [ns] or None)."""
        if self.oxford_header:
            scan = decode_oxford_form(image, where, 1)
            return scan.polar, scan.azimuths_rad, scan.azimuth_times_ns
        polar = np.ascontiguousarray(image if self.rows == "azimuths" else image.T)
        return polar, self.azimuths_rad(polar.shape[0]), None


LAYOUT_PRESETS: dict[str, ImageLayout] = {
    "radar-slam": ImageLayout(rows="azimuths", oxford_header=True),
    "navtech": ImageLayout(rows="azimuths", azimuth_direction="cw"),
    "mulran": ImageLayout(
        rows="bins",
        azimuth_direction="cw",
        range_resolution_m=MULRAN_RANGE_RESOLUTION_M,
        first_azimuth_ticks=MULRAN_FIRST_ENCODER,
    ),
}
"""Layouts by name: our own export, the Navtech ROS driver, the MulRan file player."""

ROSBAG_LAYOUT = (
    "a ROS 1 <name>.bag file or a ROS 2 bag folder (metadata.yaml + .db3 or .mcap) with one "
    "sensor_msgs/Image radar topic (options: dataset.topic, layout, gt_topic)"
)
ROSBAG_OBTAIN = "your own recordings (Navtech ROS driver, MulRan file player), or radar-slam export"


def is_bag(path: Path) -> bool:
    """True for a `.bag` file or a folder holding a ROS 2 `metadata.yaml`."""
    if path.is_file():
        return path.suffix == ROS1_SUFFIX
    return (path / ROS2_METADATA).is_file()


def resolve_layout(
    layout: str | None,
    rows: Rows | None = None,
    azimuth_direction: Direction | None = None,
    range_resolution_m: float | None = None,
    base: ImageLayout | None = None,
) -> ImageLayout:
    """The preset `layout` (or `base`, or the Navtech driver's) with the given keys overriding.

    Raises:
        ConfigError: an unknown preset name.
    """
    if layout is not None:
        if layout not in LAYOUT_PRESETS:
            raise ConfigError(
                f"dataset.layout: unknown layout {layout!r} (presets: {', '.join(LAYOUT_PRESETS)})"
            )
        chosen = LAYOUT_PRESETS[layout]
    else:
        chosen = base or LAYOUT_PRESETS["navtech"]
    changes: dict[str, Any] = {
        "rows": rows,
        "azimuth_direction": azimuth_direction,
        "range_resolution_m": range_resolution_m,
    }
    return replace(chosen, **{key: value for key, value in changes.items() if value is not None})


def stamp_ns(header: Any) -> int:
    """Integer nanoseconds of a std_msgs/Header stamp."""
    return int(header.stamp.sec) * NS_PER_S + int(header.stamp.nanosec)


def image_array(message: Any, where: str) -> NDArray[np.uint8]:
    """(height, width) uint8 view of a mono8 / 8UC1 sensor_msgs/Image (row padding removed)."""
    if message.encoding not in MONO_ENCODINGS:
        raise DatasetFormatError(
            f"{where}: image encoding {message.encoding!r}, expected one of {MONO_ENCODINGS}"
        )
    data = np.asarray(message.data, dtype=np.uint8)
    height, width, step = int(message.height), int(message.width), int(message.step)
    if step < width or data.size < height * step:
        raise DatasetFormatError(
            f"{where}: image of {height} x {width} (step {step}) holds only {data.size} bytes"
        )
    return data[: height * step].reshape(height, step)[:, :width]


class BagSequence:
    """A radar sequence recorded in a ROS bag.

    Args:
        path: a ROS 1 `.bag` file or a ROS 2 bag folder.
        topic: the scan topic; None takes the only mono8 / 8UC1 image topic.
        gt_topic: an Odometry or PoseStamped topic with ground truth; None uses the one named by
            the bag's scan info, if any.
        layout: preset name (see `LAYOUT_PRESETS`); None uses the bag's scan info, else "navtech".
        rows, azimuth_direction, range_resolution_m: override the layout's values.

    Raises:
        DatasetNotFoundError: the path does not exist or a named topic is not in the bag.
        DatasetFormatError: unreadable bag, no or several candidate image topics, no scans,
            or repeated scan stamps.
    """

    family: str = ROSBAG_FAMILY

    def __init__(
        self,
        path: Path,
        topic: str | None = None,
        gt_topic: str | None = None,
        layout: str | None = None,
        rows: Rows | None = None,
        azimuth_direction: Direction | None = None,
        range_resolution_m: float | None = None,
        scan_rate_hz: float = SCAN_RATE_HZ,
        gt_time_offset_s: float = 0.0,
    ) -> None:
        checks.finite("gt_time_offset_s", gt_time_offset_s)
        self.gt_time_offset_ns = int(round(gt_time_offset_s * NS_PER_S))
        self.path = Path(path)
        if not self.path.exists():
            raise DatasetNotFoundError(f"{self.path}: bag not found")
        self.name: str = self.path.stem if self.path.is_file() else self.path.name
        self._reader = self._open()
        info = self._scan_info()
        self._check_scan_info(info, layout, range_resolution_m)
        base = LAYOUT_PRESETS.get(str(info.get("layout"))) if info else None
        if base is not None and "range_resolution_m" in info:
            base = replace(base, range_resolution_m=float(info["range_resolution_m"]))
        self.layout = resolve_layout(layout, rows, azimuth_direction, range_resolution_m, base)
        self.sensor = str(info.get("sensor", ROSBAG_SENSOR))
        self.topic = topic or info.get("scan_topic") or self._default_topic()
        self._connections = self._topic_connections(self.topic, (IMAGE_TYPE,))
        self.gt_topic: str | None = gt_topic or info.get("gt_topic")
        self._index_scans()
        self._sweep_times = SweepTimes(self._times_ns, scan_rate_hz)

    # -- opening ------------------------------------------------------------------------------
    def _open(self) -> AnyReader:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.typesys import Stores, get_typestore

        reader = AnyReader([self.path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        try:
            reader.open()
        except (AnyReaderError, OSError, ValueError) as exc:
            raise DatasetFormatError(f"{self.path}: cannot read the bag ({exc})") from exc
        return reader

    def _decode(self, raw: bytes, msgtype: str) -> Any:
        """A deserialised message (rosbags builds its classes at run time, hence Any)."""
        return self._reader.deserialize(raw, msgtype)

    def _scan_info(self) -> dict[str, Any]:
        connections = [c for c in self._reader.connections if c.topic == SCAN_INFO_TOPIC]
        if not connections:  # (rosbags reads every topic when given no connections)
            return {}
        for _, _, raw in self._reader.messages(connections=connections):
            message = self._decode(raw, connections[0].msgtype)
            try:
                info = json.loads(message.data)
            except json.JSONDecodeError as exc:
                raise DatasetFormatError(f"{self.path}: {SCAN_INFO_TOPIC} is not JSON") from exc
            return info if isinstance(info, dict) else {}
        return {}

    def _check_scan_info(
        self, info: dict[str, Any], layout: str | None, range_resolution_m: float | None
    ) -> None:
        """A layout option that contradicts the bag's own scan info is refused (the bag says
        what it is; a wrong option would silently give a wrong trajectory)."""
        stated = info.get("layout")
        if layout is not None and stated is not None and layout != stated:
            raise ConfigError(
                f"{self.path}: --layout (dataset.layout) {layout!r} contradicts the bag's "
                f"{SCAN_INFO_TOPIC}, which says layout {stated!r}; leave the option out"
            )
        stated_m = info.get("range_resolution_m")
        if range_resolution_m is not None and stated_m is not None:
            if not np.isclose(float(stated_m), range_resolution_m, rtol=1e-9, atol=0.0):
                raise ConfigError(
                    f"{self.path}: dataset.range_resolution_m {range_resolution_m} contradicts "
                    f"the bag's {SCAN_INFO_TOPIC}, which says {stated_m}; leave the key out"
                )

    def _topic_connections(self, topic: str, types: tuple[str, ...]) -> list[Connection]:
        connections = [c for c in self._reader.connections if c.topic == topic]
        if not connections:
            known = ", ".join(sorted({c.topic for c in self._reader.connections}))
            raise DatasetNotFoundError(f"{self.path}: no topic {topic!r} (topics: {known})")
        if any(c.msgtype not in types for c in connections):
            raise DatasetFormatError(
                f"{self.path}: topic {topic} has type {connections[0].msgtype}, expected "
                f"{' or '.join(types)}"
            )
        return connections

    def _default_topic(self) -> str:
        """The only image topic whose first message is mono8 / 8UC1."""
        candidates = []
        described = []
        connections = self._reader.connections
        image_topics = sorted({c.topic for c in connections if c.msgtype == IMAGE_TYPE})
        for topic in image_topics:
            chosen = [c for c in connections if c.topic == topic]
            encoding = "no messages"
            for connection, _, raw in self._reader.messages(connections=chosen):
                encoding = str(self._decode(raw, connection.msgtype).encoding)
                if encoding in MONO_ENCODINGS:
                    candidates.append(topic)
                break
            described.append(f"{topic} ({encoding})")
        if len(candidates) == 1:
            return candidates[0]
        if candidates:
            found = f"{len(candidates)} mono8 image topics ({', '.join(candidates)})"
        else:
            others = sorted({f"{c.topic} ({c.msgtype})" for c in connections})
            others = [o for o in others if o.split(" ")[0] not in image_topics]
            found = "no mono8 image topic with messages; image topics: " + (
                ", ".join(described) or "none"
            )
            found += f"; other topics: {', '.join(others) or 'none'}"
        raise DatasetFormatError(
            f"{self.path}: {found}; choose the scan topic with --topic (or dataset.topic)"
        )

    def _index_scans(self) -> None:
        """One pass over the scan topic: header stamps and where each message is."""
        stamps: list[int] = []
        places: list[tuple[int, int]] = []  # (bag time, rank among messages at that bag time)
        previous, rank = -1, 0
        shape: tuple[int, int] | None = None
        for connection, bag_time, raw in self._reader.messages(connections=self._connections):
            message = self._decode(raw, connection.msgtype)
            size = (int(message.height), int(message.width))
            shape = shape or size
            if size != shape:
                raise DatasetFormatError(
                    f"{self.path}: {self.topic} message {len(stamps)} (stamp "
                    f"{stamp_ns(message.header)} ns) is a {size[0]} x {size[1]} image, the "
                    f"messages before it {shape[0]} x {shape[1]}: the image geometry changes "
                    "mid-bag"
                )
            rank = rank + 1 if bag_time == previous else 0
            previous = bag_time
            stamps.append(stamp_ns(message.header))
            places.append((bag_time, rank))
        if not stamps:
            raise DatasetFormatError(f"{self.path}: topic {self.topic} has no messages")
        order = np.argsort(np.array(stamps, dtype=np.int64), kind="stable")
        self._times_ns = np.array(stamps, dtype=np.int64)[order]
        self._places = [places[i] for i in order]
        repeated = np.flatnonzero(np.diff(self._times_ns) == 0)
        if repeated.size:
            raise DatasetFormatError(
                f"{self.path}: two scans on {self.topic} share the stamp "
                f"{self._times_ns[repeated[0]]} ns"
            )
        self._times_ns.flags.writeable = False

    # -- the sequence protocol ----------------------------------------------------------------
    def __len__(self) -> int:
        return len(self._places)

    def __getitem__(self, index: int) -> RadarFrame:
        """Read scan `index` (negative indices count from the end).

        Raises:
            IndexError: index out of range.
            DatasetFormatError: a message that is not a mono8 image of the layout.
        """
        index = frame_index(index, len(self))
        bag_time, rank = self._places[index]
        messages = self._reader.messages(
            connections=self._connections, start=bag_time, stop=bag_time + 1
        )
        for position, (connection, _, raw) in enumerate(messages):
            if position == rank:
                message = self._decode(raw, connection.msgtype)
                break
        else:
            raise DatasetFormatError(f"{self.path}: scan {index} vanished from {self.topic}")
        where = Path(f"{self.path}:{self.topic}[{index}]")
        image = image_array(message, str(where))
        if self.layout.oxford_header and image.shape[1] <= OXFORD_HEADER_BYTES:
            raise DatasetFormatError(f"{where}: image too narrow for the Oxford-form header")
        polar, azimuths, times = self.layout.decode(image, where)
        return RadarFrame(
            timestamp_ns=int(self._times_ns[index]),
            polar=polar,
            azimuths_rad=azimuths,
            range_resolution_m=self.layout.range_resolution_m,
            sensor=self.sensor,
            azimuth_times_ns=times
            if times is not None and np.any(times)
            else self._sweep_times(index, polar.shape[0]),
        )

    @property
    def timestamps_ns(self) -> NDArray[np.int64]:
        """(N,) int64 scan times [ns] (image header stamps), increasing; read-only."""
        return self._times_ns

    @cached_property
    def ground_truth(self) -> NDArray[np.float64] | None:
        """(N, 3) poses (x, y, yaw) from `gt_topic` at the scan times; None without a GT topic."""
        if self.gt_topic is None:
            return None
        connections = self._topic_connections(self.gt_topic, GT_TYPES)
        times: list[int] = []
        poses: list[tuple[float, float, float]] = []
        for connection, _, raw in self._reader.messages(connections=connections):
            message = self._decode(raw, connection.msgtype)
            pose = message.pose.pose if connection.msgtype == GT_TYPES[0] else message.pose
            q = pose.orientation
            yaw = float(yaw_from_quaternion([q.x, q.y, q.z, q.w]))
            times.append(stamp_ns(message.header))
            poses.append((pose.position.x, pose.position.y, yaw))
        if not times:
            raise DatasetFormatError(f"{self.path}: ground-truth topic {self.gt_topic} is empty")
        order = np.argsort(np.array(times, dtype=np.int64), kind="stable")
        stamps = np.array(times, dtype=np.int64)[order]
        keep = np.concatenate([[True], np.diff(stamps) > 0])
        return interpolate_poses(
            stamps[keep],
            np.array(poses)[order][keep],
            self._times_ns + self.gt_time_offset_ns,
            max_gap_ns=gt_max_gap_ns(stamps[keep]),
        )

    @property
    def ground_truth_source(self) -> GroundTruthSource | None:
        """The bag's ground-truth topic (its accuracy is the recording's own)."""
        if self.gt_topic is None:
            return None
        return GroundTruthSource(f"{self.path}: topic {self.gt_topic} (accuracy not stated)", 0.0)

    def close(self) -> None:
        """Close the bag (further frame reads fail)."""
        self._reader.close()

    # -- pickling (a `radar-slam batch` job carries its opened sequence to a worker) ------------
    def __getstate__(self) -> dict[str, Any]:
        """The index without the open bag reader (and its connections, which refer to it)."""
        return {k: v for k, v in self.__dict__.items() if k not in ("_reader", "_connections")}

    def __setstate__(self, state: dict[str, Any]) -> None:
        """The bag reopened at the same path; its scans are not indexed again."""
        self.__dict__.update(state)
        self._reader = self._open()
        self._connections = self._topic_connections(self.topic, (IMAGE_TYPE,))

    def __repr__(self) -> str:
        return f"BagSequence({str(self.path)!r}, topic={self.topic!r}, frames={len(self)})"


ROSBAG = register(
    Family(
        name=ROSBAG_FAMILY,
        open=BagSequence,
        detect=is_bag,
        layout=ROSBAG_LAYOUT,
        obtain=ROSBAG_OBTAIN,
        options=(
            "range_resolution_m",
            "topic",
            "gt_topic",
            "layout",
            "rows",
            "azimuth_direction",
            "scan_rate_hz",
            "gt_time_offset_s",
        ),
    )
)
