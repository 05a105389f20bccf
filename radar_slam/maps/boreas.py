"""Localisation results in the form of the Boreas localisation benchmark (pure I/O, no GTSAM).

The benchmark scores, for each scan s2 of the localised sequence, the pose T_s1_s2 relative to a
scan s1 of the map sequence that the method chooses. One space-separated line per scan:

    t_s2 t_s1 r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz [36 values]

t_s2, t_s1: the scans' times, integer microseconds (Boreas stamps; nanoseconds are truncated);
then the upper 3x4 block of the SE(3) matrix T_s1_s2 row by row; then, optionally, the 6x6
inverse covariance of the pose, row by row, in the tangent order (x, y, z, roll, pitch, yaw) of a
perturbation on the left (T_s1_s2 = Exp(xi) T_estimate, xi in s1's axes), which is how the
benchmark forms its error, pred * gt^-1.

Here s1 is the map keyframe of the scan's latest fix, and T_s1_s2 its SE(2) pose lifted to SE(3)
(z, roll, pitch zero). Those three are not estimated: their rows and columns of the inverse
covariance are zero (no information). Lost scans have no line.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from radar_slam.errors import RadarSlamError
from radar_slam.maps.localizer import Localization
from raplace import adjoint

FloatArray = NDArray[np.float64]
BOREAS_FILE = "localization_boreas.txt"
NS_PER_US = 1000
POSE_COLUMNS = 14
"""Two times and the 3x4 block."""
COLUMNS = POSE_COLUMNS + 36
"""... and the 6x6 inverse covariance."""
_PLANAR = (0, 1, 5)
"""Indices of x, y and yaw in the benchmark's 6-vector tangent order."""


class BoreasFormatError(RadarSlamError):
    """A Boreas localisation file that cannot be read (names the file and line)."""


@dataclass(frozen=True)
class BoreasLocalization:
    """The content of a Boreas localisation file, SE(2) part.

    Attributes:
        scan_us: (K,) times of the localised scans [us].
        reference_us: (K,) times of their map scans [us].
        relative: (K, 3) T_s1_s2 as (x, y [m], yaw [rad]).
        information: (K, 6, 6) inverse covariances in the benchmark's order (None if absent).
    """

    scan_us: NDArray[np.int64]
    reference_us: NDArray[np.int64]
    relative: FloatArray
    information: FloatArray | None


def left_covariance(relative: FloatArray, covariance: FloatArray) -> FloatArray:
    """(3, 3) covariance of a perturbation on the left of T (in its reference frame's axes),
    from the (3, 3) covariance of one on the right (in its own axes; `Localization.covariance`):
    Exp(Ad(T) xi) T = T Exp(xi). Order (x, y [m], yaw [rad])."""
    carry = adjoint(relative)
    left = carry @ covariance @ carry.T
    return np.asarray(0.5 * (left + left.T), dtype=np.float64)


def information_6x6(covariance_left: FloatArray) -> FloatArray:
    """(6, 6) inverse covariance in the order (x, y, z, roll, pitch, yaw) from the (3, 3) planar
    one; the unestimated z, roll and pitch carry no information (zero rows and columns)."""
    info = np.zeros((6, 6))
    info[np.ix_(_PLANAR, _PLANAR)] = np.linalg.inv(covariance_left)
    return info


def boreas_table(
    fixes: Sequence[Localization], keyframe_ns: NDArray[np.int64]
) -> tuple[NDArray[np.int64], FloatArray]:
    """((K, 2) times [us], (K, 48) 3x4 blocks and inverse covariances) of the localised scans.

    Args:
        keyframe_ns: (M,) times of the map keyframes [ns] (`Map.keyframes["timestamp_ns"]`).
    """
    stamps, values = [], []
    for f in fixes:
        if not f.localised:
            continue
        x, y, yaw = (float(v) for v in f.relative)
        c, s = np.cos(yaw), np.sin(yaw)
        block = [c, -s, 0.0, x, s, c, 0.0, y, 0.0, 0.0, 1.0, 0.0]
        info = information_6x6(left_covariance(f.relative, f.covariance))
        stamps.append((f.timestamp_ns // NS_PER_US, int(keyframe_ns[f.map_key]) // NS_PER_US))
        values.append(block + info.ravel().tolist())
    return (
        np.array(stamps, dtype=np.int64).reshape(-1, 2),
        np.array(values, dtype=np.float64).reshape(-1, COLUMNS - 2),
    )


def write_boreas(path: Path, fixes: Sequence[Localization], keyframe_ns: NDArray[np.int64]) -> None:
    """One line per localised scan (module docstring); `keyframe_ns` as in `boreas_table`."""
    stamps, values = boreas_table(fixes, keyframe_ns)
    lines = [
        f"{a} {b} " + " ".join(repr(float(v)) for v in row) + "\n"
        for (a, b), row in zip(stamps.tolist(), values.tolist(), strict=True)
    ]
    Path(path).write_text("".join(lines))


def read_boreas(path: Path) -> BoreasLocalization:
    """Read a Boreas localisation file (14 or 50 columns a line, all lines alike).

    Raises:
        BoreasFormatError: unreadable file, a wrong column count, a bad number.
    """
    path = Path(path)
    try:
        lines = [line.split() for line in path.read_text().splitlines() if line.strip()]
    except (OSError, UnicodeDecodeError) as exc:
        raise BoreasFormatError(f"{path}: cannot read: {exc}") from None
    width = len(lines[0]) if lines else POSE_COLUMNS
    stamps, values = [], []
    for number, tokens in enumerate(lines, start=1):
        if len(tokens) != width or width not in (POSE_COLUMNS, COLUMNS):
            raise BoreasFormatError(
                f"{path}:{number}: expected {POSE_COLUMNS} or {COLUMNS} columns on every line, "
                f"found {len(tokens)}"
            )
        try:
            stamps.append((int(tokens[0]), int(tokens[1])))
            values.append([float(v) for v in tokens[2:]])
        except ValueError:
            raise BoreasFormatError(f"{path}:{number}: not a number in the line") from None
    table = np.array(values, dtype=np.float64).reshape(-1, width - 2)
    if not np.isfinite(table).all():
        raise BoreasFormatError(f"{path}: NaN or infinite value")
    blocks = table[:, :12].reshape(-1, 3, 4)
    relative = np.column_stack(
        [blocks[:, 0, 3], blocks[:, 1, 3], np.arctan2(blocks[:, 1, 0], blocks[:, 0, 0])]
    )
    times = np.array(stamps, dtype=np.int64).reshape(-1, 2)
    information = table[:, 12:].reshape(-1, 6, 6) if width == COLUMNS else None
    return BoreasLocalization(times[:, 0], times[:, 1], relative, information)
