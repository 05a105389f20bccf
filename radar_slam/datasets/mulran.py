"""MulRan loader (Navtech CIR204-H): polar PNG scans and `global_pose.csv` ground truth.

Sequence folder layouts accepted (the first scan folder found wins, in this order)::

    <seq>/sensor_data/radar/polar/<t_ns>.png      3360 rows (bins) x 400 cols (azimuths)
    <seq>/radar/polar/<t_ns>.png
    <seq>/polar/<t_ns>.png
    <seq>/sensor_data/radar/polar_oxford_form/<t_ns>.png   400 x (11 + 3360), Oxford header, ns
    <seq>/radar/polar_oxford_form/<t_ns>.png
    <seq>/polar_oxford_form/<t_ns>.png
    <seq>/global_pose.csv                         optional GT: t_ns + 3x4 row-major [R|t]
    <seq>/sensor_data/navtech_top_stamp.csv       optional, one t_ns per line (or <seq>/...)

Time conventions: a scan's file name is the time of its LAST azimuth (end of sweep). The frame's
`timestamp_ns` is that time, and the ground truth refers to it. Plain polar PNGs carry no
per-azimuth times; they are spread uniformly over one scan period ending at the file time (the
period is the gap to the previous radar stamp, or 250 ms when that gap is implausible).

Ground truth: `global_pose.csv` holds the vehicle BASE pose in MulRan's UTM-like world frame. It
is interpolated to each scan time (x, y linearly; yaw linearly after unwrapping) and the radar
mounting `MULRAN_T_BASE_RADAR` is applied: T_world_radar = T_world_base * T_base_radar. A scan
outside the GT time span, or between two GT samples more than two GT sample periods apart (the
median gap of global_pose.csv, at most 0.5 s), has no ground truth (NaN pose, counted in one
logged warning): ground truth is never held at its end nor stretched over an outage.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from radar_slam.datasets._io import (
    check_strictly_increasing,
    frame_index,
    list_stamped_files,
    parse_navtech_header,
    read_gray_png,
    read_numeric_table,
    transposed,
)
from radar_slam.datasets.frame import GroundTruthSource, RadarFrame
from radar_slam.datasets.navtech import (
    MULRAN_ENCODER_STEP,
    MULRAN_FIRST_ENCODER,
    MULRAN_N_AZIMUTHS,
    MULRAN_N_BINS,
    MULRAN_RANGE_RESOLUTION_M,
    MULRAN_T_BASE_RADAR,
    OXFORD_HEADER_BYTES,
    SCAN_RATE_HZ,
    encoder_to_azimuth_ccw,
)
from radar_slam.datasets.registry import Family, register
from radar_slam.datasets.sweep import SweepTimes
from radar_slam.errors import DatasetFormatError, DatasetNotFoundError
from raplace import NS_PER_S, checks, compose, wrap_angle

logger = logging.getLogger(__name__)

MULRAN_FAMILY = "mulran"
MULRAN_SENSOR = "navtech-cir204h"
MULRAN_OBTAIN = "https://sites.google.com/view/mulran-pr"

POLAR_FOLDERS = ("sensor_data/radar/polar", "radar/polar", "polar")
"""Folders of plain polar PNGs (bins x azimuths), relative to the sequence folder."""
OXFORD_FORM_FOLDERS = (
    "sensor_data/radar/polar_oxford_form",
    "radar/polar_oxford_form",
    "polar_oxford_form",
)
"""Folders of Oxford-form PNGs (azimuths x (11-byte header + bins), header times in ns)."""
GLOBAL_POSE_FILE = "global_pose.csv"
GLOBAL_POSE_COLUMNS = 13
"""t_ns, then the 3x4 row-major [R|t] of the base in the world frame."""
GP_COL_R00, GP_COL_X, GP_COL_R10, GP_COL_Y = 1, 4, 5, 8
STAMP_FILES = ("sensor_data/navtech_top_stamp.csv", "navtech_top_stamp.csv")

MULRAN_GT_DESCRIPTION = "MulRan global_pose.csv: GPS/INS and fibre-optic gyro fused by SLAM"
MULRAN_GT_ACCURACY_M = 0.1
"""Stated accuracy of MulRan's fused GT positions [m] (decimetre level)."""
GT_CLAMP_NS = 500_000_000
"""Upper bound of the GT tolerance (one GT sample period, at most this)."""
OUTAGE_PERIODS = 2
"""Two GT samples more than this many tolerances apart enclose an outage: scans between them
have no GT (a single dropped sample or jitter is still interpolated over)."""

MULRAN_LAYOUT = (
    "<root>/mulran/<SEQ>/sensor_data/radar/polar/<t_ns>.png (also <SEQ>/radar/polar/, "
    "<SEQ>/polar/ or polar_oxford_form/), optional <SEQ>/global_pose.csv and "
    "<SEQ>/sensor_data/navtech_top_stamp.csv"
)


@dataclass(frozen=True)
class ScanFolder:
    """Where a MulRan sequence keeps its scans.

    Attributes:
        path: folder of `<t_ns>.png` files.
        oxford_form: True for `polar_oxford_form` (azimuth rows with an 11-byte header),
            False for plain polar images (bin rows, azimuth columns, no metadata).
    """

    path: Path
    oxford_form: bool


def find_scan_folder(sequence_folder: Path) -> ScanFolder | None:
    """The scan folder of a MulRan sequence (plain polar preferred), or None when there is none."""
    for relative in POLAR_FOLDERS:
        if (sequence_folder / relative).is_dir():
            return ScanFolder(sequence_folder / relative, oxford_form=False)
    for relative in OXFORD_FORM_FOLDERS:
        if (sequence_folder / relative).is_dir():
            return ScanFolder(sequence_folder / relative, oxford_form=True)
    return None


def is_mulran_sequence(folder: Path) -> bool:
    """True when `folder` holds one of the MulRan scan folders."""
    return folder.is_dir() and find_scan_folder(folder) is not None


def column_azimuths_rad(n_azimuths: int = MULRAN_N_AZIMUTHS) -> NDArray[np.float64]:
    """CCW azimuth [rad] of each polar column: column j is encoder 9 + 14 j, clockwise."""
    encoders = MULRAN_FIRST_ENCODER + MULRAN_ENCODER_STEP * np.arange(n_azimuths)
    return encoder_to_azimuth_ccw(encoders)


def read_global_pose(path: Path) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Read MulRan `global_pose.csv`.

    Returns:
        (times (N,) int64 [ns] strictly increasing, T_world_base (N, 3) SE(2) poses: x = column 4,
        y = column 8, yaw = atan2(R10, R00) [m, m, rad]).

    Raises:
        DatasetFormatError: wrong column count, non-numeric or NaN entries, unsorted or
            duplicated times.
    """
    ints, values = read_numeric_table(path, GLOBAL_POSE_COLUMNS, int_columns=(0,), header_rows=1)
    times = ints[:, 0]
    check_strictly_increasing(times, path, "timestamp")
    yaw = np.arctan2(values[:, GP_COL_R10], values[:, GP_COL_R00])
    poses = np.stack([values[:, GP_COL_X], values[:, GP_COL_Y], yaw], axis=-1)
    return times, poses


def interpolate_poses(
    times_ns: NDArray[np.int64],
    poses: NDArray[np.float64],
    query_ns: NDArray[np.int64],
    max_gap_ns: int | None = None,
) -> NDArray[np.float64]:
    """Interpolate SE(2) poses to query times; NaN rows where the poses do not tell.

    x and y are linear in time; yaw is linear after unwrapping (so it turns the short way through
    +-pi). A query outside [times[0], times[-1]] has no pose (its row is NaN): the end pose is
    never held and nothing is extrapolated. With `max_gap_ns`, a query between two samples more
    than that apart lies in an outage of the poses and has none either.

    Args:
        times_ns: (N,) strictly increasing pose times [ns].
        poses: (N, 3) poses (x, y, yaw).
        query_ns: (M,) times to interpolate at [ns].
        max_gap_ns: the longest gap between two samples that is interpolated over [ns] (e.g.
            `gt_max_gap_ns(times_ns)`, the family's tolerance); None interpolates over any gap.

    Returns:
        (M, 3) interpolated poses, yaw wrapped to [-pi, pi); NaN rows as above.
    """
    origin = times_ns[0]
    t = (times_ns - origin).astype(np.float64)
    q = (query_ns - origin).astype(np.float64)
    yaw = np.unwrap(poses[:, 2])
    result = np.stack(
        [np.interp(q, t, poses[:, 0]), np.interp(q, t, poses[:, 1]), np.interp(q, t, yaw)],
        axis=-1,
    )
    result[:, 2] = wrap_angle(result[:, 2])
    result[~gt_covers(times_ns, query_ns, max_gap_ns)] = np.nan
    return result


def gt_covers(
    times_ns: NDArray[np.int64], query_ns: NDArray[np.int64], max_gap_ns: int | None = None
) -> NDArray[np.bool_]:
    """(M,) True where a query can be interpolated: inside the span of `times_ns`, at a sample
    time or between two samples at most `max_gap_ns` apart (None: any)."""
    query_ns = np.asarray(query_ns, dtype=np.int64)
    inside = (query_ns >= times_ns[0]) & (query_ns <= times_ns[-1])
    if max_gap_ns is None:
        return inside
    after = np.clip(np.searchsorted(times_ns, query_ns, side="left"), 0, len(times_ns) - 1)
    before = np.clip(after - 1, 0, len(times_ns) - 1)
    at_sample = times_ns[after] == query_ns
    short_gap = times_ns[after] - times_ns[before] <= max_gap_ns
    return inside & (at_sample | short_gap)


def gt_tolerance_ns(times_ns: NDArray[np.int64]) -> int:
    """The GT tolerance: one GT sample period (the median gap), at most `GT_CLAMP_NS` [ns]."""
    if len(times_ns) < 2:
        return 0
    return int(min(GT_CLAMP_NS, np.median(np.diff(times_ns))))


def gt_max_gap_ns(times_ns: NDArray[np.int64]) -> int:
    """The longest GT gap interpolated over: `OUTAGE_PERIODS` tolerances [ns]; a longer one is
    an outage (a single dropped sample or jitter is not)."""
    return OUTAGE_PERIODS * gt_tolerance_ns(times_ns)


def radar_ground_truth(gt_path: Path, scan_stamps_ns: NDArray[np.int64]) -> NDArray[np.float64]:
    """T_world_radar (N, 3) at each (GT-clock) scan time, from `global_pose.csv` (NaN rows
    outside GT)."""
    times, base_poses = read_global_pose(gt_path)
    tolerance_ns = gt_tolerance_ns(times)
    base_at_scans = interpolate_poses(
        times, base_poses, scan_stamps_ns, max_gap_ns=gt_max_gap_ns(times)
    )
    missing = int(np.isnan(base_at_scans[:, 0]).sum())
    if missing:
        logger.warning(
            "%s: %d of %d scans lie outside its time span or in an outage (samples more than "
            "2 x %.3f s apart); they have no ground truth",
            gt_path,
            missing,
            len(scan_stamps_ns),
            tolerance_ns / NS_PER_S,
        )
    return compose(base_at_scans, MULRAN_T_BASE_RADAR)


def _read_stamp_list(path: Path) -> NDArray[np.int64]:
    """Read navtech_top_stamp.csv: one t_ns per line, strictly increasing."""
    ints, _ = read_numeric_table(path, 1, int_columns=(0,), header_rows=1)
    stamps = ints[:, 0]
    check_strictly_increasing(stamps, path, "timestamp")
    return stamps


class MulRanSequence:
    """A MulRan radar sequence; frames are read lazily, one PNG per `__getitem__`.

    Args:
        folder: the sequence folder (e.g. `<root>/mulran/KAIST01`).
        n_bins: range bins per azimuth (3360 for the CIR204-H).
        range_resolution_m: size of one bin [m].
        family: family name reported by the sequence (a generator writing MulRan layout may pass
            its own).
        azimuth_offset_rad: added to every azimuth [rad, CCW] (the `dataset:` config section).
        scan_rate_hz: revolutions per second of the radar (the `dataset:` config section; 4 for
            MulRan's CIR204-H). A scan's azimuths are spread over the gap to the previous radar
            stamp when that is within 20 % of one revolution, else over one revolution.
        gt_time_offset_s: GT clock minus radar clock [s]: a scan stamped t takes the GT pose of
            time t + offset.

    Raises:
        DatasetNotFoundError: `folder` does not exist.
        DatasetFormatError: no scan folder, no scans, duplicated scan stamps, or a malformed
            navtech_top_stamp.csv.
    """

    def __init__(
        self,
        folder: Path,
        n_bins: int = MULRAN_N_BINS,
        range_resolution_m: float = MULRAN_RANGE_RESOLUTION_M,
        family: str = MULRAN_FAMILY,
        azimuth_offset_rad: float = 0.0,
        scan_rate_hz: float = SCAN_RATE_HZ,
        gt_time_offset_s: float = 0.0,
    ) -> None:
        checks.positive("scan_rate_hz", scan_rate_hz)
        checks.finite("gt_time_offset_s", gt_time_offset_s)
        folder = Path(folder)
        if not folder.is_dir():
            raise DatasetNotFoundError(f"MulRan sequence folder {folder} does not exist")
        scans = find_scan_folder(folder)
        if scans is None:
            looked = ", ".join(POLAR_FOLDERS + OXFORD_FORM_FOLDERS)
            raise DatasetFormatError(f"{folder}: no MulRan scan folder (looked for {looked})")
        stamps, paths = list_stamped_files(scans.path)
        if not paths:
            raise DatasetFormatError(f"{scans.path}: no scans (<t_ns>.png files)")
        self.name: str = folder.name
        self.family: str = family
        self.folder = folder
        self.scan_folder = scans
        self.n_bins = n_bins
        self.range_resolution_m = range_resolution_m
        self.azimuth_offset_rad = float(azimuth_offset_rad)
        self._paths = paths
        self._stamps = stamps
        self._stamps.flags.writeable = False
        gt_path = folder / GLOBAL_POSE_FILE
        self.gt_path: Path | None = gt_path if gt_path.is_file() else None
        radar_stamps = self._radar_stamps(folder, stamps)
        self.gt_time_offset_ns = int(round(gt_time_offset_s * NS_PER_S))
        self.scan_rate_hz = float(scan_rate_hz)
        self._sweep_times = SweepTimes(stamps, self.scan_rate_hz, radar_stamps)

    @staticmethod
    def _radar_stamps(folder: Path, scan_stamps: NDArray[np.int64]) -> NDArray[np.int64]:
        """Stamps of every recorded sweep: navtech_top_stamp.csv when present, cross-checked."""
        for relative in STAMP_FILES:
            path = folder / relative
            if path.is_file():
                listed = _read_stamp_list(path)
                unlisted = int(np.count_nonzero(~np.isin(scan_stamps, listed)))
                if unlisted:
                    logger.warning(
                        "%s: %d of %d scan file names are not listed in it",
                        path,
                        unlisted,
                        len(scan_stamps),
                    )
                    return np.union1d(listed, scan_stamps)
                return listed
        return scan_stamps

    def __len__(self) -> int:
        return len(self._paths)

    def __getitem__(self, index: int) -> RadarFrame:
        """Read scan `index` (negative indices count from the end).

        Raises:
            IndexError: index out of range.
            DatasetFormatError: unreadable PNG or wrong shape.
        """
        index = frame_index(index, len(self))
        path = self._paths[index]
        stamp = int(self._stamps[index])
        if self.scan_folder.oxford_form:
            image = read_gray_png(path, (MULRAN_N_AZIMUTHS, OXFORD_HEADER_BYTES + self.n_bins))
            header = parse_navtech_header(image, path)
            polar = np.ascontiguousarray(image[:, OXFORD_HEADER_BYTES:])
            azimuths = encoder_to_azimuth_ccw(header.encoders)
            azimuth_times = header.times
        else:
            image = read_gray_png(path, (self.n_bins, MULRAN_N_AZIMUTHS))
            polar = transposed(image)
            azimuths = column_azimuths_rad(MULRAN_N_AZIMUTHS)
            azimuth_times = self._sweep_times(index, MULRAN_N_AZIMUTHS)
        return RadarFrame(
            timestamp_ns=stamp,
            polar=polar,
            azimuths_rad=azimuths + self.azimuth_offset_rad,
            range_resolution_m=self.range_resolution_m,
            sensor=MULRAN_SENSOR,
            azimuth_times_ns=azimuth_times,
        )

    @property
    def timestamps_ns(self) -> NDArray[np.int64]:
        """(N,) int64 scan times [ns] (end of sweep = file name), increasing; read-only."""
        return self._stamps

    @cached_property
    def ground_truth(self) -> NDArray[np.float64] | None:
        """(N, 3) T_world_radar (x, y, yaw) at each scan time, MulRan world frame; None without GT.

        Read and interpolated on first access. Rows are NaN for scans outside the GT time span
        or in an outage of it (`interpolate_poses`).
        """
        if self.gt_path is None:
            return None
        return radar_ground_truth(self.gt_path, self._stamps + self.gt_time_offset_ns)

    @property
    def ground_truth_source(self) -> GroundTruthSource | None:
        """MulRan's global_pose.csv, or the simulator's exact poses."""
        if self.gt_path is None:
            return None
        if self.family != MULRAN_FAMILY:
            return GroundTruthSource(f"simulated poses ({self.gt_path})", 0.0)
        return GroundTruthSource(MULRAN_GT_DESCRIPTION + f" ({self.gt_path})", MULRAN_GT_ACCURACY_M)

    def __repr__(self) -> str:
        return f"MulRanSequence({str(self.folder)!r}, frames={len(self)})"


MULRAN = register(
    Family(
        name=MULRAN_FAMILY,
        open=MulRanSequence,
        detect=is_mulran_sequence,
        layout=MULRAN_LAYOUT,
        obtain=MULRAN_OBTAIN,
        options=("range_resolution_m", "azimuth_offset_rad", "scan_rate_hz", "gt_time_offset_s"),
    )
)
