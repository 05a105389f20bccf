"""What a simulated drive asks of the car: speed, yaw rate and lateral acceleration over time,
and the envelope a car stays in.

The envelope is a car's, not a driving style's: the drives themselves are gentler (the plans of
manoeuvres.py keep 3 m/s^2 and about 35 deg/s; the smooth drive of route.py keeps 2.5 m/s^2
except in its tightest corners, which it takes at its minimum speed, slower where that speed
would leave the envelope). A route that folds onto itself (a quarter turn within one radar
sweep, 360 deg/s) is far outside it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from radar_slam.sim.route import MAX_LATERAL_ACCEL_MPS2, Trajectory

FloatArray = NDArray[np.float64]

MAX_YAW_RATE_DPS = 90.0
"""Above what a car reaches at full lock (a base radius of about 3.5 m, a 10.5 m turning
circle) at the speed where the lateral acceleration reaches MAX_LATERAL_ACCEL_MPS2: about
sqrt(7 / 3.5) rad/s = 81 deg/s."""
KINEMATICS_WINDOW_S = 0.05
"""Time over which the motion is differenced [s] (25 trajectory samples)."""


@dataclass(frozen=True)
class Kinematics:
    """The motion of a drive, one value per window of KINEMATICS_WINDOW_S.

    Attributes:
        t_s: (N,) window centre times [s].
        speed_mps: (N,) forward speed (negative in reverse gear) [m/s].
        yaw_rate_radps: (N,) yaw rate, counter-clockwise positive [rad/s].
        lateral_accel_mps2: (N,) centripetal acceleration, speed times yaw rate [m/s^2].
    """

    t_s: FloatArray
    speed_mps: FloatArray
    yaw_rate_radps: FloatArray
    lateral_accel_mps2: FloatArray

    def within_limits(self) -> bool:
        """Yaw rate and lateral acceleration stay within a car's envelope everywhere."""
        return bool(
            np.abs(self.yaw_rate_radps).max() <= np.deg2rad(MAX_YAW_RATE_DPS)
            and np.abs(self.lateral_accel_mps2).max() <= MAX_LATERAL_ACCEL_MPS2
        )


def kinematics(trajectory: Trajectory, window_s: float = KINEMATICS_WINDOW_S) -> Kinematics:
    """The speed, yaw rate and lateral acceleration of `trajectory` (base poses, unwrapped yaw),
    differenced over windows of `window_s` [s] sliding by one trajectory sample."""
    t, poses = trajectory.t_s, trajectory.poses
    step = max(1, round(window_s / float(t[1] - t[0])))
    dt = t[step:] - t[:-step]
    move = poses[step:] - poses[:-step]
    mid = 0.5 * (poses[step:, 2] + poses[:-step, 2])
    speed = (move[:, 0] * np.cos(mid) + move[:, 1] * np.sin(mid)) / dt
    yaw_rate = move[:, 2] / dt
    return Kinematics(0.5 * (t[step:] + t[:-step]), speed, yaw_rate, speed * yaw_rate)
