"""The de-skew yaw-rate search by correlation peak quality (`odometry.velocity`, used by loop
verification at low frame rates; `tests/test_loops.py` checks it on a loop query)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from odometry import OdometryConfig, velocity
from odometry.preprocess import preprocess_polar
from odometry.registration import MotionEstimate, PreparedScan, register_images
from odometry.velocity import MAX_VERTEX_STEPS, vertex_offset, weak_searched
from radar_slam.datasets import OxfordSequence


def test_vertex_of_the_peak_quality_parabola() -> None:
    """The parabola through three qualities at -1, 0, +1 half-widths peaks where it should."""
    offsets = np.array([-1.0, 0.0, 1.0])
    for true_peak in (-2.2, -0.6, 0.5, 1.7):
        qualities = 50.0 - 7.0 * (offsets - true_peak) ** 2
        found = vertex_offset((qualities[0], qualities[1], qualities[2]))
        assert found == pytest.approx(true_peak, abs=1e-9)
    assert vertex_offset((40.0, 50.0, 40.0)) is None  # at the point already tried
    assert vertex_offset((50.0, 40.0, 50.0)) is None  # a minimum, not a peak
    assert vertex_offset((10.0, 40.0, 69.0)) == MAX_VERTEX_STEPS  # clipped


@pytest.mark.realdata
def test_only_a_collapsed_peak_has_its_yaw_rate_searched(oxford: OxfordSequence) -> None:
    """Two real Oxford scans 0.25 s apart, de-skewed at the measured twist but 20 deg/s off in
    yaw rate: a peak as strong as the previous scan's is kept without a registration; against a
    previous peak over twice as strong the yaw rate is searched (registrations counted), and
    what comes back correlates at least as strongly."""
    cfg = OdometryConfig()
    twist = np.array([8.0, 0.0, np.deg2rad(20.0)])
    reference = PreparedScan(preprocess_polar(oxford[0], cfg.preprocess), twist, cfg)
    scan = PreparedScan(preprocess_polar(oxford[1], cfg.preprocess), twist, cfg)
    estimate = register_images(reference, scan, cfg)
    assert estimate.ok, estimate.reason
    calls = []

    def counting(*args: Any, **kwargs: Any) -> MotionEstimate:
        calls.append(1)
        return register_images(*args, **kwargs)

    kept = weak_searched(reference, (scan, estimate), estimate.quality, cfg, counting)
    assert kept[1] is estimate and calls == []
    limit = estimate.quality / velocity.WEAK_PEAK_FRACTION
    searched_scan, searched = weak_searched(
        reference, (scan, estimate), 1.01 * limit, cfg, counting
    )
    assert len(calls) >= 2
    assert searched.ok and searched.quality >= estimate.quality
