"""The odometry's per-scan results and their history, final one scan late.

`Odometry.register` returns a scan's result at once (its *prompt* result). Its pose at the
reference time is its image pose moved by a velocity that, at that moment, is only known up to
the scan: at a yaw-rate reversal late in the sweep that move is off by degrees. When the next
scan registers, the velocity on both sides of the scan's reference time is known and the pose is
revised (`ResultHistory.revise`). The history holds the revised results, chained in its own
poses (`motion` and `keyframe_motion` are relative to the history's poses); the prompt results
chain in the prompt poses, so that a consumer adding one factor per scan as it comes (a pose
graph) stays consistent.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from raplace.se2 import between

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class OdometryResult:
    """The odometry's output for one scan.

    Attributes:
        index: position of the scan in the sequence registered so far (0-based).
        timestamp_ns: the scan's reference time [ns] (the time `pose` refers to).
        pose: (3,) T_world_radar (x, y [m], yaw [rad]) at `timestamp_ns`; the world frame is the
            first scan's radar frame moved to `start_pose`.
        motion: (3,) this scan's pose in the previous scan's frame (zeros for the first scan).
        covariance: (3, 3) covariance [m^2, m rad, rad^2], order (x, y, yaw), of this scan's
            pose relative to the scan it was registered against (`keyframe_motion`): the
            registration's plus both moves from mid-sweep to the reference times; expressed in
            the previous scan's axes, so that it also serves (conservatively) for `motion`.
        keyframe_index: index of the scan it was registered against (the keyframe, or the
            previous scan after a failure; itself for the first scan; the keyframe for a gap).
        keyframe_motion: (3,) this scan's pose in that scan's frame.
        is_keyframe: the scan is the keyframe for the scans that follow.
        ok: the registration succeeded.
        gap: the pose is a constant-velocity prediction covering a failed registration.
        quality: peak-to-noise ratio of the translation peak (0 for the first scan or a gap).
        reason: why the registration failed ("" when ok).
        registrations: image registrations (`registration.register_images`, coarse and fine
            levels counting as one) run for this scan.
    """

    index: int
    timestamp_ns: int
    pose: FloatArray
    motion: FloatArray
    covariance: FloatArray
    keyframe_index: int
    keyframe_motion: FloatArray
    is_keyframe: bool
    ok: bool
    gap: bool
    quality: float
    reason: str = ""
    registrations: int = 0


class ResultHistory:
    """Every scan's result, the last one prompt and the others revised (see the module)."""

    def __init__(self) -> None:
        self._results: list[OdometryResult] = []

    def __len__(self) -> int:
        return len(self._results)

    @property
    def results(self) -> list[OdometryResult]:
        """One result per scan, in order."""
        return list(self._results)

    def __getitem__(self, index: int) -> OdometryResult:
        """Scan `index`'s result (revised unless it is the last)."""
        return self._results[index]

    def append(self, result: OdometryResult) -> None:
        """Add the next scan's prompt result, its motions re-chained to the history's poses."""
        if self._results:
            result = self._chained(result, result.pose)
        self._results.append(result)

    def revise(self, index: int, pose: FloatArray, covariance: FloatArray | None = None) -> None:
        """Move the last scan (`index`) to `pose`, its revised T_world_radar at its reference
        time, with `covariance` (as `OdometryResult.covariance`; None: unchanged)."""
        if index != len(self._results) - 1 or index == 0:
            raise ValueError(f"only the last scan after the first can be revised, not {index}")
        result = self._chained(self._results[index], pose)
        if covariance is not None:
            result = dataclasses.replace(result, covariance=np.asarray(covariance, np.float64))
        self._results[index] = result

    def _chained(self, result: OdometryResult, pose: FloatArray) -> OdometryResult:
        """`result` at `pose`, its motions relative to the history's earlier poses."""
        pose = np.asarray(pose, dtype=np.float64)
        return dataclasses.replace(
            result,
            pose=pose,
            motion=between(self._results[result.index - 1].pose, pose),
            keyframe_motion=between(self._results[result.keyframe_index].pose, pose),
        )
