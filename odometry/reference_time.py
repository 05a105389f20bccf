"""A scan's pose at its reference time from the pose of its de-skewed image (mid-sweep).

Registrations chain image poses (`registration.PreparedScan`); the pose a user sees is at the
scan's reference time, the image pose moved by the body velocity over the time between them.
`interpolated_twist` gives the twist between two measured velocities (the loop verifier's sweep
velocity of a scan between two odometry steps).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from odometry.deskew import motion_from_twist
from odometry.registration import PreparedScan
from odometry.velocity import Velocity
from raplace.se2 import compose, inverse
from raplace.units import NS_PER_S

FloatArray = NDArray[np.float64]


def pose_at_reference(image_pose: FloatArray, twist: FloatArray, image_time_s: float) -> FloatArray:
    """(3,) T_world_radar at the reference time of a scan whose image frame is at `image_pose`
    (world) `image_time_s` [s] from the reference time (negative: before it), moving at `twist`
    (vx, vy [m/s], yaw rate [rad/s]) between the two."""
    return compose(image_pose, inverse(motion_from_twist(twist, image_time_s)))


def interpolated_twist(before: Velocity, after: Velocity, time_ns: int) -> FloatArray:
    """(3,) twist at `time_ns`, linear in time between two measured velocities (each at the
    middle of its interval, `time_ns` of each), held constant outside them."""
    span_ns = after.time_ns - before.time_ns
    if span_ns <= 0:
        return np.asarray(after.twist, dtype=np.float64).copy()
    fraction = float(np.clip((time_ns - before.time_ns) / span_ns, 0.0, 1.0))
    return np.asarray((1.0 - fraction) * before.twist + fraction * after.twist, dtype=np.float64)


def seconds_to_ns(seconds: float) -> int:
    """A duration [s] in integer nanoseconds (rounded)."""
    return int(round(seconds * NS_PER_S))


def image_time_ns(scan: PreparedScan) -> int:
    """Absolute time of a scan's image frame [ns]."""
    return scan.timestamp_ns + seconds_to_ns(scan.image_time_s)


def move_centre_ns(scan: PreparedScan) -> int:
    """The middle of the move from a scan's image time to its reference time [ns]."""
    return (image_time_ns(scan) + scan.timestamp_ns) // 2


def image_interval_s(previous: PreparedScan, scan: PreparedScan, dt_s: float) -> float:
    """Time [s] from `previous`'s image time to `scan`'s, `dt_s` apart in reference time."""
    return dt_s + scan.image_time_s - previous.image_time_s
