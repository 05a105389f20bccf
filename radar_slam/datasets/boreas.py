"""Boreas loader (Navtech CIR204-H, later firmware): Oxford-form polar PNGs, Applanix GT.

Sequence folder layout (from the public Boreas documentation, DATA_REFERENCE.md of pyboreas)::

    boreas-YYYY-MM-DD-HH-MM/radar/<t_us>.png      400 rows (azimuths) x (11 + n_bins) uint8:
                                                  per row an int64 LE time [us], a uint16 LE
                                                  encoder count (5600 per turn), a spare byte,
                                                  then the range bins
    boreas-YYYY-MM-DD-HH-MM/applanix/radar_poses.csv   optional GT (header row, 13 columns)

Times: file names and the per-azimuth times are UTC microseconds; the file name is the MIDDLE of
the sweep (the time of azimuth floor(400 / 2) - 1), and `radar_poses.csv` has one row per scan
at that same time. The frame's `timestamp_ns` is the file time.

Geometry: azimuth = encoder * 2 pi / 5600, clockwise seen from above (the radar frame is
x-forward, y-right, z-down), as in the Oxford layout; the bytes are decoded by the one Oxford-form
decoder in `radar_slam.datasets._io`. The bin size depends on the sensor firmware: 0.0596 m for
sequences recorded before 2021-09-21 and 0.04381 m from then on, chosen from the date in the
sequence name (overridable with `dataset: range_resolution_m`). The bin count is taken from the
images.

Ground truth: `radar_poses.csv` columns GPSTime [us], easting, northing, altitude [m], velocity
(east, north, up), roll, pitch, heading [rad], angular velocity (z, y, x). Positions are in a
fixed East-North-Up frame; the rotation is yaw-pitch-roll (heading, pitch, roll) from the radar
frame to ENU. With roll ~ pi (z-down), the heading is the angle of the radar's +x (forward) axis
counter-clockwise from East, which is the yaw of our x-forward, y-left radar frame, so
T_world_radar = (easting, northing, heading). Rows are interpolated to the scan times (exact
when they match, as in the dataset).
"""

from __future__ import annotations

import logging
import re
from datetime import date
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
from radar_slam.datasets.mulran import gt_max_gap_ns, interpolate_poses
from radar_slam.datasets.navtech import OXFORD_HEADER_BYTES
from radar_slam.datasets.registry import Family, register
from radar_slam.errors import DatasetFormatError, DatasetNotFoundError
from raplace import NS_PER_S, checks

logger = logging.getLogger(__name__)

BOREAS_FAMILY = "boreas"
BOREAS_SENSOR = "navtech-cir204h-boreas"
BOREAS_OBTAIN = (
    "https://www.boreas.utias.utoronto.ca (aws s3 sync s3://boreas/<SEQ> <SEQ> --no-sign-request)"
)
RADAR_FOLDER = "radar"
POSES_FILE = "applanix/radar_poses.csv"
POSES_COLUMNS = 13
"""GPSTime, easting, northing, altitude, vel_east, vel_north, vel_up, roll, pitch, heading,
angvel_z, angvel_y, angvel_x."""
COL_X, COL_Y, COL_HEADING = 1, 2, 9
NS_PER_US = 1000
N_AZIMUTHS = 400

RANGE_RESOLUTION_BEFORE_M = 0.0596
"""Bin size of sequences recorded before `FIRMWARE_CHANGE` [m]."""
RANGE_RESOLUTION_AFTER_M = 0.04381
"""Bin size of sequences recorded on or after `FIRMWARE_CHANGE` [m]."""
FIRMWARE_CHANGE = date(2021, 9, 21)
SEQUENCE_DATE = re.compile(r"(\d{4})-(\d{2})-(\d{2})")

BOREAS_LAYOUT = (
    "<root>/boreas/boreas-YYYY-MM-DD-HH-MM/radar/<t_us>.png (400 x (11 + bins), Oxford-form "
    "header per azimuth), optional applanix/radar_poses.csv"
)


def sequence_date(name: str) -> date | None:
    """The recording date in a sequence name such as `boreas-2021-09-02-11-42`, or None."""
    match = SEQUENCE_DATE.search(name)
    if match is None:
        return None
    try:
        return date(int(match[1]), int(match[2]), int(match[3]))
    except ValueError:
        return None


def range_resolution_for(name: str) -> float | None:
    """The bin size [m] of a Boreas sequence from the date in its name, or None without a date."""
    recorded = sequence_date(name)
    if recorded is None:
        return None
    return RANGE_RESOLUTION_BEFORE_M if recorded < FIRMWARE_CHANGE else RANGE_RESOLUTION_AFTER_M


def is_boreas_sequence(folder: Path) -> bool:
    """True for `radar/` PNGs plus `applanix/radar_poses.csv` or a `boreas-<date>` name, and no
    Oxford `radar.timestamps` list."""
    radar = folder / RADAR_FOLDER
    if not radar.is_dir() or (folder / "radar.timestamps").exists():
        return False
    named = folder.name.lower().startswith("boreas") and sequence_date(folder.name) is not None
    return ((folder / POSES_FILE).is_file() or named) and any(radar.glob("*.png"))


def read_radar_poses(path: Path) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Read `applanix/radar_poses.csv`.

    Returns:
        (times (N,) int64 [ns] strictly increasing, T_world_radar (N, 3) as (easting, northing,
        heading) [m, m, rad]).
    """
    ints, values = read_numeric_table(path, POSES_COLUMNS, int_columns=(0,), header_rows=1)
    times_us = ints[:, 0]
    check_strictly_increasing(times_us, path, "GPSTime")
    return times_us * NS_PER_US, values[:, [COL_X, COL_Y, COL_HEADING]]


class BoreasSequence:
    """A Boreas radar sequence; frames are read lazily, one PNG per `__getitem__`.

    Args:
        folder: the sequence folder (holding `radar/`).
        range_resolution_m: bin size [m]; None chooses it from the date in the folder name.

    Raises:
        DatasetNotFoundError: `folder/radar` does not exist.
        DatasetFormatError: no scans, duplicated scan times, or no date in the name and no
            range resolution given.
    """

    family: str = BOREAS_FAMILY

    def __init__(
        self,
        folder: Path,
        range_resolution_m: float | None = None,
        azimuth_offset_rad: float = 0.0,
        gt_time_offset_s: float = 0.0,
    ) -> None:
        checks.finite("gt_time_offset_s", gt_time_offset_s)
        folder = Path(folder)
        radar = folder / RADAR_FOLDER
        if not radar.is_dir():
            raise DatasetNotFoundError(f"Boreas sequence folder {radar} does not exist")
        scan_us, paths = list_stamped_files(radar)
        if not paths:
            raise DatasetFormatError(f"{radar}: no scans (<t_us>.png files)")
        if range_resolution_m is None:
            range_resolution_m = range_resolution_for(folder.name)
        if range_resolution_m is None:
            raise DatasetFormatError(
                f"{folder}: no recording date in the name (boreas-YYYY-MM-DD-HH-MM), so the "
                f"range resolution is unknown ({RANGE_RESOLUTION_BEFORE_M} m before "
                f"{FIRMWARE_CHANGE}, {RANGE_RESOLUTION_AFTER_M} m after); set "
                "dataset: range_resolution_m in a --config file"
            )
        self.name: str = folder.name
        self.folder = folder
        self.azimuth_offset_rad = float(azimuth_offset_rad)
        self.gt_time_offset_ns = int(round(gt_time_offset_s * NS_PER_S))
        self.range_resolution_m = float(range_resolution_m)
        self._paths = paths
        self._times_ns = scan_us * NS_PER_US
        self._times_ns.flags.writeable = False
        self._shape: tuple[int, int] | None = None
        gt_path = folder / POSES_FILE
        self.gt_path: Path | None = gt_path if gt_path.is_file() else None

    def __len__(self) -> int:
        return len(self._paths)

    def __getitem__(self, index: int) -> RadarFrame:
        """Read scan `index` (negative indices count from the end).

        Every scan must have the shape of the first one read (400 rows, 11 + n_bins columns).

        Raises:
            IndexError: index out of range.
            DatasetFormatError: unreadable PNG, wrong shape, or a corrupt header.
        """
        index = frame_index(index, len(self))
        path = self._paths[index]
        image = read_gray_png(path, self._shape)
        if self._shape is None:
            if image.shape[0] != N_AZIMUTHS or image.shape[1] <= OXFORD_HEADER_BYTES:
                raise DatasetFormatError(
                    f"{path}: scan has shape {image.shape[0]} x {image.shape[1]}, expected "
                    f"{N_AZIMUTHS} x (11 + bins)"
                )
            self._shape = (int(image.shape[0]), int(image.shape[1]))
        scan = decode_oxford_form(image, path, NS_PER_US)
        return scan.frame(
            int(self._times_ns[index]),
            self.range_resolution_m,
            BOREAS_SENSOR,
            azimuth_offset_rad=self.azimuth_offset_rad,
        )

    @property
    def timestamps_ns(self) -> NDArray[np.int64]:
        """(N,) int64 scan times [ns] (mid-sweep, the file names), increasing; read-only."""
        return self._times_ns

    @cached_property
    def ground_truth(self) -> NDArray[np.float64] | None:
        """(N, 3) T_enu_radar (easting, northing, heading) at each scan time; None without GT.

        Rows are NaN for scans outside the time span of `radar_poses.csv` or inside an outage of
        it (`interpolate_poses`).
        """
        if self.gt_path is None:
            return None
        times, poses = read_radar_poses(self.gt_path)
        result = interpolate_poses(
            times,
            poses,
            self._times_ns + self.gt_time_offset_ns,
            max_gap_ns=gt_max_gap_ns(times),
        )
        missing = int(np.isnan(result[:, 0]).sum())
        if missing:
            logger.warning(
                "%s: %d of %d scans lie outside its time span or in an outage of it; their ground "
                "truth is NaN",
                self.gt_path,
                missing,
                len(self),
            )
        return result

    @property
    def ground_truth_source(self) -> GroundTruthSource | None:
        """Boreas radar_poses.csv: post-processed GNSS/INS with RTK (centimetre level)."""
        if self.gt_path is None:
            return None
        return GroundTruthSource(f"Boreas post-processed RTK GNSS/INS ({self.gt_path})", 0.05)

    def __repr__(self) -> str:
        return f"BoreasSequence({str(self.folder)!r}, frames={len(self)})"


BOREAS = register(
    Family(
        name=BOREAS_FAMILY,
        open=BoreasSequence,
        detect=is_boreas_sequence,
        layout=BOREAS_LAYOUT,
        obtain=BOREAS_OBTAIN,
        detect_priority=1,
    )
)
