"""What the odometry trusts after a scan it could not describe: pure helpers of `Odometry`.

A scan whose sweep holds a motion no vehicle makes (a heading snap, a registration that is wrong
but passes its checks) must not pass its error on. A registration whose images pass every check
is kept even when its motion is faster than the vehicle can move (a prior is a hint, never a
veto), but such a twist (`plausible_twist`), or the mean twist across a gap when the scan after
it lands off the constant-velocity prediction (`agrees`), never becomes the running velocity nor
re-renders the scan: the velocity from before is kept until two registered scans in a row
measure it again.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from odometry.config import OdometryConfig
from odometry.registration import kinematic_reason
from raplace.se2 import wrap_angle

FloatArray = NDArray[np.float64]

PREDICTION_TOLERANCE_M = 1.5
"""A registration further than this [m] from the constant-velocity prediction is checked against
one seeded with the prediction (the stronger correlation wins): a few m/s^2 of braking over a
4 Hz interval stays inside it."""
PREDICTION_TOLERANCE_DEG = 5.0
"""The same for the rotation [deg]: a steering change over a 4 Hz interval."""


def agrees(motion: FloatArray, expected: FloatArray, cfg: OdometryConfig) -> bool:
    """`motion` (3,) is within the prediction tolerances of `expected` (3,) (poses or motions in
    one frame)."""
    off = np.asarray(motion, dtype=np.float64) - np.asarray(expected, dtype=np.float64)
    return bool(
        np.hypot(off[0], off[1]) <= PREDICTION_TOLERANCE_M
        and abs(wrap_angle(float(off[2]))) <= np.deg2rad(PREDICTION_TOLERANCE_DEG)
    )


def plausible_twist(twist: FloatArray, cfg: OdometryConfig) -> bool:
    """`twist` (vx, vy [m/s], yaw rate [rad/s]) is within the plausible speed and yaw rate."""
    return not kinematic_reason(twist, cfg)
