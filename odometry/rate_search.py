"""A new scan's de-skew yaw rate searched by correlation peak quality at low frame rates.

At 1 Hz the velocity a scan is de-skewed with is the mean over the second before it; through a
yaw-rate step or reversal the sweep's own yaw rate can be tens of deg/s away. Rendered at a range
of yaw rates and registered against the same reference, the peak quality is highest where the
scan's de-skew matches the reference image's: it measures the sweep's yaw rate *relative to the
reference's de-skew* (its error follows the reference's de-skew error), not the true one. Both
images distorted alike register to a better relative motion than one distorted and one right
(docs/odometry_notes.md, issue 10y), which is what this search buys. It runs at every scan of a
low frame rate (a long interval between the image frames; `DeskewConfig.yaw_rate_search_*`).

Because the search measures a rate relative to the reference's, a new keyframe at a low frame
rate is not re-rendered at what the search found, nor at the mean yaw rate since the previous
image (a 1 s mean misses a curvature change inside the second), but at `keyframe_yaw_rate`: that
mean plus half the change between the two sweeps' rates that the search measured. The yaw step
between the two images gives the sum of the two sweeps' rates, the search their difference, so
the keyframe's rate does not carry the reference's error (where the yaw rate is linear between
the two sweeps), and the next scan's search matches it (docs/odometry_notes.md, stop 19). When
the previous scan was not a keyframe, both scans were searched against the same keyframe: the
difference of their two searched rates is the change, and the reference's error cancels in it
(stop 20).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from odometry.config import OdometryConfig
from odometry.registration import MotionEstimate, PreparedScan
from odometry.velocity import bounded_twist

FloatArray = NDArray[np.float64]
Register = Callable[..., MotionEstimate]
"""`registration.register_images` (passed in so that callers can count the registrations)."""
MAX_VERTEX_STEPS = 3.0
"""The parabola's vertex is tried at most this many half-widths from the kept yaw rate."""
MIN_VERTEX_OFFSET = 0.25
"""... and only when it is at least this many half-widths from every point already tried."""


def rounds_wanted(
    scan: PreparedScan, estimate: MotionEstimate, interval_s: float, cfg: OdometryConfig
) -> int:
    """How many rounds of search `scan`'s de-skew yaw rate gets (0: none): a de-skewed,
    registered scan (`estimate`) whose image frame is `interval_s` [s] after the last one, at
    least `yaw_rate_search_min_interval_s` (a low frame rate), gets
    `yaw_rate_search_slow_rounds` rounds while the search is on."""
    if scan.twist is None or not estimate.ok or not searched_slowly(interval_s, cfg):
        return 0
    return cfg.deskew.yaw_rate_search_slow_rounds


def searched_slowly(interval_s: float, cfg: OdometryConfig) -> bool:
    """Whether a scan `interval_s` [s] after its reference image has its de-skew yaw rate
    searched as at a low frame rate (`rounds_wanted`)."""
    dcfg = cfg.deskew
    return dcfg.yaw_rate_search_dps > 0.0 and interval_s >= dcfg.yaw_rate_search_min_interval_s


def keyframe_yaw_rate(mean_rate: float, searched_rate: float, reference_rate: float) -> float:
    """The de-skew yaw rate [rad/s] of a new keyframe at a low frame rate.

    Args:
        mean_rate: the mean yaw rate between the previous scan's image and the keyframe's
            [rad/s].
        searched_rate: the keyframe's de-skew yaw rate as its search left it [rad/s] ...
        reference_rate: ... and the previous scan's [rad/s], relative to the same image: the
            previous scan itself (the keyframe was searched against it) or the image both were
            searched against. Their difference is the change of the yaw rate from one sweep to
            the other (the search matches distortions, so the common image's error cancels).

    With the yaw rate linear in time between the two sweeps, the mean is the average of their
    rates; half the measured change on top of it is the keyframe's sweep rate.
    """
    return mean_rate + 0.5 * (searched_rate - reference_rate)


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
    more than `DeskewConfig.yaw_rate_search_min_gain`. Each of up to `rounds` rounds costs 2-3
    registrations and searches around the yaw rate the last one moved to (it stops where one
    does not move). The caller decides whether and how long to search (`rounds_wanted`)."""
    found_scan, found = scan, estimate
    for _ in range(rounds):
        better = _search_round(reference, found_scan, found, cfg, register)
        if better[0] is found_scan:
            break
        found_scan, found = better
    gain = cfg.deskew.yaw_rate_search_min_gain
    if found.quality <= (1.0 + gain) * estimate.quality:
        return scan, estimate
    return found_scan, found


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
    step = np.deg2rad(cfg.deskew.yaw_rate_search_dps)
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
