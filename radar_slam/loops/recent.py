"""Which earlier scans a loop query may match: the stretch just driven is never a candidate.

A loop between scans a few metres of travel apart says nothing the odometry does not, so the
place database must not offer them. RaPlace's own exclusion counts database entries or seconds,
which at a low frame rate or a high speed hides hundreds of metres of travel, and with them the
revisit just after a U-turn or a turn round a block. With poses the loop detector measures the
exclusion in path length instead: a scan joins the database (`HeldBackDatabase`) only once the
vehicle has driven `recent_path_m` beyond it. And of the candidates the database returns, those
the odometry places clearly out of the verifier's reach are not verified (`within_reach`): over a
short stretch of path the odometry is accurate, so a candidate that the odometry says is 60 m away
after 100 m of travel is not 15 m away.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from raplace import ExclusionConfig, Recognizer, RetrievalConfig

FloatArray = NDArray[np.float64]

NO_EXCLUSION = ExclusionConfig(recent_keyframes=0, recent_seconds=0.0)


def held_back_retrieval(retrieval: RetrievalConfig, recent_path_m: float) -> RetrievalConfig:
    """The retrieval settings of the detector's own database: without an exclusion window when
    the detector holds scans back itself (`recent_path_m` > 0), else unchanged."""
    return replace(retrieval, exclusion=NO_EXCLUSION) if recent_path_m > 0 else retrieval


@dataclass(frozen=True)
class _Pending:
    descriptor: NDArray
    key: int
    time_s: float
    path_m: float | None


class HeldBackDatabase:
    """A place database that receives each scan only once the vehicle is far enough past it.

    With a path length (poses): `recent_path_m` of travel. Without one: once `exclusion`'s
    `recent_keyframes` newer scans and its `recent_seconds` have passed (what RaPlace's own
    exclusion does; the database itself then excludes nothing, see `held_back_retrieval`).

    Args:
        database: the place database (a `raplace.Recognizer`) entries are released into.
        recent_path_m: travel [m] after which a scan joins the database (> 0).
        exclusion: the count / seconds rule for scans without a path length.
    """

    def __init__(
        self, database: Recognizer, recent_path_m: float, exclusion: ExclusionConfig
    ) -> None:
        self.database = database
        self.recent_path_m = recent_path_m
        self.exclusion = exclusion
        self._pending: deque[_Pending] = deque()

    def __len__(self) -> int:
        """Scans held back, not yet in the database."""
        return len(self._pending)

    def hold(self, descriptor: NDArray, key: int, time_s: float, path_m: float | None) -> None:
        """Keep a scan's descriptor until it may be matched (time [s], path length [m] or None)."""
        self._pending.append(_Pending(descriptor, key, time_s, path_m))

    def release(self, time_s: float, path_m: float | None) -> None:
        """Move into the database every held scan a query at `time_s` / `path_m` may match."""
        while self._pending and self._due(self._pending[0], time_s, path_m):
            self._admit_oldest()

    def flush(self) -> None:
        """Move every held scan into the database (after the last query)."""
        while self._pending:
            self._admit_oldest()

    def _admit_oldest(self) -> None:
        entry = self._pending.popleft()
        self.database.add(entry.descriptor, entry.key, entry.time_s)

    def _due(self, entry: _Pending, time_s: float, path_m: float | None) -> bool:
        if entry.path_m is not None and path_m is not None:
            return path_m - entry.path_m >= self.recent_path_m
        if len(self._pending) <= self.exclusion.recent_keyframes:
            return False
        return time_s - entry.time_s >= self.exclusion.recent_seconds


def within_reach(
    query_pose: FloatArray,
    match_poses: FloatArray,
    path_gaps_m: FloatArray,
    reach_m: float,
    drift_fraction: float,
) -> NDArray[np.bool_]:
    """Which candidates the odometry does not rule out: (n,) True where the odometry distance
    between the query and the candidate is at most `reach_m` plus `drift_fraction` of the path
    travelled between them.

    Args:
        query_pose: (3,) odometry pose of the query (x, y [m], yaw [rad]).
        match_poses: (n, 3) odometry poses of the candidates.
        path_gaps_m: (n,) path length between each candidate and the query [m] (>= 0).
        reach_m: the verifier's largest translation [m].
        drift_fraction: bound on the odometry's position drift per metre travelled.
    """
    poses = np.asarray(match_poses, dtype=np.float64).reshape(-1, 3)
    if not np.isfinite(drift_fraction):
        return np.ones(len(poses), dtype=bool)
    distance = np.hypot(*(poses[:, :2] - np.asarray(query_pose, dtype=np.float64)[:2]).T)
    return np.asarray(distance <= reach_m + drift_fraction * np.asarray(path_gaps_m), dtype=bool)
