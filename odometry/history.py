"""The odometry's output per scan (`OdometryResult`) and its working state (`ScanNode`,
`OdometryState`, used by `odometry.Odometry` only)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from odometry.registration import PreparedScan
from odometry.velocity import Velocity

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
        covariance: (3, 3) covariance [m^2, m rad, rad^2] (x, y, yaw) of `keyframe_motion`, in
            the previous scan's axes (so that it also serves, conservatively, for `motion`).
        keyframe_index: index of the scan it was registered against (the keyframe, or the last
            registered scan when the keyframe failed; itself for the first; the keyframe for a
            gap).
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


@dataclass
class ScanNode:
    """A scan: its pose at its reference time and the pose of its image frame (`image_pose`,
    world; see `PreparedScan`), which the registrations chain; a gap's are the prediction.
    `conversion_covariance` (own axes) is what moving the image pose to the reference time adds
    to `pose`."""

    index: int
    pose: FloatArray
    image_pose: FloatArray
    scan: PreparedScan
    frames: int = 0
    gap: bool = False
    conversion_covariance: FloatArray = field(default_factory=lambda: np.zeros((3, 3)))


@dataclass
class OdometryState:
    keyframe: ScanNode | None = None
    previous: ScanNode | None = None
    last_registered: ScanNode | None = None  # the last scan that was not a gap
    velocity: Velocity | None = None
    history: list[OdometryResult] = field(default_factory=list)
    registrations: int = 0  # image registrations run for the scan being registered
