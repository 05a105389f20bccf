"""The motion model (steps 3-5 of `odometry.odometry`): the running velocity, the vehicle's limits
on it, the move between a scan's image and reference times, and which de-skew a scan keeps."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from odometry.config import OdometryConfig
from odometry.preprocess import motion_from_twist
from odometry.registration import MotionEstimate, PreparedScan, register, register_images
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
Register = Callable[..., MotionEstimate]  # `register_images`, passed in to count registrations
Rendered = tuple[PreparedScan, MotionEstimate]  # a rendering of a scan and its registration
YAW_TREND_GAIN = 1.0
"""Fraction of the bounded yaw-rate trend (`Velocity.at`) in the second de-skew hypothesis."""
WEAK_PEAK_FRACTION = 0.5
"""A peak below this fraction of the previous scan's has its de-skew yaw rate searched (a de-skew
far off collapses the peak; the real drive's peaks change by tens of per cent per scan)."""
HALF_WIDTH_DPS = 16.0
"""The search tries the yaw rate -+ this [deg/s], then the parabola's vertex (about the error of
a yaw rate interpolated across a second of a junction turn)."""
MIN_GAIN = 0.05
"""A searched de-skew is kept only when its peak is stronger by more than this fraction."""
LOW_RATE_INTERVAL_S = 0.75
"""Loop queries are searched, and a yaw rate crossing zero not extrapolated, over this long [s]."""
YAW_RATE_NOISE_RADPS = np.deg2rad(2.5)
"""A 1 Hz yaw rate [rad/s] at most this large is a straight road's (above what the real drive
measures on its straight stretches): going from it to a turn is a turn starting, not a crossing."""
MAX_VERTEX_STEPS = 3.0
"""The parabola's vertex is tried at most this many half-widths from the kept yaw rate ..."""
MIN_VERTEX_OFFSET = 0.25
"""... and only when it is at least this many half-widths from every point already tried."""


@dataclass(frozen=True)
class Velocity:
    """The twist (vx, vy [m/s], yaw rate [rad/s]) measured between two image poses, at the middle
    `time_ns`, and its yaw rate's change since the last (`yaw_rate_change` [rad/s], `span_s`)."""

    twist: FloatArray
    time_ns: int
    yaw_rate_change: float = 0.0
    span_s: float = 0.0

    def at(self, time_ns: int, trend_gain: float) -> FloatArray:
        """The twist at `time_ns` plus `trend_gain` times the yaw-rate trend extrapolated
        linearly, by at most the last change, never across zero; none over a low-rate interval
        across which it crossed zero (zero if it fell in size), but out of noise into a turn."""
        twist = self.twist.copy()
        if trend_gain == 0.0 or self.span_s <= 0.0:
            return twist
        elapsed_s = (time_ns - self.time_ns) / NS_PER_S
        limit = abs(self.yaw_rate_change)
        delta = float(np.clip(self.yaw_rate_change / self.span_s * elapsed_s, -limit, limit))
        yaw_rate, previous = twist[2] + trend_gain * delta, twist[2] - self.yaw_rate_change
        starting = abs(previous) <= YAW_RATE_NOISE_RADPS < abs(twist[2])  # a turn, from noise
        if self.span_s >= LOW_RATE_INTERVAL_S and twist[2] * previous < 0.0 and not starting:
            yaw_rate = twist[2] * float(abs(twist[2]) >= abs(previous))  # a swing; a turn ended
        twist[2] = yaw_rate if yaw_rate * twist[2] > 0.0 else 0.0
        return twist

    def updated(self, twist: FloatArray, time_ns: int) -> Velocity:
        """The velocity after measuring `twist` over an interval centred at `time_ns`."""
        span_s = (time_ns - self.time_ns) / NS_PER_S
        change = float(twist[2] - self.twist[2]) if span_s > 0 else 0.0
        return Velocity(twist, time_ns, change, max(span_s, 0.0))


def plausible_twist(twist: FloatArray, cfg: OdometryConfig) -> bool:
    """`twist` (vx, vy [m/s], yaw rate [rad/s]) is within the vehicle's speed and yaw rate."""
    fast = np.hypot(twist[0], twist[1]) > cfg.quality.max_speed_mps
    return not (fast or np.rad2deg(abs(twist[2])) > cfg.quality.max_yaw_rate_dps)


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


def close_twists(a: FloatArray, b: FloatArray, speed_mps: float, yaw_rate_radps: float) -> bool:
    """Two twists differ by at most `speed_mps` and `yaw_rate_radps`."""
    near = np.hypot(a[0] - b[0], a[1] - b[1]) <= speed_mps
    return bool(near and abs(a[2] - b[2]) <= yaw_rate_radps)


def agrees(motion: FloatArray, expected: FloatArray) -> bool:
    """`motion` (3,) is within the prediction tolerances of `expected` (3,), in one frame."""
    off = np.asarray(motion, dtype=np.float64) - np.asarray(expected, dtype=np.float64)
    near = np.hypot(off[0], off[1]) <= PREDICTION_TOLERANCE_M
    return bool(near and abs(wrap_angle(float(off[2]))) <= np.deg2rad(PREDICTION_TOLERANCE_DEG))


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


def expected_twist(
    velocity: Velocity, time_ns: int, cfg: OdometryConfig, trend: bool = True
) -> FloatArray:
    """(3,) the running twist at `time_ns` [ns], with the yaw-rate trend when `trend`, bounded."""
    return bounded_twist(velocity.at(time_ns, YAW_TREND_GAIN if trend else 0.0), cfg)


def with_trend(
    reference: PreparedScan,
    scan: PreparedScan,
    estimate: MotionEstimate,
    velocity: Velocity,
    cfg: OdometryConfig,
    register: Register = register_images,
) -> Rendered:
    """`scan` and its estimate, or the scan de-skewed with the yaw-rate trend (a tightening turn)
    when that correlates more strongly (not tried when the trend hardly changes the twist)."""
    if scan.twist is None:
        return scan, estimate
    trend = expected_twist(velocity, image_time_ns(scan), cfg)
    if close_twists(trend, scan.twist, TWIST_REFRESH_MPS, TWIST_REFRESH_RADPS):
        return scan, estimate
    alternative = PreparedScan(scan.polar, trend, cfg)
    other = register(reference, alternative, cfg, hint=estimate.motion)
    if other.ok and other.quality > estimate.quality:
        return alternative, other
    return scan, estimate


def redeskewed(
    ref: PreparedScan,
    rendered: Rendered,
    twist: FloatArray,
    cfg: OdometryConfig,
    register: Register,
) -> Rendered:
    """`rendered`, or the scan re-rendered at the `twist` (3,) its registration measures when
    that is far from the one it was de-skewed with (hard braking, a curvature step)."""
    scan, estimate = rendered
    if scan.twist is None:
        return rendered
    twist = bounded_twist(twist, cfg)
    if close_twists(twist, scan.twist, REDESKEW_MPS, REDESKEW_RADPS):
        return rendered
    again = PreparedScan(scan.polar, twist, cfg)
    redone = register(ref, again, cfg, hint=estimate.motion)
    return (again, redone) if redone.ok else rendered


def weak_searched(
    ref: PreparedScan, rendered: Rendered, last: float, cfg: OdometryConfig, register: Register
) -> Rendered:
    """`rendered`, or below `WEAK_PEAK_FRACTION` of the previous peak `last`, the `searched` one."""
    scan, estimate = rendered
    strong = estimate.quality >= WEAK_PEAK_FRACTION * last
    if scan.twist is None or not estimate.ok or strong:
        return rendered
    return searched(ref, scan, estimate, cfg, register)


def refreshed(scan: PreparedScan, velocity: Velocity, cfg: OdometryConfig) -> PreparedScan:
    """A new keyframe re-rendered where its de-skew velocity is stale (e.g. the first scans)."""
    if not cfg.deskew or scan.polar.timing is None:
        return scan
    new = expected_twist(velocity, image_time_ns(scan), cfg)
    old = scan.twist
    if old is not None and close_twists(new, old, TWIST_REFRESH_MPS, TWIST_REFRESH_RADPS):
        return scan
    return PreparedScan(scan.polar, new, cfg)


def vertex_offset(qualities: tuple[float, float, float]) -> float | None:
    """Where the parabola through peak qualities at offsets -1, 0, +1 (half-widths) peaks,
    within +-`MAX_VERTEX_STEPS`; None when it opens upwards or is next to a point tried."""
    low, mid, high = qualities
    curvature = low - 2.0 * mid + high
    if curvature >= 0.0:
        return None
    offset = float(np.clip(0.5 * (low - high) / curvature, -MAX_VERTEX_STEPS, MAX_VERTEX_STEPS))
    if min(abs(offset), abs(abs(offset) - 1.0)) <= MIN_VERTEX_OFFSET:
        return None
    return offset


def searched(
    reference: PreparedScan,
    scan: PreparedScan,
    estimate: MotionEstimate,
    cfg: OdometryConfig,
    register: Register,
) -> Rendered:
    """`scan` and its `estimate`, or the scan de-skewed at the yaw rate -+ `HALF_WIDTH_DPS` or the
    parabola's vertex (seeded with `estimate`) whose peak is stronger by over `MIN_GAIN` (peaks
    are strongest where the scan's de-skew matches the reference image's)."""
    assert scan.twist is not None
    base_twist = scan.twist

    def tried(offset: float) -> Rendered:
        twist = base_twist.copy()
        twist[2] += offset * np.deg2rad(HALF_WIDTH_DPS)
        again = PreparedScan(scan.polar, bounded_twist(twist, cfg), cfg)
        return again, register(reference, again, cfg, hint=estimate.motion)

    candidates = [tried(-1.0), (scan, estimate), tried(1.0)]
    qualities = tuple(e.quality if e.ok else 0.0 for _, e in candidates)
    offset = vertex_offset((qualities[0], qualities[1], qualities[2]))
    if offset is not None:
        candidates.append(tried(offset))
    found_scan, found = max(
        (c for c in candidates if c[1].ok), key=lambda c: c[1].quality, default=(scan, estimate)
    )
    if found.quality <= (1.0 + MIN_GAIN) * estimate.quality:
        return scan, estimate
    return found_scan, found


def searched_registration(
    query: PreparedScan,
    match: PreparedScan,
    estimate: MotionEstimate,
    cfg: OdometryConfig,
    twist_span_s: float | None,
) -> MotionEstimate:
    """`estimate` (`register(query, match, cfg)`), or the registration with `query` de-skewed at
    a searched yaw rate when that correlates more strongly; only for a query twist interpolated
    over `twist_span_s` [s] of at least `LOW_RATE_INTERVAL_S` and a valid `estimate`."""
    short = twist_span_s is None or twist_span_s < LOW_RATE_INTERVAL_S
    if query.twist is None or short or not estimate.ok:
        return estimate
    swapped = register(match, query, cfg, inverse(estimate.motion))
    if not swapped.ok:
        return estimate
    found, _ = searched(match, query, swapped, cfg, register)
    if found is query:
        return estimate
    again = register(found, match, cfg, estimate.motion)
    return again if again.ok and again.quality > estimate.quality else estimate
