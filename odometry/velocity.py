"""The odometry's motion model: the running body velocity and what it may do.

The velocity is a search hint and a de-skew input, never a veto (see `odometry.odometry`): its
yaw-rate trend is bounded (`Velocity.at`), and every twist it hands out is limited to the
plausible speed and yaw rate (`bounded_twist`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from odometry.config import OdometryConfig
from raplace.units import NS_PER_S

FloatArray = NDArray[np.float64]
TWIST_REFRESH_MPS = 0.25
"""A scan is re-rendered when its de-skew velocity is off by more than this [m/s]."""
TWIST_REFRESH_RADPS = np.deg2rad(2.0)
"""... or its yaw rate by more than this [rad/s]."""
REDESKEW_MPS = 1.0
"""A registered scan is de-skewed and registered again when the velocity its registration
measures differs from the one it was de-skewed with by more than this [m/s] (a velocity error
smears a mid-sweep image symmetrically: below this it costs less than the second pass gains)."""
REDESKEW_RADPS = np.deg2rad(5.0)
"""... or by more than this in yaw rate [rad/s]."""


@dataclass(frozen=True)
class Velocity:
    """The running body velocity: the twist (vx, vy [m/s], yaw rate [rad/s]) measured between
    two registered image poses, at the middle of that interval (`time_ns`), and the change of
    its yaw rate since the measurement before (`yaw_rate_change` [rad/s] over `span_s` [s])."""

    twist: FloatArray
    time_ns: int
    yaw_rate_change: float = 0.0
    span_s: float = 0.0

    def at(self, time_ns: int, trend_gain: float) -> FloatArray:
        """The twist expected at `time_ns`: constant, plus `trend_gain` times the yaw-rate trend
        extrapolated linearly, bounded: the extrapolated change is at most the last measured
        change, and it never turns the yaw rate to the other side (leaving a turn, an
        unbounded trend predicts the turn to swing the other way)."""
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
        return Velocity(
            twist=twist, time_ns=time_ns, yaw_rate_change=change, span_s=max(span_s, 0.0)
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
    """Two de-skew twists render nearly the same image: they differ by at most `speed_mps` in
    velocity and `yaw_rate_radps` in yaw rate."""
    return bool(
        np.hypot(a[0] - b[0], a[1] - b[1]) <= speed_mps and abs(a[2] - b[2]) <= yaw_rate_radps
    )
