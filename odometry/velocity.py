"""The motion model: the running body velocity, the vehicle's limits on it, and the move of a
scan's pose between its image time and its reference time (see `odometry.odometry`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from odometry.config import OdometryConfig
from odometry.deskew import motion_from_twist
from odometry.registration import PreparedScan
from raplace.se2 import compose, inverse, wrap_angle
from raplace.units import NS_PER_S

FloatArray = NDArray[np.float64]
TWIST_REFRESH_MPS = 0.25
"""A scan is re-rendered when its de-skew velocity is off by more than this [m/s] ..."""
TWIST_REFRESH_RADPS = np.deg2rad(2.0)
"""... or its yaw rate by more than this [rad/s]."""
REDESKEW_MPS = 1.0
"""A scan is de-skewed and registered again when its registration measures a velocity this far
[m/s] from its de-skew's (below, the symmetric smear costs less than a second pass) ..."""
REDESKEW_RADPS = np.deg2rad(5.0)
"""... or a yaw rate this far [rad/s]."""
PREDICTION_TOLERANCE_M = 1.5
"""A registration further than this [m] from the constant-velocity prediction is checked against
one seeded with it: a few m/s^2 of braking over a 4 Hz interval stays inside."""
PREDICTION_TOLERANCE_DEG = 5.0
"""The same for the rotation [deg]: a steering change over a 4 Hz interval."""


@dataclass(frozen=True)
class Velocity:
    """The twist (vx, vy [m/s], yaw rate [rad/s]) measured between two registered image poses,
    at the middle of that interval (`time_ns`), and the change of its yaw rate since the
    measurement before (`yaw_rate_change` [rad/s] over `span_s` [s])."""

    twist: FloatArray
    time_ns: int
    yaw_rate_change: float = 0.0
    span_s: float = 0.0

    def at(self, time_ns: int, trend_gain: float) -> FloatArray:
        """The twist at `time_ns` plus `trend_gain` times the yaw-rate trend extrapolated
        linearly, by at most the last measured change and never across zero yaw rate."""
        twist = self.twist.copy()
        if trend_gain == 0.0 or self.span_s <= 0.0:
            return twist
        elapsed_s = (time_ns - self.time_ns) / NS_PER_S
        limit = abs(self.yaw_rate_change)
        delta = float(np.clip(self.yaw_rate_change / self.span_s * elapsed_s, -limit, limit))
        yaw_rate = twist[2] + trend_gain * delta
        twist[2] = yaw_rate if yaw_rate * twist[2] > 0.0 else 0.0
        return twist

    def updated(self, twist: FloatArray, time_ns: int) -> Velocity:
        """The velocity after measuring `twist` over an interval centred at `time_ns`."""
        span_s = (time_ns - self.time_ns) / NS_PER_S
        change = float(twist[2] - self.twist[2]) if span_s > 0 else 0.0
        return Velocity(twist, time_ns, change, max(span_s, 0.0))


def plausible_twist(twist: FloatArray, cfg: OdometryConfig) -> bool:
    """`twist` (vx, vy [m/s], yaw rate [rad/s]) is within the vehicle's speed and yaw rate."""
    qcfg = cfg.quality
    return not (
        np.hypot(twist[0], twist[1]) > qcfg.max_speed_mps
        or np.rad2deg(abs(twist[2])) > qcfg.max_yaw_rate_dps
    )


def bounded_twist(twist: FloatArray, cfg: OdometryConfig) -> FloatArray:
    """`twist` (vx, vy [m/s], yaw rate [rad/s]) limited to the plausible speed and yaw rate."""
    qcfg = cfg.quality
    bounded = np.asarray(twist, dtype=np.float64).copy()
    speed = float(np.hypot(bounded[0], bounded[1]))
    if speed > qcfg.max_speed_mps:
        bounded[:2] *= qcfg.max_speed_mps / speed
    limit = np.deg2rad(qcfg.max_yaw_rate_dps)
    bounded[2] = float(np.clip(bounded[2], -limit, limit))
    return bounded


def close_twists(
    a: FloatArray,
    b: FloatArray,
    speed_mps: float = TWIST_REFRESH_MPS,
    yaw_rate_radps: float = TWIST_REFRESH_RADPS,
) -> bool:
    """Two twists differ by at most `speed_mps` and `yaw_rate_radps`."""
    return bool(
        np.hypot(a[0] - b[0], a[1] - b[1]) <= speed_mps and abs(a[2] - b[2]) <= yaw_rate_radps
    )


def agrees(motion: FloatArray, expected: FloatArray) -> bool:
    """`motion` (3,) is within the prediction tolerances of `expected` (3,) (poses or motions in
    one frame)."""
    off = np.asarray(motion, dtype=np.float64) - np.asarray(expected, dtype=np.float64)
    return bool(
        np.hypot(off[0], off[1]) <= PREDICTION_TOLERANCE_M
        and abs(wrap_angle(float(off[2]))) <= np.deg2rad(PREDICTION_TOLERANCE_DEG)
    )


def pose_at_reference(image_pose: FloatArray, twist: FloatArray, image_time_s: float) -> FloatArray:
    """(3,) T_world_radar at the reference time of a scan whose image frame is at `image_pose`
    (world) `image_time_s` [s] from the reference time, moving at `twist` in between."""
    return compose(image_pose, inverse(motion_from_twist(twist, image_time_s)))


def interpolated_twist(before: Velocity, after: Velocity, time_ns: int) -> FloatArray:
    """(3,) twist at `time_ns`, linear in time between two velocities, held outside them."""
    span_ns = after.time_ns - before.time_ns
    if span_ns <= 0:
        return np.asarray(after.twist, dtype=np.float64).copy()
    fraction = float(np.clip((time_ns - before.time_ns) / span_ns, 0.0, 1.0))
    return np.asarray((1.0 - fraction) * before.twist + fraction * after.twist, dtype=np.float64)


def image_time_ns(scan: PreparedScan) -> int:
    """Absolute time of a scan's image frame [ns]."""
    return scan.timestamp_ns + int(round(scan.image_time_s * NS_PER_S))


def image_interval_s(previous: PreparedScan, scan: PreparedScan, dt_s: float) -> float:
    """Time [s] from `previous`'s image time to `scan`'s, `dt_s` apart in reference time."""
    return dt_s + scan.image_time_s - previous.image_time_s
