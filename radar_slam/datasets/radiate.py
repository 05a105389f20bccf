"""RADIATE loader (Navtech CTS350-X in fog, rain, snow): polar PNGs and their time list.

Sequence folder layout (RADIATE SDK and dataset documentation)::

    <seq>/Navtech_Polar/NNNNNN.png     576 rows (range bins of 0.175 m, ~100 m) x 400 columns
                                       (azimuths), uint8, no per-azimuth metadata
    <seq>/Navtech_Polar.txt            "Frame: NNNNNN Time: <seconds.nanoseconds>" per line

Geometry (checked against the dataset's own `Navtech_Cartesian` images, see the tests): column j
lies j / 400 of a turn CLOCKWISE from the vehicle's forward direction, bin k at (k + 0.5) *
0.175 m. The frame's `timestamp_ns` is the listed time; the files give no per-azimuth times, so
`azimuth_times_ns` is None. RADIATE's GPS/IMU files are not read: sequences have no ground truth
here.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from radar_slam.datasets._io import (
    check_strictly_increasing,
    frame_index,
    read_gray_png,
    transposed,
)
from radar_slam.datasets.frame import RadarFrame
from radar_slam.datasets.navtech import ENCODER_TICKS_PER_REV, encoder_to_azimuth_ccw
from radar_slam.datasets.registry import Family, register
from radar_slam.errors import DatasetFormatError, DatasetNotFoundError
from radar_slam.trajectory import parse_seconds_as_ns

RADIATE_FAMILY = "radiate"
RADIATE_SENSOR = "navtech-cts350x-radiate"
RADIATE_OBTAIN = "http://pro.hw.ac.uk/radiate/"
POLAR_FOLDER = "Navtech_Polar"
TIMES_FILE = "Navtech_Polar.txt"
RADIATE_N_AZIMUTHS = 400
RADIATE_N_BINS = 576
RADIATE_RANGE_RESOLUTION_M = 0.175
TIME_LINE = re.compile(r"^\s*Frame:\s*(\d+)\s+Time:\s*([0-9]+(?:\.[0-9]*)?)\s*$")

RADIATE_LAYOUT = (
    "<root>/radiate/<SEQ>/Navtech_Polar/NNNNNN.png (576 bins x 400 azimuths) and "
    "<SEQ>/Navtech_Polar.txt"
)


def is_radiate_sequence(folder: Path) -> bool:
    """True when `folder` holds `Navtech_Polar/` and `Navtech_Polar.txt`."""
    return (folder / POLAR_FOLDER).is_dir() and (folder / TIMES_FILE).is_file()


def radiate_azimuths_rad(n_azimuths: int = RADIATE_N_AZIMUTHS) -> NDArray[np.float64]:
    """CCW azimuth [rad] of each polar column: column j is j / n of a turn clockwise."""
    encoders = np.arange(n_azimuths) * (ENCODER_TICKS_PER_REV // n_azimuths)
    return encoder_to_azimuth_ccw(encoders)


def read_frame_times(path: Path) -> tuple[list[str], NDArray[np.int64]]:
    """Read `Navtech_Polar.txt`.

    Returns:
        (frame numbers as written, e.g. "000001"; times (N,) int64 [ns], strictly increasing).

    Raises:
        DatasetFormatError: a line that is not `Frame: N Time: S`, or unsorted times.
    """
    frames: list[str] = []
    times: list[int] = []
    for number, line in enumerate(path.read_text(encoding="ascii").splitlines(), start=1):
        if not line.strip():
            continue
        match = TIME_LINE.match(line)
        if match is None:
            raise DatasetFormatError(
                f"{path}: line {number} is {line!r}, expected 'Frame: NNNNNN Time: <seconds>'"
            )
        frames.append(match[1])
        times.append(parse_seconds_as_ns(match[2]))
    if not frames:
        raise DatasetFormatError(f"{path}: no frames listed")
    stamps = np.array(times, dtype=np.int64)
    check_strictly_increasing(stamps, path, "time")
    return frames, stamps


class RadiateSequence:
    """A RADIATE radar sequence; frames are read lazily, one PNG per `__getitem__`.

    Args:
        folder: the sequence folder (holding `Navtech_Polar/` and `Navtech_Polar.txt`).
        range_resolution_m: bin size [m] (0.175 by default).

    Raises:
        DatasetNotFoundError: the folder has no `Navtech_Polar/`.
        DatasetFormatError: a malformed time list, or listed frames missing from the folder.
    """

    family: str = RADIATE_FAMILY

    def __init__(
        self,
        folder: Path,
        range_resolution_m: float = RADIATE_RANGE_RESOLUTION_M,
        azimuth_offset_rad: float = 0.0,
    ) -> None:
        folder = Path(folder)
        polar = folder / POLAR_FOLDER
        if not polar.is_dir():
            raise DatasetNotFoundError(f"RADIATE sequence folder {polar} does not exist")
        frames, stamps = read_frame_times(folder / TIMES_FILE)
        paths = [polar / f"{frame}.png" for frame in frames]
        missing = [path.name for path in paths if not path.is_file()]
        if missing:
            raise DatasetFormatError(
                f"{folder / TIMES_FILE}: {len(missing)} of {len(paths)} listed frames are missing "
                f"from {polar} (first: {missing[0]})"
            )
        self.name: str = folder.name
        self.folder = folder
        self.azimuth_offset_rad = float(azimuth_offset_rad)
        self.range_resolution_m = range_resolution_m
        self._paths = paths
        self._times_ns = stamps
        self._times_ns.flags.writeable = False

    def __len__(self) -> int:
        return len(self._paths)

    def __getitem__(self, index: int) -> RadarFrame:
        """Read scan `index` (negative indices count from the end).

        Raises:
            IndexError: index out of range.
            DatasetFormatError: unreadable PNG or a shape other than 576 x 400.
        """
        index = frame_index(index, len(self))
        image = read_gray_png(self._paths[index], (RADIATE_N_BINS, RADIATE_N_AZIMUTHS))
        return RadarFrame(
            timestamp_ns=int(self._times_ns[index]),
            polar=transposed(image),
            azimuths_rad=radiate_azimuths_rad() + self.azimuth_offset_rad,
            range_resolution_m=self.range_resolution_m,
            sensor=RADIATE_SENSOR,
        )

    @property
    def timestamps_ns(self) -> NDArray[np.int64]:
        """(N,) int64 scan times [ns] from `Navtech_Polar.txt`, increasing; read-only."""
        return self._times_ns

    @property
    def ground_truth(self) -> NDArray[np.float64] | None:
        """Always None: RADIATE's GPS/IMU files are not read as ground truth."""
        return None

    def __repr__(self) -> str:
        return f"RadiateSequence({str(self.folder)!r}, frames={len(self)})"


RADIATE = register(
    Family(
        name=RADIATE_FAMILY,
        open=RadiateSequence,
        detect=is_radiate_sequence,
        layout=RADIATE_LAYOUT,
        obtain=RADIATE_OBTAIN,
    )
)
