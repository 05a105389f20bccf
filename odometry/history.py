"""The odometry's output for one scan (`OdometryResult`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

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
