"""Fewer verifications along a stretch that is already closed.

In a revisit every database scan proposes a candidate, and each verification costs about as much
as an odometry step; after a few consecutive accepted loops along one stretch of road, more loops
on it add little to the graph. `StretchThrottle` tracks the latest run of accepted loops whose
matches advance with their queries (same or opposite direction of travel). Once it holds
`CLOSED_AFTER` loops the stretch is closed: a candidate lying where the stretch predicts the
match (on the stretch) is verified at most once per `closed_spacing_m` of travel, and a query
whose candidate on the stretch is not due is skipped whole (its place is known). Anything else
returns to full rate: a candidate off the stretch is verified as usual, and a failed
verification on the stretch, a rejected loop, or `MAX_GAP_M` of travel without an accepted loop
on it ends the stretch.

`anchor` names the latest loop of the closed stretch a candidate lies on, from which the loop
detector predicts the candidate's loop (`radar_slam.loops.tracking`).

Skipping only ever removes verifications, so it cannot add a false loop; the consistency gate
(`radar_slam.loops.consistency`) still sees a loop every `closed_spacing_m`, well inside its
support window.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from radar_slam.loops.config import ThrottleConfig
from radar_slam.loops.records import LoopStatus

CLOSED_AFTER = 3
"""Consecutive accepted loops along one stretch (matches advancing with the queries, the same or
the opposite way) that mark it closed."""
STRETCH_TOLERANCE_M = 12.0
"""A match is on a stretch when it lies within this path distance [m] of where the stretch
predicts it ..."""
STRETCH_DRIFT_FRACTION = 0.05
"""... plus this fraction of the travel since the stretch's latest loop (the two drives' odometry
path lengths differ by the drift)."""
MAX_GAP_M = 100.0
"""A stretch without an accepted loop over this much travel [m] is forgotten."""
MAX_STRETCHES = 8
"""Stretches tracked at once (a place driven several times aligns with each earlier drive); the
oldest is dropped beyond."""


@dataclass(frozen=True)
class _Loop:
    """Where a loop that passed verification joins the two drives (path lengths [m])."""

    query_path_m: float
    match_path_m: float
    direction: int  # +1: driven the same way as the match, -1: the opposite way
    decision: int = -1


@dataclass(frozen=True)
class Stretch:
    """A run of consecutive accepted loops that agree on the alignment of the two drives.

    Attributes:
        query_path_m: query path length of its latest loop [m].
        match_path_m: match path length of its latest loop [m].
        direction: +1 when the query drives the way the match did, -1 the opposite way.
        loops: accepted loops along it.
        decision: the loop detector's decision index of its latest loop (-1: unknown).
    """

    query_path_m: float
    match_path_m: float
    direction: int
    loops: int
    decision: int = -1

    def offset_m(self, query_path_m: float, match_path_m: float) -> float:
        """How far [m] a match at `match_path_m` lies from where the stretch predicts the match
        of a query at `query_path_m`, beyond the tolerance (<= 0: on the stretch)."""
        travelled = abs(query_path_m - self.query_path_m)
        predicted = self.match_path_m + self.direction * (query_path_m - self.query_path_m)
        tolerance = STRETCH_TOLERANCE_M + STRETCH_DRIFT_FRACTION * travelled
        return abs(match_path_m - predicted) - tolerance


def direction_of(yaw_rad: float) -> int:
    """+1 when a loop's relative yaw T_query_match says both scans face the same way, else -1."""
    return 1 if np.cos(yaw_rad) >= 0.0 else -1


class StretchThrottle:
    """Decides which queries the loop detector verifies (see the module docstring).

    The detector calls, per query: `due(query_path_m, match_paths_m)` before verifying; then
    `verified(...)` after each verification it ran and `resolved(changes)` with the statuses the
    consistency gate set. Several stretches are tracked at once (a place driven three times
    aligns the third drive with both earlier ones), at most `MAX_STRETCHES`.
    """

    def __init__(self, cfg: ThrottleConfig) -> None:
        self.cfg = cfg
        self.stretches: list[Stretch] = []
        self.skipped = 0
        """Queries skipped because their place was on a closed stretch."""
        self._passed: dict[int, _Loop] = {}  # decision -> loop, while its status is unresolved
        self._last_verified_m = -np.inf  # query path of the latest verification on a stretch

    def closed(self, stretch: Stretch) -> bool:
        """True when `stretch` has enough loops for throttling."""
        return self.cfg.closed_spacing_m > 0 and stretch.loops >= CLOSED_AFTER

    def on_closed_stretch(self, query_path_m: float, match_path_m: float) -> bool:
        """True when a match at `match_path_m` lies where a closed stretch predicts it."""
        return any(
            self.closed(s) and s.offset_m(query_path_m, match_path_m) <= 0.0 for s in self.stretches
        )

    def anchor(self, query_path_m: float, match_path_m: float) -> int | None:
        """The decision index of the latest loop of the closed stretch a match at
        `match_path_m` lies on (the nearest to its prediction), or None when it is on none."""
        on = [
            (s.offset_m(query_path_m, match_path_m), s.decision)
            for s in self.stretches
            if self.closed(s) and s.decision >= 0
        ]
        on = [item for item in on if item[0] <= 0.0]
        return min(on)[1] if on else None

    def due(self, query_path_m: float, match_paths_m: list[float]) -> bool:
        """Whether a query at `query_path_m` with candidates matching at `match_paths_m` is
        verified (False: skipped, counted in `skipped`)."""
        self.stretches = [s for s in self.stretches if query_path_m - s.query_path_m <= MAX_GAP_M]
        if not any(self.on_closed_stretch(query_path_m, m) for m in match_paths_m):
            return True
        if query_path_m - self._last_verified_m >= self.cfg.closed_spacing_m:
            return True
        self.skipped += 1
        return False

    def verified(
        self, decision: int, query_path_m: float, match_path_m: float, yaw_rad: float, ok: bool
    ) -> None:
        """Record a verification: `decision` its index, `yaw_rad` the measured relative yaw."""
        if self.on_closed_stretch(query_path_m, match_path_m):
            self._last_verified_m = query_path_m
        if ok:
            self._passed[decision] = _Loop(
                query_path_m, match_path_m, direction_of(yaw_rad), decision
            )
        else:  # the stretch may have ended there: back to full rate on it
            self._end(query_path_m, match_path_m)

    def resolved(self, changes: dict[int, LoopStatus]) -> None:
        """Take the statuses the consistency gate set (decision -> status)."""
        for decision, status in sorted(changes.items()):
            if status == "pending":
                continue
            loop = self._passed.pop(decision, None)
            if loop is None:
                continue
            if status == "rejected":
                self._end(loop.query_path_m, loop.match_path_m)
            else:
                self._extend(loop)

    def _extend(self, loop: _Loop) -> None:
        """An accepted loop extends the stretch it follows or starts a new one."""
        for n, s in enumerate(self.stretches):
            if loop.direction != s.direction:
                continue
            if s.offset_m(loop.query_path_m, loop.match_path_m) > 0.0:
                continue
            if loop.query_path_m > s.query_path_m:  # not an older loop accepted late
                self.stretches[n] = Stretch(
                    loop.query_path_m, loop.match_path_m, s.direction, s.loops + 1, loop.decision
                )
            return
        new = Stretch(loop.query_path_m, loop.match_path_m, loop.direction, 1, loop.decision)
        self.stretches = [*self.stretches, new][-MAX_STRETCHES:]

    def _end(self, query_path_m: float, match_path_m: float) -> None:
        """Drop the stretches a match at `match_path_m` lies on."""
        self.stretches = [s for s in self.stretches if s.offset_m(query_path_m, match_path_m) > 0.0]
