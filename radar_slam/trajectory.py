"""SE(2) trajectories with integer-nanosecond timestamps, and their TUM and KITTI files.

A `Trajectory` holds `timestamps_ns` (N,) int64 and `poses` (N, 3) float64 `(x [m], y [m],
yaw [rad])`, the pose of the body (radar) in the trajectory's world frame, T_world_radar.

File formats (as evo reads and writes them):
- TUM: one pose per line, `t x y z qx qy qz qw`, `t` in seconds. We write `t` with nine decimals
  from the integer nanoseconds ("1564718976.161407002") and parse it back exactly, so timestamps
  round-trip bit for bit. Yaw is a rotation about z: q = (0, 0, sin(yaw/2), cos(yaw/2)).
- KITTI: one pose per line, the 3x4 matrix [R | t] row-major (12 numbers), no timestamps.
Reading a 3-D file projects it onto SE(2): (x, y) and the yaw of the rotation (ZYX convention).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radar_slam.errors import TrajectoryError
from raplace import NS_PER_S, accumulate, relative_motions, wrap_angle

logger = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

TUM_COLUMNS = 8
KITTI_COLUMNS = 12
COMMENT_PREFIX = "#"
PLANAR_TOLERANCE = 1e-6  # |z| [m] or off-plane rotation entries above this are "3-D" (logged)


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Timestamped SE(2) poses T_world_radar.

    Attributes:
        timestamps_ns: (N,) int64, strictly increasing [ns].
        poses: (N, 3) float64 `(x [m], y [m], yaw [rad])`, yaw wrapped into [-pi, pi).

    Both arrays are copied and made read-only. Invalid input (length mismatch, non-finite
    pose, timestamps not strictly increasing) raises `TrajectoryError`.
    """

    timestamps_ns: IntArray
    poses: FloatArray

    def __post_init__(self) -> None:
        timestamps = _as_int_ns(self.timestamps_ns)
        poses = np.array(self.poses, dtype=np.float64, copy=True)
        if poses.size == 0:
            poses = poses.reshape(0, 3)
        if poses.ndim != 2 or poses.shape[1] != 3:
            raise TrajectoryError(f"poses must have shape (N, 3), got {poses.shape}")
        if timestamps.shape != (len(poses),):
            raise TrajectoryError(
                f"{len(timestamps)} timestamps for {len(poses)} poses; the counts must match"
            )
        bad = ~np.isfinite(poses).all(axis=1)
        if bad.any():
            raise TrajectoryError(
                f"pose {int(np.argmax(bad))} is not finite ({int(bad.sum())} non-finite poses); "
                "use Trajectory.from_arrays(..., drop_nonfinite=True) to drop them"
            )
        steps = np.diff(timestamps)
        if (steps <= 0).any():
            k = int(np.argmax(steps <= 0))
            raise TrajectoryError(
                f"timestamps must be strictly increasing: index {k + 1} "
                f"({timestamps[k + 1]} ns) follows {timestamps[k]} ns"
            )
        poses[:, 2] = wrap_angle(poses[:, 2])
        timestamps.setflags(write=False)
        poses.setflags(write=False)
        object.__setattr__(self, "timestamps_ns", timestamps)
        object.__setattr__(self, "poses", poses)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_arrays(
        cls, timestamps_ns: ArrayLike, poses: ArrayLike, drop_nonfinite: bool = False
    ) -> Trajectory:
        """Build a trajectory, optionally dropping rows whose pose has NaN/inf.

        Loaders mark scans outside the ground-truth span with NaN poses; pass
        `drop_nonfinite=True` to evaluate against such a ground truth.
        """
        poses_arr = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        timestamps = np.asarray(timestamps_ns)
        if drop_nonfinite and len(timestamps) == len(poses_arr):
            keep = np.isfinite(poses_arr).all(axis=1)
            if not keep.all():
                logger.info("dropping %d of %d non-finite poses", (~keep).sum(), len(poses_arr))
            timestamps, poses_arr = timestamps[keep], poses_arr[keep]
        return cls(timestamps, poses_arr)

    @classmethod
    def from_relative_motions(
        cls,
        timestamps_ns: ArrayLike,
        motions: ArrayLike,
        start: ArrayLike = (0.0, 0.0, 0.0),
    ) -> Trajectory:
        """Chain (N - 1, 3) motions T_k_k+1 from `start` into N poses at `timestamps_ns`."""
        return cls(np.asarray(timestamps_ns), accumulate(motions, start))

    # ------------------------------------------------------------------ queries
    def __len__(self) -> int:
        return len(self.timestamps_ns)

    def __getitem__(self, key: slice | ArrayLike) -> Trajectory:
        """Select poses by slice, integer indices or boolean mask; always returns a Trajectory."""
        index = key if isinstance(key, slice) else np.atleast_1d(np.asarray(key))
        return Trajectory(self.timestamps_ns[index], self.poses[index])

    @property
    def positions(self) -> FloatArray:
        """(N, 2) positions (x, y) [m]."""
        return self.poses[:, :2]

    @property
    def timestamps_s(self) -> FloatArray:
        """(N,) timestamps as float seconds (for display and evo; loses sub-us precision)."""
        return self.timestamps_ns.astype(np.float64) / NS_PER_S

    def path_distances_m(self) -> FloatArray:
        """(N,) cumulative path length [m] from the first pose (0 at index 0)."""
        steps = np.linalg.norm(np.diff(self.positions, axis=0), axis=1)
        return np.concatenate([[0.0], np.cumsum(steps)])

    def length_m(self) -> float:
        """Total path length [m]: the sum of distances between consecutive positions."""
        return float(self.path_distances_m()[-1]) if len(self) else 0.0

    def relative_motions(self) -> FloatArray:
        """(N - 1, 3) motions T_k_k+1 between consecutive poses."""
        return relative_motions(self.poses)

    def between_times(self, start_ns: int, end_ns: int) -> Trajectory:
        """Poses with start_ns <= t <= end_ns."""
        mask = (self.timestamps_ns >= start_ns) & (self.timestamps_ns <= end_ns)
        return self[mask]


def _as_int_ns(timestamps: ArrayLike) -> IntArray:
    """Return (N,) int64 nanoseconds; float input must hold integral values."""
    arr = np.array(timestamps, copy=True)
    if arr.ndim == 0 or arr.ndim > 1:
        raise TrajectoryError(f"timestamps must be a 1-D array, got shape {arr.shape}")
    if arr.size == 0:
        return np.zeros(0, dtype=np.int64)
    if np.issubdtype(arr.dtype, np.integer):
        return arr.astype(np.int64)
    if np.issubdtype(arr.dtype, np.floating):
        if not np.isfinite(arr).all() or (arr != np.round(arr)).any():
            raise TrajectoryError("timestamps must be integer nanoseconds")
        return arr.astype(np.int64)
    raise TrajectoryError(f"timestamps must be integer nanoseconds, got dtype {arr.dtype}")


# ---------------------------------------------------------------------- number formatting
def format_ns_as_seconds(timestamp_ns: int) -> str:
    """Integer nanoseconds -> exact decimal seconds with nine decimals ("12.000000001")."""
    sign = "-" if timestamp_ns < 0 else ""
    seconds, nanos = divmod(abs(int(timestamp_ns)), NS_PER_S)
    return f"{sign}{seconds}.{nanos:09d}"


def parse_seconds_as_ns(text: str) -> int:
    """Decimal seconds -> integer nanoseconds, exact for up to nine decimals (rounded beyond).

    Raises ValueError for text that is not a finite number.
    """
    try:
        value = Decimal(text)
    except InvalidOperation as exc:
        raise ValueError(f"not a number: {text!r}") from exc
    if not value.is_finite():
        raise ValueError(f"not a finite number: {text!r}")
    return int((value * NS_PER_S).to_integral_value())


def _format_row(values: Sequence[float]) -> str:
    """Shortest text that round-trips each float exactly."""
    return " ".join(repr(float(v)) for v in values)


# ---------------------------------------------------------------------- parsing helpers
def _data_lines(path: Path) -> list[tuple[int, list[str]]]:
    """(1-based line number, tokens) of each non-blank, non-comment line of `path`."""
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise TrajectoryError(f"{path}: cannot read trajectory file: {exc}") from exc
    rows = []
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if stripped and not stripped.startswith(COMMENT_PREFIX):
            rows.append((number, stripped.replace(",", " ").split()))
    if not rows:
        raise TrajectoryError(f"{path}: trajectory file is empty (no pose lines)")
    return rows


def _numeric_table(
    path: Path, rows: list[tuple[int, list[str]]], n_columns: int, layout: str
) -> FloatArray:
    """Check the column count and parse every token as a finite float: (N, n_columns)."""
    for number, tokens in rows:
        if len(tokens) != n_columns:
            raise TrajectoryError(
                f"{path}:{number}: expected {n_columns} columns ({layout}), found {len(tokens)}"
            )
    try:
        table = np.array([tokens for _, tokens in rows], dtype=np.float64)
    except ValueError:
        table = None
    if table is None or not np.isfinite(table).all():
        for number, tokens in rows:  # slow path, only to name the offending line
            try:
                values = np.array(tokens, dtype=np.float64)
            except ValueError:
                raise TrajectoryError(
                    f"{path}:{number}: non-numeric value in {' '.join(tokens)!r}"
                ) from None
            if not np.isfinite(values).all():
                raise TrajectoryError(f"{path}:{number}: NaN or infinite value")
    assert table is not None
    return table


def yaw_from_quaternion(quat_xyzw: ArrayLike) -> FloatArray:
    """Yaw [rad] (rotation about z, ZYX convention) of quaternions (..., 4) ordered x, y, z, w.

    Scale-invariant, so unnormalised quaternions give the same yaw.
    """
    q = np.asarray(quat_xyzw, dtype=np.float64)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.arctan2(2.0 * (w * z + x * y), w * w + x * x - y * y - z * z)


def quaternion_from_yaw(yaw: ArrayLike) -> FloatArray:
    """Quaternions (..., 4) ordered x, y, z, w of rotations by `yaw` [rad] about z."""
    half = 0.5 * np.asarray(yaw, dtype=np.float64)
    zeros = np.zeros_like(half)
    return np.stack([zeros, zeros, np.sin(half), np.cos(half)], axis=-1)


def _log_projection(path: Path, off_plane: FloatArray) -> None:
    if off_plane.size and float(np.max(np.abs(off_plane))) > PLANAR_TOLERANCE:
        logger.info("%s: 3-D poses projected onto SE(2) (z, roll and pitch dropped)", path)


# ---------------------------------------------------------------------- TUM
INTEGER_NS_MIN = 10**17
"""Integer TUM timestamps at least this large are nanoseconds (epoch ns are about 1.6e18)."""
INTEGER_US_MIN = 10**14
"""... and at least this large (below INTEGER_NS_MIN) microseconds (epoch us about 1.6e15)."""


def tum_times_ns(path: Path, tokens: list[str]) -> NDArray[np.int64]:
    """TUM timestamps -> integer ns: decimal seconds, or integer micro/nanoseconds (as MulRan
    users have), detected by magnitude when every stamp is an integer; the unit detected is
    stated in a logged warning, since TUM defines seconds."""
    if all(token.lstrip("-").isdigit() for token in tokens):
        largest = max(abs(int(token)) for token in tokens)
        for minimum, unit, scale in (
            (INTEGER_NS_MIN, "nanoseconds", 1),
            (INTEGER_US_MIN, "microseconds", 1000),
        ):
            if largest >= minimum:
                logger.warning("%s: integer timestamps read as %s (TUM uses seconds)", path, unit)
                return _int64_times(path, [int(token) * scale for token in tokens])
    return _int64_times(path, [parse_seconds_as_ns(token) for token in tokens])


def _int64_times(path: Path, times_ns: list[int]) -> NDArray[np.int64]:
    try:
        return np.array(times_ns, dtype=np.int64)
    except OverflowError:
        raise TrajectoryError(
            f"{path}: a timestamp is beyond the year 2262 in nanoseconds; TUM uses seconds"
        ) from None


def read_tum(path: Path | str) -> Trajectory:
    """Read a TUM file `t x y z qx qy qz qw` as an SE(2) trajectory: t in seconds, or integer
    micro- or nanoseconds (see `tum_times_ns`).

    Raises TrajectoryError naming the file and line for an empty file, a wrong column count,
    a non-numeric or non-finite value, a zero quaternion, or timestamps not strictly increasing.
    """
    path = Path(path)
    rows = _data_lines(path)
    table = _numeric_table(path, rows, TUM_COLUMNS, "t x y z qx qy qz qw")
    timestamps = tum_times_ns(path, [tokens[0] for _, tokens in rows])
    steps = np.diff(timestamps)
    if (steps <= 0).any():
        k = int(np.argmax(steps <= 0)) + 1
        raise TrajectoryError(
            f"{path}:{rows[k][0]}: timestamp {rows[k][1][0]} s does not increase "
            f"(previous line has {rows[k - 1][1][0]} s); TUM timestamps must be strictly increasing"
        )
    quats = table[:, 4:8]
    zero = np.linalg.norm(quats, axis=1) == 0.0
    if zero.any():
        raise TrajectoryError(f"{path}:{rows[int(np.argmax(zero))][0]}: zero quaternion")
    unit = quats / np.linalg.norm(quats, axis=1, keepdims=True)
    _log_projection(path, np.concatenate([table[:, 3], unit[:, 0], unit[:, 1]]))
    poses = np.column_stack([table[:, 1], table[:, 2], yaw_from_quaternion(quats)])
    return Trajectory(timestamps, poses)


def write_tum(path: Path | str, trajectory: Trajectory) -> None:
    """Write `trajectory` as TUM (`t x y z qx qy qz qw`, z = 0), t with nanosecond precision."""
    quats = quaternion_from_yaw(trajectory.poses[:, 2])
    lines = [
        f"{format_ns_as_seconds(t)} {_format_row([x, y, 0.0, *q])}\n"
        for t, (x, y, _), q in zip(
            trajectory.timestamps_ns.tolist(),
            trajectory.poses.tolist(),
            quats.tolist(),
            strict=True,
        )
    ]
    Path(path).write_text("".join(lines))


# ---------------------------------------------------------------------- KITTI
def read_kitti(path: Path | str, timestamps_ns: ArrayLike | None = None) -> Trajectory:
    """Read a KITTI file (3x4 [R|t] row-major per line) as an SE(2) trajectory.

    KITTI files carry no time: pass `timestamps_ns` (N,), else the frame indices 0..N-1 are used
    as timestamps (so KITTI trajectories associate by index).
    """
    path = Path(path)
    rows = _data_lines(path)
    table = _numeric_table(path, rows, KITTI_COLUMNS, "3x4 row-major [R|t]")
    mats = table.reshape(-1, 3, 4)
    _log_projection(path, np.concatenate([mats[:, 2, 3], mats[:, 2, 0], mats[:, 2, 1]]))
    yaw = np.arctan2(mats[:, 1, 0], mats[:, 0, 0])
    poses = np.column_stack([mats[:, 0, 3], mats[:, 1, 3], yaw])
    if timestamps_ns is None:
        stamps = np.arange(len(poses), dtype=np.int64)
    else:
        stamps = np.asarray(timestamps_ns)
        if stamps.shape != (len(poses),):
            raise TrajectoryError(
                f"{path}: {len(poses)} poses but {stamps.size} timestamps were given"
            )
    return Trajectory(stamps, poses)


def write_kitti(path: Path | str, trajectory: Trajectory) -> None:
    """Write `trajectory` as KITTI: [[c, -s, 0, x], [s, c, 0, y], [0, 0, 1, 0]] row-major."""
    x, y, yaw = trajectory.poses.T
    c, s = np.cos(yaw), np.sin(yaw)
    zeros, ones = np.zeros_like(x), np.ones_like(x)
    table = np.column_stack([c, -s, zeros, x, s, c, zeros, y, zeros, zeros, ones, zeros])
    Path(path).write_text("".join(f"{_format_row(row)}\n" for row in table.tolist()))


TRAJECTORY_FORMATS = ("tum", "kitti")


def detect_format(path: Path | str) -> str:
    """Guess "tum" or "kitti" from the column count of the first pose line."""
    path = Path(path)
    _refuse_pose_graph(path)
    number, tokens = _data_lines(path)[0]
    if len(tokens) == TUM_COLUMNS:
        return "tum"
    if len(tokens) == KITTI_COLUMNS:
        return "kitti"
    raise TrajectoryError(
        f"{path}:{number}: {len(tokens)} columns is neither TUM ({TUM_COLUMNS}) "
        f"nor KITTI ({KITTI_COLUMNS})"
    )


POSE_GRAPH_TAGS = ("VERTEX_SE2", "EDGE_SE2", "FIX")
"""First words of a g2o pose-graph line (`radar-slam loops` writes such files)."""


def _refuse_pose_graph(path: Path | str) -> None:
    """A g2o pose graph is no trajectory: its vertices carry no timestamps to match."""
    lines = _data_lines(Path(path))
    if lines and lines[0][1] and lines[0][1][0] in POSE_GRAPH_TAGS:
        raise TrajectoryError(
            f"{path}: a g2o pose graph, not a trajectory: its vertices carry no timestamps to "
            "match with the ground truth (evaluate a TUM or KITTI file, e.g. the slam.tum of a "
            "`radar-slam run`)"
        )


def read_trajectory(path: Path | str, fmt: str = "auto") -> Trajectory:
    """Read a trajectory file in format `fmt` ("tum", "kitti" or "auto" by column count)."""
    _refuse_pose_graph(path)
    fmt = detect_format(path) if fmt == "auto" else fmt
    if fmt == "tum":
        return read_tum(path)
    if fmt == "kitti":
        return read_kitti(path)
    raise TrajectoryError(
        f"unknown trajectory format {fmt!r}; expected one of {TRAJECTORY_FORMATS}"
    )
