"""RADIATE loader (Navtech CTS350-X in fog, rain, snow): polar PNGs and their time list.

Sequence folder layout (RADIATE SDK and dataset documentation)::

    <seq>/Navtech_Polar/NNNNNN.png     576 rows (range bins of 0.175 m, ~100 m) x 400 columns
                                       (azimuths), uint8, no per-azimuth metadata
    <seq>/Navtech_Polar.txt            "Frame: NNNNNN Time: <seconds.nanoseconds>" per line

    <seq>/GPS_IMU_Twist.txt, GPS_IMU_Twist/NNNNNN.txt   optional GNSS/INS log (ground truth)

Geometry (checked against the dataset's own `Navtech_Cartesian` images, see the tests): column j
lies j / 400 of a turn CLOCKWISE from the vehicle's forward direction, bin k at (k + 0.5) *
0.175 m. Times are written as seconds, a dot and an integer count of nanoseconds without leading
zeros (`radiate_gnss.radiate_time_ns`).

Sweep times: the files give no per-azimuth times, so they are spread over one revolution at
`scan_rate_hz` (`sweep.SweepTimes`), and the listed time is taken as the END of the sweep: the
time the assembled image was written, after its last azimuth (as MulRan's file names). Taking the
middle instead would only move every pose by half a revolution in time, which the ground-truth
time offset absorbs.

Ground truth, when the folder holds `GPS_IMU_Twist/`: the GNSS/INS track (`radiate_gnss`), at
each scan's time plus `gt_time_offset_s` (the two clocks differ), moved to the radar by
`lever_arm_m`. Metre level: no RTK.
"""

from __future__ import annotations

from functools import cached_property
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from radar_slam.datasets._io import frame_index, read_gray_png, transposed
from radar_slam.datasets.frame import GroundTruthSource, RadarFrame
from radar_slam.datasets.navtech import (
    ENCODER_TICKS_PER_REV,
    SCAN_RATE_HZ,
    encoder_to_azimuth_ccw,
)
from radar_slam.datasets.radiate_gnss import (
    GNSS_ACCURACY_M,
    GnssTrack,
    has_gnss,
    read_gnss_track,
    read_time_list,
)
from radar_slam.datasets.registry import Family, register
from radar_slam.datasets.sweep import SweepTimes
from radar_slam.errors import DatasetFormatError, DatasetNotFoundError
from raplace import NS_PER_S, checks

RADIATE_FAMILY = "radiate"
RADIATE_SENSOR = "navtech-cts350x-radiate"
RADIATE_OBTAIN = "http://pro.hw.ac.uk/radiate/"
POLAR_FOLDER = "Navtech_Polar"
TIMES_FILE = "Navtech_Polar.txt"
RADIATE_N_AZIMUTHS = 400
RADIATE_N_BINS = 576
RADIATE_RANGE_RESOLUTION_M = 0.175

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


class RadiateSequence:
    """A RADIATE radar sequence; frames are read lazily, one PNG per `__getitem__`.

    Args:
        folder: the sequence folder (holding `Navtech_Polar/` and `Navtech_Polar.txt`).
        range_resolution_m: bin size [m] (0.175 by default).
        azimuth_offset_rad: added to every azimuth [rad, CCW].
        scan_rate_hz: revolutions per second the azimuth times are spread over (4).
        gt_time_offset_s: GNSS clock minus radar clock [s]: a scan stamped t takes the GNSS
            pose of time t + offset.
        lever_arm_m: the radar's (x forward, y left) position relative to the GNSS antenna [m].

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
        scan_rate_hz: float = SCAN_RATE_HZ,
        gt_time_offset_s: float = 0.0,
        lever_arm_m: tuple[float, float] = (0.0, 0.0),
    ) -> None:
        checks.positive("scan_rate_hz", scan_rate_hz)
        checks.finite("gt_time_offset_s", gt_time_offset_s)
        folder = Path(folder)
        polar = folder / POLAR_FOLDER
        if not polar.is_dir():
            raise DatasetNotFoundError(f"RADIATE sequence folder {polar} does not exist")
        frames, stamps = read_time_list(folder / TIMES_FILE)
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
        self._sweep_times = SweepTimes(stamps, scan_rate_hz)
        self.gt_time_offset_ns = int(round(gt_time_offset_s * NS_PER_S))
        self.lever_arm_m = (float(lever_arm_m[0]), float(lever_arm_m[1]))

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
            azimuth_times_ns=self._sweep_times(index, RADIATE_N_AZIMUTHS),
        )

    @property
    def timestamps_ns(self) -> NDArray[np.int64]:
        """(N,) int64 scan times [ns] from `Navtech_Polar.txt`, increasing; read-only."""
        return self._times_ns

    @cached_property
    def gnss(self) -> GnssTrack | None:
        """The GNSS/INS track of `GPS_IMU_Twist/`, read on first use; None without one."""
        return read_gnss_track(self.folder) if has_gnss(self.folder) else None

    @cached_property
    def ground_truth(self) -> NDArray[np.float64] | None:
        """(N, 3) T_utm_radar (easting, northing, heading) at each scan; None without GNSS.

        NaN rows: scans whose GNSS time lies in an outage or outside the log.
        """
        if self.gnss is None:
            return None
        return self.gnss.radar_poses(self._times_ns + self.gt_time_offset_ns, self.lever_arm_m)

    @property
    def ground_truth_source(self) -> GroundTruthSource | None:
        """GNSS/INS without RTK (metre level), with this log's outages and heading bias."""
        if self.gnss is None:
            return None
        query = self._times_ns + self.gt_time_offset_ns
        bias_deg = float(np.degrees(self.gnss.heading_bias_rad))
        span = (query < self.gnss.times_ns[0]) | (query > self.gnss.times_ns[-1])
        return GroundTruthSource(
            description=f"GNSS/INS without RTK ({self.folder / 'GPS_IMU_Twist'}), metre level",
            accuracy_m=GNSS_ACCURACY_M,
            notes={
                "gnss_repeated_fixes_dropped": self.gnss.repeated_fixes,
                "gnss_outages_over_0.5s": len(self.gnss.outages),
                "scans_in_gnss_outages": self.gnss.scans_in_outages(query),
                "scans_outside_gnss_span": int(span.sum()),
                "ins_heading_minus_course_deg": round(bias_deg, 2),
                "gt_time_offset_s": self.gt_time_offset_ns / NS_PER_S,
                "lever_arm_m": f"{self.lever_arm_m[0]} {self.lever_arm_m[1]}",
            },
        )

    def __repr__(self) -> str:
        return f"RadiateSequence({str(self.folder)!r}, frames={len(self)})"


RADIATE = register(
    Family(
        name=RADIATE_FAMILY,
        open=RadiateSequence,
        detect=is_radiate_sequence,
        layout=RADIATE_LAYOUT,
        obtain=RADIATE_OBTAIN,
        options=(
            "range_resolution_m",
            "azimuth_offset_rad",
            "scan_rate_hz",
            "gt_time_offset_s",
            "lever_arm_m",
        ),
    )
)
