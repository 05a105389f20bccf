"""RADIATE ground truth from its GNSS/INS log (`GPS_IMU_Twist/`): a metre-level radar track.

RADIATE records an Advanced Navigation GNSS/INS without RTK corrections, so positions are good
to a metre or two: enough to score odometry over hundreds of metres, not to score a
registration. Its log is rough: about half the rows repeat the previous fix exactly (a 32 Hz
log of a slower fix), and the fix drops out for seconds at a time while driving.

What this module does with it:
- times as RADIATE writes them (`radiate_time_ns`: seconds, a dot, then an integer count of
  nanoseconds printed without leading zeros);
- repeated fixes dropped; latitude/longitude to metres in the UTM zone of the first fix (pyproj);
- heading from the INS orientation quaternion (yaw counter-clockwise from east), checked against
  the course over ground while moving (`GnssTrack.heading_bias_rad`, reported, not applied);
- the radar's pose from the antenna's through a lever arm (radar position in the vehicle frame
  of the antenna, x forward, y left [m]);
- a scan whose GT time lies in an outage (a gap between fixes longer than `MAX_FIX_GAP_NS`) or
  outside the log's span gets no ground truth (NaN), never an extrapolated one.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radar_slam.datasets._io import check_strictly_increasing
from radar_slam.datasets.mulran import interpolate_poses
from radar_slam.errors import DatasetFormatError
from raplace import NS_PER_S, compose, wrap_angle

logger = logging.getLogger(__name__)

GNSS_FOLDER = "GPS_IMU_Twist"
GNSS_TIMES_FILE = "GPS_IMU_Twist.txt"
GNSS_FILE_LINES = 18
"""Lines of one GPS_IMU_Twist file: fix, covariance (3), orientation, angular velocity,
acceleration, three covariances (3 each), twist linear, twist angular."""
LINE_FIX, LINE_ORIENTATION, LINE_TWIST = 0, 4, 16
GNSS_ACCURACY_M = 2.0
"""Stated accuracy of a GNSS fix without RTK [m]: metre level."""
MAX_FIX_GAP_NS = 500_000_000
"""A gap between fixes longer than this is an outage: scans inside it have no ground truth."""
STANDING_SPEED_MPS = 0.5
"""A held record whose INS speed is below this, and after which the next fix is where it was,
is the vehicle standing still, not an outage [m/s]."""
MOVING_SPEED_MPS = 3.0
"""Course over ground is compared with the INS heading only above this speed [m/s]."""
COURSE_MAX_STEP_NS = 200_000_000
"""... and only over steps between fixes at most this far apart (no course across outages)."""
WGS84 = "EPSG:4326"
EARTH_RADIUS_M = 6_371_000.0
UTM_NORTH_EPSG, UTM_SOUTH_EPSG = 32600, 32700

TIME_LINE = re.compile(r"^\s*Frame:\s*(\d+)\s+Time:\s*(\d+)(?:\.(\d+))?\s*$")


def radiate_time_ns(seconds: str, nanoseconds: str | None) -> int:
    """A RADIATE time `S.N` -> integer ns: N counts nanoseconds, printed without leading zeros.

    `1549985636.25327499` is 1549985636 s + 25327499 ns (not 0.25327499 s).

    Raises:
        ValueError: N has more than nine digits.
    """
    if nanoseconds is None:
        return int(seconds) * NS_PER_S
    if len(nanoseconds) > 9:
        raise ValueError(f"{seconds}.{nanoseconds}: more than nine digits of nanoseconds")
    return int(seconds) * NS_PER_S + int(nanoseconds)


def read_time_list(
    path: Path, strictly_increasing: bool = True
) -> tuple[list[str], NDArray[np.int64]]:
    """Read a RADIATE `Frame: NNNNNN Time: S.N` list (Navtech_Polar.txt, GPS_IMU_Twist.txt).

    Returns:
        (frame numbers as written, e.g. "000001"; (N,) int64 times [ns]).

    Raises:
        DatasetFormatError: a malformed line, no frames, or (if `strictly_increasing`) times
            that do not increase.
    """
    frames: list[str] = []
    times: list[int] = []
    for number, line in enumerate(path.read_text(encoding="ascii").splitlines(), start=1):
        if not line.strip():
            continue
        match = TIME_LINE.match(line)
        try:
            if match is None:
                raise ValueError("not a time line")
            times.append(radiate_time_ns(match[2], match[3]))
        except ValueError:
            raise DatasetFormatError(
                f"{path}: line {number} is {line!r}, expected 'Frame: NNNNNN Time: <s>.<ns>'"
            ) from None
        frames.append(match[1])
    if not frames:
        raise DatasetFormatError(f"{path}: no frames listed")
    stamps = np.array(times, dtype=np.int64)
    if strictly_increasing:
        check_strictly_increasing(stamps, path, "time")
    return frames, stamps


def _read_fix(path: Path) -> tuple[float, ...]:
    """(latitude deg, longitude deg, qx, qy, qz, qw, speed m/s) from one GPS_IMU_Twist file."""
    try:
        lines = [line for line in path.read_text(encoding="ascii").splitlines() if line.strip()]
        if len(lines) != GNSS_FILE_LINES:
            raise ValueError(f"{len(lines)} lines, expected {GNSS_FILE_LINES}")
        fix = [float(v) for v in lines[LINE_FIX].split(",")]
        quat = [float(v) for v in lines[LINE_ORIENTATION].split(",")]
        twist = [float(v) for v in lines[LINE_TWIST].split(",")]
        values = fix + quat + twist
        if len(fix) != 3 or len(quat) != 4 or len(twist) != 3 or not np.all(np.isfinite(values)):
            raise ValueError("expected 3 fix, 4 quaternion and 3 twist values, all finite")
    except (OSError, ValueError) as exc:
        raise DatasetFormatError(f"{path}: not a GPS_IMU_Twist record ({exc})") from None
    return fix[0], fix[1], quat[0], quat[1], quat[2], quat[3], float(np.hypot(twist[0], twist[1]))


def utm_epsg(latitude_deg: float, longitude_deg: float) -> int:
    """EPSG code of the WGS 84 / UTM zone holding a point."""
    zone = int((longitude_deg + 180.0) // 6.0) % 60 + 1
    return (UTM_NORTH_EPSG if latitude_deg >= 0 else UTM_SOUTH_EPSG) + zone


def yaw_enu(quat_xyzw: NDArray[np.float64]) -> NDArray[np.float64]:
    """(N,) yaw [rad] about +z of (N, 4) quaternions x, y, z, w."""
    x, y, z, w = quat_xyzw.T
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def heading_bias_rad(times_ns: NDArray[np.int64], poses: NDArray[np.float64]) -> tuple[float, int]:
    """Median of (INS heading - course over ground) while moving, and how many steps it used.

    Returns (NaN, 0) when the vehicle never moves fast enough between close fixes.
    """
    step = np.diff(poses[:, :2], axis=0)
    dt_ns = np.diff(times_ns)
    speed = np.hypot(step[:, 0], step[:, 1]) / (dt_ns / NS_PER_S)
    moving = (speed > MOVING_SPEED_MPS) & (dt_ns <= COURSE_MAX_STEP_NS)
    if not moving.any():
        return float("nan"), 0
    course = np.arctan2(step[:, 1], step[:, 0])
    mid_heading = poses[:-1, 2] + 0.5 * wrap_angle(np.diff(poses[:, 2]))
    difference = wrap_angle(mid_heading - course)[moving]
    return float(np.median(difference)), int(moving.sum())


@dataclass(frozen=True)
class GnssTrack:
    """The antenna's track from a GPS_IMU_Twist log, repeated fixes dropped.

    Attributes:
        times_ns: (M,) strictly increasing fix times [ns] (the GNSS clock).
        poses: (M, 3) T_utm_antenna: easting, northing [m] in `epsg`, INS heading [rad, CCW
            from east].
        epsg: the UTM zone's EPSG code.
        repeated_fixes: rows dropped because they repeat the previous fix exactly.
        outages: (K, 2) start and end [ns] of every gap between fixes longer than
            `MAX_FIX_GAP_NS`.
        heading_bias_rad: median INS heading minus course over ground while moving [rad].
        course_steps: how many steps between fixes that median used.
    """

    times_ns: NDArray[np.int64]
    poses: NDArray[np.float64]
    epsg: int
    repeated_fixes: int
    outages: NDArray[np.int64]
    heading_bias_rad: float
    course_steps: int

    def radar_poses(
        self, query_ns: ArrayLike, lever_arm_m: tuple[float, float] = (0.0, 0.0)
    ) -> NDArray[np.float64]:
        """(N, 3) T_utm_radar at GNSS-clock times `query_ns`; NaN in outages and off the span.

        Args:
            query_ns: (N,) times on the GNSS clock [ns].
            lever_arm_m: the radar's position in the antenna's vehicle frame (x forward, y left)
                [m]; the radar is taken to face forward.
        """
        query = np.asarray(query_ns, dtype=np.int64)
        antenna = interpolate_poses(self.times_ns, self.poses, query, max_gap_ns=MAX_FIX_GAP_NS)
        lever = np.array([lever_arm_m[0], lever_arm_m[1], 0.0])
        return compose(antenna, lever)

    def scans_in_outages(self, query_ns: ArrayLike) -> int:
        """How many of `query_ns` (GNSS clock) fall inside an outage."""
        query = np.asarray(query_ns, dtype=np.int64)
        inside = np.zeros(len(query), dtype=bool)
        for start, end in self.outages:
            inside |= (query > start) & (query < end)
        return int(inside.sum())


def held_records(records: NDArray[np.float64], times_ns: NDArray[np.int64]) -> NDArray[np.bool_]:
    """(N,) True for a record that repeats the previous fix while the fix is lost.

    The log repeats its last record until a new fix arrives: at its own rate when fixes are
    slower, for seconds in an outage. A run of repeats longer than `MAX_FIX_GAP_NS` whose INS
    speed is below `STANDING_SPEED_MPS` and after which the next fix is where it was is the
    vehicle standing: those records are kept (it stood there), not dropped as an outage.

    Args:
        records: (N, 7) latitude, longitude, quaternion (4), INS speed [m/s].
        times_ns: (N,) their times.
    """
    repeated = np.zeros(len(records), dtype=bool)
    repeated[1:] = np.all(records[1:, :2] == records[:-1, :2], axis=1)
    starts = np.flatnonzero(~repeated)
    ends = np.append(starts[1:], len(records))
    for start, end in zip(starts, ends, strict=True):
        if end - start < 2 or times_ns[end - 1] - times_ns[start] <= MAX_FIX_GAP_NS:
            continue
        standing = records[start, 6] < STANDING_SPEED_MPS
        if end < len(records):
            moved = _metres_between(records[start, :2], records[end, :2])
            standing = standing and moved <= GNSS_ACCURACY_M
        if standing:
            repeated[start:end] = False
    return repeated


def _metres_between(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """Distance between two (latitude, longitude) points [m] (equirectangular; short spans)."""
    lat = np.radians(0.5 * (a[0] + b[0]))
    d_north = np.radians(b[0] - a[0]) * EARTH_RADIUS_M
    d_east = np.radians(b[1] - a[1]) * EARTH_RADIUS_M * np.cos(lat)
    return float(np.hypot(d_north, d_east))


def read_gnss_track(folder: Path) -> GnssTrack:
    """Read `<folder>/GPS_IMU_Twist.txt` and `<folder>/GPS_IMU_Twist/NNNNNN.txt`.

    Raises:
        DatasetFormatError: a malformed time list or record, a listed file missing, fewer than
            two distinct fixes, or fix times that go back.
    """
    times_path = folder / GNSS_TIMES_FILE
    frames, stamps = read_time_list(times_path, strictly_increasing=False)
    records = np.array([_read_fix(folder / GNSS_FOLDER / f"{frame}.txt") for frame in frames])
    repeated = held_records(records, stamps)
    kept, times = records[~repeated], stamps[~repeated]
    if len(kept) < 2:
        raise DatasetFormatError(f"{times_path}: fewer than two distinct GNSS fixes")
    check_strictly_increasing(times, times_path, "time of a new fix")
    epsg = utm_epsg(float(kept[0, 0]), float(kept[0, 1]))
    from pyproj import Transformer  # PROJ loads only for a RADIATE drive's GNSS

    transformer = Transformer.from_crs(WGS84, f"EPSG:{epsg}", always_xy=True)
    easting, northing = transformer.transform(kept[:, 1], kept[:, 0])
    poses = np.stack([easting, northing, yaw_enu(kept[:, 2:6])], axis=-1)
    gaps = np.flatnonzero(np.diff(times) > MAX_FIX_GAP_NS)
    outages = np.stack([times[gaps], times[gaps + 1]], axis=-1).astype(np.int64)
    bias, steps = heading_bias_rad(times, poses)
    return GnssTrack(
        times_ns=times,
        poses=poses,
        epsg=epsg,
        repeated_fixes=int(repeated.sum()),
        outages=outages.reshape(-1, 2),
        heading_bias_rad=bias,
        course_steps=steps,
    )


def has_gnss(folder: Path) -> bool:
    """True when a RADIATE sequence folder holds a GPS_IMU_Twist log."""
    return (folder / GNSS_TIMES_FILE).is_file() and (folder / GNSS_FOLDER).is_dir()
