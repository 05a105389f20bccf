"""The de-skew yaw-rate search by correlation peak quality (`odometry.rate_search`, used by loop
verification at low frame rates; `tests/test_loops.py` checks it on a loop query)."""

from __future__ import annotations

import numpy as np
import pytest

from odometry.rate_search import MAX_VERTEX_STEPS, vertex_offset


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
