"""Oxford Radar RobotCar loader (Navtech CTS350-X): header-prefixed polar PNGs, odometry GT.

Sequence folder layout::

    <seq>/radar/<t_us>.png            400 x 3779 uint8: per azimuth row an 11-byte header
                                      (int64 LE time [us], uint16 LE encoder, uint8 valid flag),
                                      then 3768 range bins. File name = first azimuth's time.
    <seq>/radar.timestamps            "<t_us> <flag>" per line: the scan list
    <seq>/gt/radar_odometry.csv       optional GT (header row; 10 columns)

Reference time: each GT row's `source_timestamp` is the mid-scan time of the scan named by its
`source_radar_timestamp` (checked on the shipped samples: it equals the mean of the first and
last azimuth times, to the microsecond). The GT pose of a scan refers to that time, so the frame's
`timestamp_ns` is `source_timestamp` of the scan's row; a scan without a row gets its file time
plus half a scan period. This keeps `timestamps_ns` known without reading any PNG.

Ground truth: row (x, y, yaw) is the later (source) scan's pose in the earlier (destination)
scan's radar frame, x-forward y-RIGHT z-down. In our x-forward y-left frame that motion is
(x, -y, -yaw), and T_w(k+1) = T_w(k) * T(x, -y, -yaw). The world frame is the first scan of the
folder (GT[0] = 0); only the rows linking the folder's scans are chained. If the chain breaks
(a missing row), the poses after the break are NaN and a warning is logged.
"""

from __future__ import annotations

import logging
from functools import cached_property
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from radar_slam.datasets._io import (
    check_strictly_increasing,
    decode_oxford_form,
    frame_index,
    list_stamped_files,
    read_gray_png,
    read_numeric_table,
)
from radar_slam.datasets.frame import GroundTruthSource, RadarFrame
from radar_slam.datasets.mulran import interpolate_poses
from radar_slam.datasets.navtech import (
    OXFORD_HEADER_BYTES,
    OXFORD_N_AZIMUTHS,
    OXFORD_N_BINS,
    OXFORD_RANGE_RESOLUTION_M,
    SCAN_RATE_HZ,
)
from radar_slam.datasets.registry import Family, register
from radar_slam.errors import DatasetFormatError, DatasetNotFoundError
from raplace import NS_PER_S, NS_PER_US, US_PER_S, checks, compose

logger = logging.getLogger(__name__)

OXFORD_GT_ACCURACY_M = 0.1
"""Stated accuracy of the chained ground-truth odometry over a partial sequence [m]."""

OXFORD_FAMILY = "oxford"
OXFORD_SENSOR = "navtech-cts350x"
OXFORD_OBTAIN = "https://oxford-robotics-institute.github.io/radar-robotcar-dataset"
RADAR_FOLDER = "radar"
TIMESTAMPS_FILE = "radar.timestamps"
TIMESTAMPS_COLUMNS = 2
ODOMETRY_FILE = "gt/radar_odometry.csv"
ODOMETRY_COLUMNS = 10
"""source_timestamp, destination_timestamp, x, y, z, roll, pitch, yaw, source_radar_timestamp,
destination_radar_timestamp."""
COL_SOURCE_TIME, COL_X, COL_Y, COL_YAW = 0, 2, 3, 7
ODOMETRY_INT_COLUMNS = (0, 8, 9)
"""Integer columns read exactly: source_timestamp, source_radar_ts, destination_radar_ts."""
NOMINAL_SCAN_PERIOD_US = int(round(US_PER_S / SCAN_RATE_HZ))
SCAN_PERIOD_TOLERANCE = 0.2
"""A median gap between scans within +-20 % of 250 ms is taken as the scan period."""
Y_RIGHT_TO_Y_LEFT = np.array([1.0, -1.0, -1.0])
"""Multiply an (x, y, yaw) motion in x-forward y-right z-down by this to get x-forward y-left."""

OXFORD_LAYOUT = (
    "<root>/oxford/<SEQ>/radar/<t_us>.png (400 x 3779, 11-byte header per azimuth), "
    "<SEQ>/radar.timestamps, optional <SEQ>/gt/radar_odometry.csv"
)


def is_oxford_sequence(folder: Path) -> bool:
    """True when `folder` has `radar/` holding PNGs directly, or `radar.timestamps`."""
    radar = folder / RADAR_FOLDER
    if not radar.is_dir():
        return False
    return (folder / TIMESTAMPS_FILE).is_file() or any(radar.glob("*.png"))


def read_radar_timestamps(path: Path) -> NDArray[np.int64]:
    """Read `radar.timestamps` ("<t_us> <flag>" lines): (N,) int64 scan times [us], increasing."""
    ints, _ = read_numeric_table(
        path, TIMESTAMPS_COLUMNS, int_columns=(0,), header_rows=1, delimiter=None
    )
    stamps = ints[:, 0]
    check_strictly_increasing(stamps, path, "timestamp")
    return stamps


class RadarOdometryTable:
    """The rows of `gt/radar_odometry.csv`, indexed by radar scan time.

    Attributes:
        source_time_us: (M,) mid-scan time of the source (later) scan [us].
        source_radar_us: (M,) file time of the source (later) scan [us], strictly increasing.
        destination_radar_us: (M,) file time of the destination (earlier) scan [us].
        motion: (M, 3) source scan pose in the destination scan's frame, converted to our
            x-forward y-left convention (x, -y, -yaw) [m, m, rad].
    """

    def __init__(self, path: Path) -> None:
        ints, values = read_numeric_table(
            path, ODOMETRY_COLUMNS, int_columns=ODOMETRY_INT_COLUMNS, header_rows=1
        )
        self.path = path
        self.source_time_us = ints[:, 0]
        self.source_radar_us = ints[:, 1]
        self.destination_radar_us = ints[:, 2]
        check_strictly_increasing(self.source_radar_us, path, "source_radar_timestamp")
        self.motion = values[:, [COL_X, COL_Y, COL_YAW]] * Y_RIGHT_TO_Y_LEFT
        self._row_from_destination = {
            int(stamp): row for row, stamp in enumerate(self.destination_radar_us)
        }

    def rows_of_sources(self, scan_us: NDArray[np.int64]) -> NDArray[np.int64]:
        """(N,) row whose source scan is each of `scan_us`, or -1 when there is none."""
        rows = np.searchsorted(self.source_radar_us, scan_us)
        rows_clipped = np.minimum(rows, len(self.source_radar_us) - 1)
        found = self.source_radar_us[rows_clipped] == scan_us
        return np.where(found, rows_clipped, -1)

    def chain(self, scan_us: NDArray[np.int64]) -> NDArray[np.float64]:
        """Compose the motions linking consecutive scans of `scan_us` (sorted file times).

        Returns:
            (N, 3) T_first_scan (x, y, yaw); row 0 is zero; rows after a break in the chain
            (no row leaving a scan) are NaN.
        """
        poses = np.full((len(scan_us), 3), np.nan)
        poses[0] = 0.0
        pose = poses[0]
        current = int(scan_us[0])
        for k in range(1, len(scan_us)):
            target = int(scan_us[k])
            while current < target:  # sequential: each pose builds on the previous one
                row = self._row_from_destination.get(current)
                if row is None:
                    logger.warning(
                        "%s: no row leaves radar scan %d; ground truth of the %d scans from %d "
                        "on is NaN",
                        self.path,
                        current,
                        len(scan_us) - k,
                        target,
                    )
                    return poses
                pose = compose(pose, self.motion[row])
                current = int(self.source_radar_us[row])
            if current != target:
                logger.warning(
                    "%s: odometry chain skips radar scan %d; its ground truth and later ones "
                    "are NaN",
                    self.path,
                    target,
                )
                return poses
            poses[k] = pose
        return poses


def reference_times_ns(
    scan_us: NDArray[np.int64], table: RadarOdometryTable | None
) -> NDArray[np.int64]:
    """Reference (mid-scan) time of each scan [ns].

    The GT row's `source_timestamp` when the scan has a row; else file time + half the scan
    period (the median gap between scans when plausible, else 250 ms).
    """
    gaps = np.diff(scan_us)
    period_us = float(np.median(gaps)) if gaps.size else float(NOMINAL_SCAN_PERIOD_US)
    if abs(period_us - NOMINAL_SCAN_PERIOD_US) > SCAN_PERIOD_TOLERANCE * NOMINAL_SCAN_PERIOD_US:
        period_us = float(NOMINAL_SCAN_PERIOD_US)
    times_us = scan_us + int(round(period_us / 2))
    if table is not None:
        rows = table.rows_of_sources(scan_us)
        has_row = rows >= 0
        times_us = np.where(has_row, table.source_time_us[np.maximum(rows, 0)], times_us)
    return times_us.astype(np.int64) * NS_PER_US


class OxfordSequence:
    """An Oxford Radar RobotCar sequence; frames are read lazily, one PNG per `__getitem__`.

    Args:
        folder: the sequence folder (holding `radar/` and `radar.timestamps`).
        range_resolution_m: size of one range bin [m] (documentation 0.0438; SDK 0.0432).
        azimuth_offset_rad: added to every azimuth [rad, CCW] (the `dataset:` config section).

    Raises:
        DatasetNotFoundError: `folder` or its `radar/` folder does not exist.
        DatasetFormatError: no scans, scans listed in radar.timestamps missing from `radar/`,
            unsorted or duplicated timestamps, or a malformed GT file.
    """

    family: str = OXFORD_FAMILY

    def __init__(
        self,
        folder: Path,
        range_resolution_m: float = OXFORD_RANGE_RESOLUTION_M,
        azimuth_offset_rad: float = 0.0,
        gt_time_offset_s: float = 0.0,
    ) -> None:
        checks.finite("gt_time_offset_s", gt_time_offset_s)
        folder = Path(folder)
        radar = folder / RADAR_FOLDER
        if not radar.is_dir():
            raise DatasetNotFoundError(f"Oxford sequence folder {radar} does not exist")
        timestamps_path = folder / TIMESTAMPS_FILE
        if timestamps_path.is_file():
            scan_us = read_radar_timestamps(timestamps_path)
            paths = [radar / f"{stamp}.png" for stamp in scan_us]
            missing = [path.name for path in paths if not path.is_file()]
            if missing:
                raise DatasetFormatError(
                    f"{timestamps_path}: {len(missing)} of {len(paths)} listed scans are missing "
                    f"from {radar} (first: {missing[0]})"
                )
            listed = {path.name for path in paths}
            unlisted = sorted(
                p.name for p in radar.iterdir() if p.suffix == ".png" and p.name not in listed
            )
            if unlisted:
                logger.warning(
                    "%s: ignored %d scan(s) of %s not listed in it (first: %s)",
                    timestamps_path,
                    len(unlisted),
                    radar,
                    unlisted[0],
                )
        else:
            logger.info("%s absent: taking the scan list from %s", timestamps_path, radar)
            scan_us, paths = list_stamped_files(radar)
        if not paths:
            raise DatasetFormatError(f"{radar}: no scans (<t_us>.png files)")
        self.name: str = folder.name
        self.folder = folder
        self.range_resolution_m = range_resolution_m
        self.azimuth_offset_rad = float(azimuth_offset_rad)
        self.gt_time_offset_ns = int(round(gt_time_offset_s * NS_PER_S))
        self._paths = paths
        self._scan_us = scan_us
        gt_path = folder / ODOMETRY_FILE
        self.gt_path: Path | None = gt_path if gt_path.is_file() else None
        self._odometry = RadarOdometryTable(gt_path) if self.gt_path is not None else None
        self._times_ns = reference_times_ns(scan_us, self._odometry)
        check_strictly_increasing(
            self._times_ns, self.gt_path or timestamps_path, "scan reference time"
        )
        self._times_ns.flags.writeable = False

    def __len__(self) -> int:
        return len(self._paths)

    def __getitem__(self, index: int) -> RadarFrame:
        """Read scan `index` (negative indices count from the end).

        Raises:
            IndexError: index out of range.
            DatasetFormatError: unreadable PNG, wrong shape, or a corrupt header.
        """
        index = frame_index(index, len(self))
        path = self._paths[index]
        image = read_gray_png(path, (OXFORD_N_AZIMUTHS, OXFORD_HEADER_BYTES + OXFORD_N_BINS))
        scan = decode_oxford_form(image, path, NS_PER_US)
        return scan.frame(
            int(self._times_ns[index]),
            self.range_resolution_m,
            OXFORD_SENSOR,
            azimuth_offset_rad=self.azimuth_offset_rad,
        )

    @property
    def timestamps_ns(self) -> NDArray[np.int64]:
        """(N,) int64 reference (mid-scan) time of each scan [ns], increasing; read-only."""
        return self._times_ns

    @property
    def scan_file_times_us(self) -> NDArray[np.int64]:
        """(N,) int64 file-name time (first azimuth) of each scan [us]."""
        return self._scan_us

    @cached_property
    def ground_truth(self) -> NDArray[np.float64] | None:
        """(N, 3) radar poses (x, y, yaw) in the frame of the folder's first scan; None w/o GT."""
        if self._odometry is None:
            return None
        chain = self._odometry.chain(self._scan_us)
        if self.gt_time_offset_ns == 0:
            return chain
        # The chain is sampled at the scans themselves: shifted, it is interpolated between them.
        known = np.isfinite(chain[:, 0])
        return interpolate_poses(
            self._times_ns[known], chain[known], self._times_ns + self.gt_time_offset_ns
        )

    @property
    def ground_truth_source(self) -> GroundTruthSource | None:
        """Oxford's ground-truth radar odometry, chained from the folder's first scan."""
        if self.gt_path is None:
            return None
        return GroundTruthSource(
            f"Oxford ground-truth radar odometry chained from the first scan ({self.gt_path})",
            OXFORD_GT_ACCURACY_M,
        )

    def __repr__(self) -> str:
        return f"OxfordSequence({str(self.folder)!r}, frames={len(self)})"


OXFORD = register(
    Family(
        name=OXFORD_FAMILY,
        open=OxfordSequence,
        detect=is_oxford_sequence,
        layout=OXFORD_LAYOUT,
        obtain=OXFORD_OBTAIN,
    )
)
