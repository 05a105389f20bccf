"""Checked readers shared by the dataset loaders: PNG scans, numeric CSV tables, stamp lists.

Every problem with a file becomes a `DatasetFormatError` naming the file and what is wrong, so
the CLI shows one line instead of a numpy or OpenCV traceback. Nothing here writes to disk.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from radar_slam.datasets._png import decode_gray8
from radar_slam.datasets.frame import RadarFrame
from radar_slam.datasets.navtech import (
    ENCODER_TICKS_PER_REV,
    OXFORD_HEADER_BYTES,
    encoder_to_azimuth_ccw,
)
from radar_slam.errors import DatasetFormatError

logger = logging.getLogger(__name__)

PNG_SUFFIX = ".png"


def read_gray_png(path: Path, shape: tuple[int, int] | None) -> NDArray[np.uint8]:
    """Read an 8-bit single-channel PNG and check its shape.

    Args:
        path: the PNG file.
        shape: required (rows, cols) of the image; None accepts any shape.

    Returns:
        (rows, cols) uint8 image, exactly as stored.

    Raises:
        DatasetFormatError: missing, unreadable or truncated file, not 8-bit grayscale, or a
            shape other than `shape`.
    """
    if not path.is_file():
        raise DatasetFormatError(f"{path}: scan file is missing")
    fast = _decode_fast(path)
    if fast is not None:
        return _checked_shape(fast, path, shape)
    # Another PNG layout, or a damaged file: OpenCV reads or rejects it.
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise DatasetFormatError(f"{path}: cannot decode PNG (unreadable or truncated file)")
    if image.ndim != 2 or image.dtype != np.uint8:
        raise DatasetFormatError(
            f"{path}: expected an 8-bit single-channel PNG, got {image.dtype} with shape "
            f"{image.shape}"
        )
    # OpenCV's stubs return a generic MatLike; the dtype was checked to be uint8 above.
    return _checked_shape(cast(NDArray[np.uint8], image), path, shape)


def transposed(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """A contiguous copy of `image.T` (a scan stored as range bins x azimuths turned into the
    (n_azimuths, n_bins) polar layout); OpenCV's blocked transpose is several times faster than
    numpy's strided copy of a full-resolution scan."""
    # OpenCV's stubs return a generic MatLike; a transpose keeps the uint8 dtype.
    return cast(NDArray[np.uint8], cv2.transpose(np.ascontiguousarray(image)))


def _checked_shape(
    image: NDArray[np.uint8], path: Path, shape: tuple[int, int] | None
) -> NDArray[np.uint8]:
    """`image` when its shape is `shape` (or `shape` is None); DatasetFormatError otherwise."""
    if shape is not None and image.shape != shape:
        raise DatasetFormatError(
            f"{path}: scan has shape {image.shape[0]} x {image.shape[1]}, expected "
            f"{shape[0]} x {shape[1]}"
        )
    return image


def _decode_fast(path: Path) -> NDArray[np.uint8] | None:
    """`path` decoded by the fast 8-bit grayscale decoder, or None (see `_png.decode_gray8`)."""
    try:
        data = path.read_bytes()
    except OSError:
        return None
    return decode_gray8(data)


@dataclass(frozen=True)
class NavtechHeader:
    """The 11-byte Oxford-style header at the start of each azimuth row.

    Attributes:
        times: (n_azimuths,) int64 timestamp of each azimuth, in the file's unit (us or ns).
        encoders: (n_azimuths,) int64 encoder counts in [0, 5600), clockwise from forward.
        valid: (n_azimuths,) bool, the valid flag (byte 10 non-zero).
    """

    times: NDArray[np.int64]
    encoders: NDArray[np.int64]
    valid: NDArray[np.bool_]


def parse_navtech_header(image: NDArray[np.uint8], path: Path) -> NavtechHeader:
    """Decode the per-row header of an Oxford-form scan (n_azimuths, 11 + n_bins).

    Bytes 0-7: int64 little-endian timestamp; 8-9: uint16 little-endian encoder; 10: valid flag.

    Raises:
        DatasetFormatError: encoder counts outside [0, 5600) or timestamps decreasing along the
            sweep (the file is not an Oxford-form scan or is corrupt).
    """
    header = np.ascontiguousarray(image[:, :OXFORD_HEADER_BYTES])
    times = header[:, 0:8].copy().view("<i8").reshape(-1).astype(np.int64)
    encoders = header[:, 8:10].copy().view("<u2").reshape(-1).astype(np.int64)
    valid = header[:, 10] != 0
    if np.any(encoders >= ENCODER_TICKS_PER_REV):
        bad = int(np.argmax(encoders >= ENCODER_TICKS_PER_REV))
        raise DatasetFormatError(
            f"{path}: row {bad} has encoder count {encoders[bad]} (must be < "
            f"{ENCODER_TICKS_PER_REV}); not an Oxford-form radar scan?"
        )
    if np.all(times == times[0]) or np.all(encoders == encoders[0]):
        raise DatasetFormatError(
            f"{path}: every azimuth row has the same header (time {times[0]}, encoder "
            f"{encoders[0]}); the 11-byte Navtech headers are zeroed or missing"
        )
    if np.any(np.diff(times) < 0):
        bad = int(np.argmax(np.diff(times) < 0)) + 1
        raise DatasetFormatError(f"{path}: azimuth timestamps decrease at row {bad}")
    return NavtechHeader(times=times, encoders=encoders, valid=valid)


@dataclass(frozen=True)
class OxfordFormScan:
    """An Oxford-form scan decoded into the project convention.

    Attributes:
        polar: (n_azimuths, n_bins) uint8 intensities (the image without its header columns).
        azimuths_rad: (n_azimuths,) CCW azimuths [rad] from the encoder counts.
        azimuth_times_ns: (n_azimuths,) header timestamps converted to [ns].
    """

    polar: NDArray[np.uint8]
    azimuths_rad: NDArray[np.float64]
    azimuth_times_ns: NDArray[np.int64]

    def frame(
        self,
        timestamp_ns: int,
        range_resolution_m: float,
        sensor: str,
        azimuth_offset_rad: float = 0.0,
    ) -> RadarFrame:
        """The scan as a `RadarFrame` with the given reference time [ns], bin size [m], sensor,
        its azimuths turned by `azimuth_offset_rad` [rad, CCW]."""
        return RadarFrame(
            timestamp_ns=int(timestamp_ns),
            polar=self.polar,
            azimuths_rad=self.azimuths_rad + azimuth_offset_rad,
            range_resolution_m=range_resolution_m,
            sensor=sensor,
            azimuth_times_ns=self.azimuth_times_ns,
        )


def decode_oxford_form(
    image: NDArray[np.uint8], path: Path, ns_per_time_unit: int
) -> OxfordFormScan:
    """Split an Oxford-form image (n_azimuths, 11 + n_bins) into polar data, azimuths and times.

    The one decoder of this layout (Oxford Radar RobotCar, Boreas, MulRan `polar_oxford_form`,
    our ROS bags): header times are in the file's unit, `ns_per_time_unit` converts them (1000
    for microseconds, 1 for nanoseconds). The polar array is a contiguous copy.
    """
    header = parse_navtech_header(image, path)
    return OxfordFormScan(
        polar=np.ascontiguousarray(image[:, OXFORD_HEADER_BYTES:]),
        azimuths_rad=encoder_to_azimuth_ccw(header.encoders),
        azimuth_times_ns=header.times * ns_per_time_unit,
    )


def encode_oxford_form(
    polar: NDArray[np.uint8],
    encoders: NDArray[np.int64],
    times: NDArray[np.int64],
) -> NDArray[np.uint8]:
    """The inverse of `decode_oxford_form`: prefix each azimuth row with the 11-byte header.

    Args:
        polar: (n_azimuths, n_bins) uint8.
        encoders: (n_azimuths,) encoder counts in [0, 5600).
        times: (n_azimuths,) int64 timestamps in the unit the reader will assume.

    Returns:
        (n_azimuths, 11 + n_bins) uint8 image; the valid flag is 255.
    """
    n = polar.shape[0]
    header = np.empty((n, OXFORD_HEADER_BYTES), dtype=np.uint8)
    header[:, 0:8] = np.asarray(times, dtype="<i8").reshape(n, 1).view(np.uint8)
    header[:, 8:10] = np.asarray(encoders, dtype="<u2").reshape(n, 1).view(np.uint8)
    header[:, 10] = 255
    return np.hstack([header, np.asarray(polar, dtype=np.uint8)])


def frame_index(index: int, length: int) -> int:
    """`index` into a sequence of `length` frames, negative counting from the end.

    Raises:
        IndexError: index out of range.
    """
    if not -length <= index < length:
        raise IndexError(f"frame {index} out of range for {length} frames")
    return index % length


def list_stamped_files(
    folder: Path, suffix: str = PNG_SUFFIX
) -> tuple[NDArray[np.int64], list[Path]]:
    """Files `<integer stamp><suffix>` in `folder`, sorted by stamp.

    Returns:
        (stamps (N,) int64, paths) in increasing stamp order. Other files are ignored and
        counted in one logged warning.

    Raises:
        DatasetFormatError: two files with the same stamp (e.g. `0123.png` and `123.png`).
    """
    entries = []
    ignored = []
    for path in folder.iterdir():
        if path.suffix.lower() == suffix and path.stem.isdigit() and path.is_file():
            entries.append((int(path.stem), path))
        elif not path.name.startswith("."):
            ignored.append(path.name)
    if ignored:
        logger.warning(
            "%s: ignored %d file(s) not named <integer time>%s (first: %s)",
            folder,
            len(ignored),
            suffix,
            sorted(ignored)[0],
        )
    entries.sort(key=lambda entry: entry[0])
    stamps = np.array([stamp for stamp, _ in entries], dtype=np.int64)
    duplicated = np.flatnonzero(np.diff(stamps) == 0)
    if duplicated.size:
        first = entries[int(duplicated[0])]
        second = entries[int(duplicated[0]) + 1]
        raise DatasetFormatError(
            f"{folder}: duplicated scan timestamp {first[0]} ({first[1].name}, {second[1].name})"
        )
    return stamps, [path for _, path in entries]


def check_strictly_increasing(stamps: NDArray[np.int64], path: Path, what: str) -> None:
    """Raise DatasetFormatError unless `stamps` increase strictly (no repeats, no disorder).

    Args:
        stamps: (N,) timestamps as read from `path`, in file order.
        path: file they came from (for the message).
        what: name of the column, e.g. "timestamp".
    """
    steps = np.diff(stamps)
    if np.any(steps <= 0):
        row = int(np.argmax(steps <= 0)) + 1
        problem = "duplicated" if steps[row - 1] == 0 else "unsorted"
        raise DatasetFormatError(
            f"{path}: {problem} {what} at data row {row + 1}: {stamps[row - 1]} then {stamps[row]}"
        )


def _is_numeric_row(line: str, delimiter: str | None) -> bool:
    """True when every field of `line` parses as a number (a data row, not a header)."""
    try:
        for field in line.split(delimiter):
            float(field)
    except ValueError:
        return False
    return True


def read_numeric_table(
    path: Path,
    n_columns: int,
    int_columns: tuple[int, ...],
    header_rows: int = 0,
    delimiter: str | None = ",",
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Read a numeric text table with a fixed column count.

    Integer columns (nanosecond or microsecond stamps) are parsed as exact int64, since float64
    cannot hold 19-digit timestamps; all columns are also parsed as float64.

    Args:
        path: the text file.
        n_columns: required number of columns on every row.
        int_columns: indices of the columns to return as int64.
        header_rows: at most this many leading lines are a header, recognised by content: a
            leading line is skipped only when it is not all numbers (a file saved without its
            header loses no data row).
        delimiter: column separator; None splits on whitespace.

    Returns:
        (ints (N, len(int_columns)) int64, values (N, n_columns) float64).

    Raises:
        DatasetFormatError: missing or empty file, a row with another column count, a non-numeric
            entry, or a NaN / infinite value.
    """
    if not path.is_file():
        raise DatasetFormatError(f"{path}: file is missing")
    try:
        text = path.read_text(encoding="ascii")
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasetFormatError(f"{path}: cannot read as text ({exc})") from exc
    lines = [line for line in text.splitlines() if line.strip()]
    skip = 0
    while skip < min(header_rows, len(lines)) and not _is_numeric_row(lines[skip], delimiter):
        skip += 1
    lines = lines[skip:]
    if not lines:
        raise DatasetFormatError(f"{path}: no data rows")
    counts = np.array([len(line.split(delimiter)) for line in lines])
    if np.any(counts != n_columns):
        bad = int(np.argmax(counts != n_columns))
        raise DatasetFormatError(
            f"{path}: data row {bad + 1} has {counts[bad]} columns, expected {n_columns}"
        )
    try:
        values = np.loadtxt(lines, delimiter=delimiter, dtype=np.float64, ndmin=2)
    except ValueError as exc:
        raise DatasetFormatError(f"{path}: non-numeric entry ({exc})") from exc
    finite = np.isfinite(values)
    if not finite.all():
        row, col = np.argwhere(~finite)[0]
        raise DatasetFormatError(
            f"{path}: data row {row + 1}, column {col} is {lines[row].split(delimiter)[col]!r} "
            "(NaN or infinite)"
        )
    try:
        ints = np.loadtxt(lines, delimiter=delimiter, dtype=np.int64, usecols=int_columns, ndmin=2)
    except ValueError as exc:
        raise DatasetFormatError(f"{path}: timestamp column is not an integer ({exc})") from exc
    return ints, values
