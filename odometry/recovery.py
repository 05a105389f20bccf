"""What the odometry trusts after a scan it could not describe: pure helpers of `Odometry`.

A scan whose sweep holds a motion no vehicle makes (a heading snap, a registration that is
wrong but passes its checks) must not pass its error on. Two rules keep it local:

- `plausible_twist`: a twist measured between two image poses that is faster than the vehicle
  can move (`QualityConfig.max_speed_mps`, `max_yaw_rate_dps`) is not a vehicle motion: one of
  the two poses is wrong or the motion was not smooth. Nor is the mean twist across a gap when
  the scan after it lands off the constant-velocity prediction (`Odometry` checks that with the
  prediction tolerances): the gap hid a motion the model cannot describe. Neither becomes the
  running velocity nor re-renders the scan (a de-skew at the clamped 120 deg/s bends an image by
  +-15 deg, and moving a pose from mid-sweep to the end of the sweep turns it by 15 deg); the
  velocity from before is kept until two registered scans in a row measure it again.
- a registration whose images pass every check is kept even when its motion is faster than
  the vehicle can move (a prior is a hint, never a veto: only the images fail a registration);
  its motion is then not taken as the velocity (above).
- `fallback_references`: when the keyframe cannot be registered (it may itself be such a scan),
  the earlier keyframes are tried before a gap scan, whose pose is only a prediction: a scan
  that registers against an older keyframe ends the gap with a measured pose instead of
  chaining onto the predicted one.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from odometry.config import OdometryConfig
from odometry.registration import MotionEstimate, kinematic_reason
from raplace.se2 import wrap_angle

FloatArray = NDArray[np.float64]

PREDICTION_TOLERANCE_M = 1.5
"""A registration further than this [m] from the constant-velocity prediction is checked against
one seeded with the prediction (the stronger correlation wins): a few m/s^2 of braking over a
4 Hz interval stays inside it."""
PREDICTION_TOLERANCE_DEG = 5.0
"""The same for the rotation [deg]: a steering change over a 4 Hz interval."""
Node = TypeVar("Node")


def agrees(motion: FloatArray, expected: FloatArray, cfg: OdometryConfig) -> bool:
    """`motion` (3,) is within the prediction tolerances (`PREDICTION_TOLERANCE_M`,
    `PREDICTION_TOLERANCE_DEG`) of `expected` (3,); poses or motions in one frame."""
    off = np.asarray(motion, dtype=np.float64) - np.asarray(expected, dtype=np.float64)
    return bool(
        np.hypot(off[0], off[1]) <= PREDICTION_TOLERANCE_M
        and abs(wrap_angle(float(off[2]))) <= np.deg2rad(PREDICTION_TOLERANCE_DEG)
    )


def plausible_twist(twist: FloatArray, cfg: OdometryConfig) -> bool:
    """`twist` (vx, vy [m/s], yaw rate [rad/s]) is within the plausible speed and yaw rate."""
    return not kinematic_reason(twist, cfg)


def fallback_references(
    keyframe: Node | None,
    last_registered: Node | None,
    earlier_keyframes: Sequence[Node],
    previous: Node | None,
) -> list[Node]:
    """Scans to register a new scan against, in order and without repeats: the keyframe, the
    last registered scan, the earlier keyframes (most recent first), the previous scan (a gap's
    image is real, only its pose is predicted: the last resort)."""
    nodes = [keyframe, last_registered, *earlier_keyframes, previous]
    return list({id(n): n for n in nodes if n is not None}.values())


def remembered_keyframes(
    earlier_keyframes: Sequence[Node], replaced: Node, count: int
) -> list[Node]:
    """The earlier keyframes after `replaced` stops being the keyframe (most recent first, at
    most `count`)."""
    return [replaced, *earlier_keyframes][:count]


def chosen(
    tried: Sequence[tuple[Node, MotionEstimate]],
) -> tuple[Node | None, MotionEstimate]:
    """The registration to use among those `tried` (in order; only the last may be ok): the last
    one when it passed every check, else (None, its estimate)."""
    reference, estimate = tried[-1]
    return (reference, estimate) if estimate.ok else (None, estimate)
