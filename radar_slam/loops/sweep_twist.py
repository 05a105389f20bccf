"""The body twist a loop candidate's scan is de-skewed with: the velocity during its sweep.

The loop detector knows each scan's odometry pose at its reference time (`Scan.timestamp_ns`).
The twist of one step between two consecutive scans (`twist_from_motion`) is the mean velocity
over that step, i.e. the velocity at the step's middle when it changes linearly. A scan's sweep
is best described by its velocity at the scan's mean acquisition time (the mean of its azimuth
times), so the twist is interpolated linearly in time between the step before the scan and the
step after it (`odometry.interpolated_twist`, held constant outside them):

- scans stamped at the end of the sweep (MulRan, synthetic) at their full rate: the step before
  the scan spans exactly its sweep, its middle is the mean acquisition time, and the result is
  that step's twist;
- the same scans at a quarter of the rate (1 Hz): the step before is centred half a second
  before the scan, the sweep an eighth of a second; the twist lies 3/8 of the way to the step
  after (the backward step alone lags the sweep by 3/8 s);
- scans stamped mid-sweep (Oxford): half-way, the central difference.

A step whose twist is beyond the vehicle's limits (`odometry.plausible_twist`) is an
odometry step not to be trusted; its twist is not used (the other side's is, alone).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from odometry import (
    OdometryConfig,
    OdometryResult,
    Scan,
    Velocity,
    interpolated_twist,
    plausible_twist,
    twist_from_motion,
)
from radar_slam.loops.verification import mean_acquisition_offset_s
from raplace import NS_PER_S

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class StepTwist:
    """The mean body twist of one odometry step between two consecutive scans.

    Attributes:
        velocity: the twist (vx, vy [m/s], yaw rate [rad/s]) at the step's middle
            (`Velocity.time_ns`), None when it is beyond the vehicle's limits.
        plausible: False when the step is faster than a vehicle moves or turns.
    """

    velocity: Velocity | None
    plausible: bool


def step_twist(motion: ArrayLike, start_ns: int, end_ns: int, limits: OdometryConfig) -> StepTwist:
    """The twist of the step `motion` (3,) (end pose in the start pose's frame: dx, dy [m],
    dyaw [rad]) from `start_ns` to `end_ns` [ns] (end later than start), placed at its middle.

    Raises:
        ValueError: `end_ns` not after `start_ns`.
    """
    twist = twist_from_motion(motion, (end_ns - start_ns) / NS_PER_S)
    if not plausible_twist(twist, limits):
        return StepTwist(None, False)
    return StepTwist(Velocity(twist=twist, time_ns=(start_ns + end_ns) // 2), True)


def mean_acquisition_time_ns(scan: Scan) -> int:
    """The scan's mean acquisition time [ns] (its reference time without azimuth times)."""
    offset_s = mean_acquisition_offset_s(scan)
    offset_ns = 0 if offset_s is None else round(offset_s * NS_PER_S)
    return int(scan.timestamp_ns) + offset_ns


def sweep_twist(
    before: Velocity | None, after: Velocity | None, mean_time_ns: int
) -> FloatArray | None:
    """(3,) body twist at a scan's mean acquisition time `mean_time_ns` [ns], linear in time
    between the twists of the steps before and after the scan (either may be None: the other
    is used alone; both None: None)."""
    if before is None and after is None:
        return None
    if before is None or after is None:
        known = before if before is not None else after
        assert known is not None
        return np.asarray(known.twist, dtype=np.float64).copy()
    return interpolated_twist(before, after, mean_time_ns)


def step_velocity(
    previous: OdometryResult, current: OdometryResult, limits: OdometryConfig
) -> Velocity | None:
    """The velocity of the odometry step from `previous` into `current` (`step_twist`; None for
    a step of no duration or one beyond the vehicle's limits)."""
    start_ns, end_ns = int(previous.timestamp_ns), int(current.timestamp_ns)
    if end_ns <= start_ns:
        return None
    return step_twist(current.motion, start_ns, end_ns, limits).velocity


def step_velocities(
    results: Sequence[OdometryResult], limits: OdometryConfig
) -> list[Velocity | None]:
    """Entry n: the velocity of the odometry step from scan n - 1 into scan n (`step_velocity`;
    None for the first scan)."""
    velocities: list[Velocity | None] = [None] * len(results)
    for n in range(1, len(results)):
        velocities[n] = step_velocity(results[n - 1], results[n], limits)
    return velocities


def scan_sweep_twist(
    velocities: Sequence[Velocity | None], n: int, scan: Scan
) -> FloatArray | None:
    """(3,) twist of scan `n` during its sweep, from `step_velocities` of the whole run (the
    steps into and out of the scan; None when neither is known)."""
    after = velocities[n + 1] if n + 1 < len(velocities) else None
    return sweep_twist(velocities[n], after, mean_acquisition_time_ns(scan))


def twist_change(before: Velocity | None, after: Velocity | None) -> FloatArray | None:
    """(3,) change of the twist across a scan, the step after's minus the step before's
    (vx, vy [m/s], yaw rate [rad/s]); None unless both are known. The sweep twist's error grows
    with it (a yaw-rate step inside the interval; `LoopCovarianceConfig.deskew_error_fraction`)."""
    if before is None or after is None:
        return None
    return np.asarray(after.twist, dtype=np.float64) - np.asarray(before.twist, dtype=np.float64)
