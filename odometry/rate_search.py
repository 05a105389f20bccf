"""A scan's de-skew yaw rate searched by correlation peak quality (weak peaks, loop queries).

Between two scans a second apart the yaw rate interpolated for a sweep can be tens of deg/s off
the sweep's own. Rendered at a range of yaw rates and registered against the same reference, the
peak quality is highest where the scan's de-skew matches the reference image's: it measures the
sweep's yaw rate relative to the reference's de-skew, not the true one, which is what a
registration of the two images needs. The odometry searches a scan whose peak collapsed
(`deskew_choice.weak_searched`); `radar_slam.loops.verification` a loop query's yaw rate at low
frame rates (`searched_registration`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from odometry.config import OdometryConfig
from odometry.registration import MotionEstimate, PreparedScan, register
from odometry.velocity import bounded_twist
from raplace.se2 import inverse

FloatArray = NDArray[np.float64]
Register = Callable[..., MotionEstimate]
"""`registration.register_images` (passed in so that callers can count the registrations)."""
HALF_WIDTH_DPS = 16.0
"""The search tries the yaw rate minus and plus this [deg/s] (then the parabola's vertex): about
the error of a yaw rate interpolated across a second of a junction turn."""
MIN_GAIN = 0.05
"""A searched de-skew replaces the kept one only when its peak quality is higher by more than
this fraction (peak qualities of one pair vary by a few percent with the rendering)."""
LOW_RATE_INTERVAL_S = 0.75
"""The search is for twists interpolated over at least this long [s] (1 Hz; 4 Hz and 2 Hz
interpolate over 0.25 and 0.5 s, where the yaw rate is close enough)."""
MAX_VERTEX_STEPS = 3.0
"""The parabola's vertex is tried at most this many half-widths from the kept yaw rate."""
MIN_VERTEX_OFFSET = 0.25
"""... and only when it is at least this many half-widths from every point already tried."""


def vertex_offset(qualities: tuple[float, float, float]) -> float | None:
    """Where the parabola through peak qualities at offsets -1, 0, +1 (half-widths) peaks,
    within +-`MAX_VERTEX_STEPS`; None when it opens upwards or the vertex is next to a point
    already tried."""
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
    rounds: int = 1,
) -> tuple[PreparedScan, MotionEstimate]:
    """`scan` and its registration against `reference`, or the scan de-skewed at a searched yaw
    rate and its registration (seeded with `estimate`) when that correlates more strongly by
    more than `MIN_GAIN`. Each of up to `rounds` rounds costs 2-3
    registrations and searches around the yaw rate the last one moved to (it stops where one
    does not move). The caller decides whether and how long to search."""
    found_scan, found = scan, estimate
    for _ in range(rounds):
        better = _search_round(reference, found_scan, found, cfg, register)
        if better[0] is found_scan:
            break
        found_scan, found = better
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
    """`estimate`, the registration of `match` against `query` (`registration.register(query,
    match, cfg)`), or the registration with `query` de-skewed at a searched yaw rate when that
    correlates more strongly (`searched`). Only for a query de-skewed with a twist interpolated
    over `twist_span_s` [s] of at least `LOW_RATE_INTERVAL_S` and a valid `estimate`. The search
    registers the query variants against the match; the result is registered again the usual
    way round, seeded with `estimate`."""
    if (
        query.twist is None
        or twist_span_s is None
        or twist_span_s < LOW_RATE_INTERVAL_S
        or not estimate.ok
    ):
        return estimate
    swapped = register(match, query, cfg, inverse(estimate.motion))
    if not swapped.ok:
        return estimate
    found, _ = searched(match, query, swapped, cfg, register)
    if found is query:
        return estimate
    again = register(found, match, cfg, estimate.motion)
    return again if again.ok and again.quality > estimate.quality else estimate


def _search_round(
    reference: PreparedScan,
    scan: PreparedScan,
    estimate: MotionEstimate,
    cfg: OdometryConfig,
    register: Register,
) -> tuple[PreparedScan, MotionEstimate]:
    """The strongest of `scan` and the scan de-skewed at its yaw rate -+ the half-width and at
    the vertex of the parabola through their peak qualities."""
    assert scan.twist is not None
    step = np.deg2rad(HALF_WIDTH_DPS)
    base_twist = scan.twist

    def tried(offset: float) -> tuple[PreparedScan, MotionEstimate]:
        twist = base_twist.copy()
        twist[2] += offset * step
        again = PreparedScan(scan.polar, bounded_twist(twist, cfg), cfg)
        return again, register(reference, again, cfg, hint=estimate.motion)

    candidates = [tried(-1.0), (scan, estimate), tried(1.0)]
    qualities = tuple(e.quality if e.ok else 0.0 for _, e in candidates)
    offset = vertex_offset((qualities[0], qualities[1], qualities[2]))
    if offset is not None:
        candidates.append(tried(offset))
    return max(
        (c for c in candidates if c[1].ok), key=lambda c: c[1].quality, default=(scan, estimate)
    )
