"""Which de-skew a new scan keeps: the renderings `Odometry` tries for a scan, each step's choice.

A scan is first rendered at the running velocity without its yaw-rate trend and registered
(`Odometry.register`). Then, in order, each step below may render it again and register it
again (seeded with the estimate so far); a new rendering is kept only where the images support
it (a stronger correlation) or the registration itself measured a different velocity:

- `with_trend`: the yaw-rate trend as a second hypothesis (a turn that goes on tightening);
- `redeskewed`: the velocity the registration measures, when far from the rendered one (hard
  braking, a curvature step);
- `weak_searched`: the yaw rate searched by peak quality when the peak is far weaker than the
  previous scan's (`odometry.rate_search`);
- `refreshed`: a new keyframe re-rendered for the scans that will register against it.

Pure functions of the scan, its references (`ScanNode`) and the running `Velocity`; the
registration is `registration.register_images`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from odometry import rate_search
from odometry.config import OdometryConfig
from odometry.deskew import twist_from_motion
from odometry.rate_search import Register
from odometry.reference_time import image_time_ns
from odometry.registration import MotionEstimate, PreparedScan, register_images
from odometry.state import ScanNode
from odometry.velocity import (
    REDESKEW_MPS,
    REDESKEW_RADPS,
    Velocity,
    bounded_twist,
    close_twists,
)
from raplace.se2 import between, compose

FloatArray = NDArray[np.float64]
YAW_TREND_GAIN = 1.0
"""Fraction of the yaw-rate trend extrapolated to a time (bounded by the last measured change,
never across zero; `Velocity.at`): where a turn tightens, a scan de-skewed with the trend
correlates more strongly, and the images pick (`with_trend`)."""
Rendered = tuple[PreparedScan, MotionEstimate]
"""A rendering of a scan and its registration against the reference."""


def expected_twist(
    velocity: Velocity, time_ns: int, cfg: OdometryConfig, trend: bool = True
) -> FloatArray:
    """(3,) the running twist expected at `time_ns` [ns] (with the bounded yaw-rate trend, or
    constant without `trend`), within the plausible speed and yaw rate."""
    gain = YAW_TREND_GAIN if trend else 0.0
    return bounded_twist(velocity.at(time_ns, gain), cfg)


def measured_twist(
    reference: ScanNode, base: ScanNode, estimate: MotionEstimate, interval_s: float
) -> FloatArray:
    """(3,) the twist that moves `base`'s image frame to the one `estimate` places against
    `reference`, over `interval_s` [s]."""
    image_pose = compose(reference.image_pose, estimate.motion)
    return twist_from_motion(between(base.image_pose, image_pose), interval_s)


def with_trend(
    reference: ScanNode,
    scan: PreparedScan,
    estimate: MotionEstimate,
    velocity: Velocity | None,
    cfg: OdometryConfig,
    register: Register = register_images,
) -> Rendered:
    """`scan` (de-skewed at constant velocity) and its estimate, or the scan de-skewed with
    the yaw-rate trend and its registration (seeded with the first) when that correlates
    more strongly; nothing is tried when the trend hardly changes the twist."""
    if scan.twist is None or velocity is None:
        return scan, estimate
    trend = expected_twist(velocity, image_time_ns(scan), cfg)
    if close_twists(trend, scan.twist):
        return scan, estimate
    alternative = PreparedScan(scan.polar, trend, cfg)
    other = register(reference.scan, alternative, cfg, hint=estimate.motion)
    if other.ok and other.quality > estimate.quality:
        return alternative, other
    return scan, estimate


def redeskewed(
    reference: ScanNode,
    base: ScanNode,
    rendered: Rendered,
    interval_s: float,
    velocity: Velocity | None,
    cfg: OdometryConfig,
    register: Register = register_images,
) -> Rendered:
    """The scan and its estimate (`rendered`), re-rendered and re-registered when the velocity
    it was de-skewed with is far from the one its registration measures since `base`
    (`interval_s` [s] before; a step of the velocity: hard braking, a curvature step at a
    junction; a stale velocity bends the image). The re-registration is seeded with the first
    estimate."""
    scan, estimate = rendered
    if scan.twist is None or velocity is None or interval_s <= 0:
        return rendered
    measured = bounded_twist(measured_twist(reference, base, estimate, interval_s), cfg)
    if close_twists(measured, scan.twist, REDESKEW_MPS, REDESKEW_RADPS):
        return rendered
    again = PreparedScan(scan.polar, measured, cfg)
    redone = register(reference.scan, again, cfg, hint=estimate.motion)
    return (again, redone) if redone.ok else rendered


WEAK_PEAK_FRACTION = 0.5
"""A registration whose peak is below this fraction of the previous scan's has its de-skew yaw
rate searched: a de-skew far off (through a yaw-rate reversal between two scans, at 2 Hz) shows
as a peak that collapses, where the real drive's peaks change by tens of per cent per scan."""


def weak_searched(
    reference: ScanNode,
    rendered: Rendered,
    last_quality: float,
    cfg: OdometryConfig,
    register: Register = register_images,
) -> Rendered:
    """The scan and its estimate (`rendered`), or, when its peak is below `WEAK_PEAK_FRACTION` of
    the previous scan's `last_quality`, the scan de-skewed at the yaw rate one round of
    `rate_search.searched` finds (when that correlates more strongly)."""
    scan, estimate = rendered
    if (
        scan.twist is None
        or not estimate.ok
        or estimate.quality >= WEAK_PEAK_FRACTION * last_quality
    ):
        return rendered
    return rate_search.searched(reference.scan, scan, estimate, cfg, register)


def refreshed(scan: PreparedScan, velocity: Velocity | None, cfg: OdometryConfig) -> PreparedScan:
    """A new keyframe re-rendered where its de-skew velocity is stale (e.g. the first scans);
    `scan` itself where nothing would change."""
    if velocity is None or not cfg.deskew or scan.polar.timing is None:
        return scan
    new = expected_twist(velocity, image_time_ns(scan), cfg)
    if scan.twist is not None and close_twists(new, scan.twist):
        return scan
    return PreparedScan(scan.polar, new, cfg)
