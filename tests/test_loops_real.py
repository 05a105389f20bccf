"""Loop verification on real radar: Oxford scans 8-12.5 m apart are verified as loops.

The seven real Oxford scans are one straight drive; a scan and one 8-12.5 m further on are what
a revisit at a low frame rate or in another lane offers the verifier. Without the relative
pose's radial-streak removal the pairs over 8 m are rejected: the scans' radial streaks, which
stay with the sensor, pull the sinogram shifts of the angles along the road to zero (the
inlier fraction falls far lower than on the simulator's streets at these distances).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from radar_slam.datasets.frame import RadarSequence
from radar_slam.datasets.open import open_sequence
from radar_slam.loops.config import LoopClosureConfig
from radar_slam.loops.records import KeyScan
from radar_slam.loops.verification import GeometricVerifier
from raplace.se2 import between, wrap_angle


@pytest.fixture(scope="module")
def oxford(oxford_dir: Path) -> RadarSequence:
    return open_sequence(oxford_dir)


def key_scan(sequence: RadarSequence, k: int) -> KeyScan:
    """Scan k with its ground-truth velocity (central difference) as the de-skew twist."""
    gt = sequence.ground_truth
    assert gt is not None
    times_s = sequence.timestamps_ns * 1e-9
    before, after = max(k - 1, 0), min(k + 1, len(sequence) - 1)
    twist = between(gt[before], gt[after]) / (times_s[after] - times_s[before])
    frame = sequence[k]
    return KeyScan(k, frame.timestamp_ns, frame, twist)


@pytest.mark.parametrize(("query", "match"), [(0, 6), (6, 0), (1, 5), (5, 1)])
def test_real_scans_far_apart_verify_as_loops(oxford: RadarSequence, query: int, match: int):
    gt = oxford.ground_truth
    assert gt is not None
    truth = between(gt[query], gt[match])
    assert np.hypot(truth[0], truth[1]) > 8.0

    result = GeometricVerifier(LoopClosureConfig())(
        key_scan(oxford, query), key_scan(oxford, match)
    )

    assert result.ok, result.reason
    error = between(truth, result.measurement)
    assert np.hypot(error[0], error[1]) < 0.4
    assert np.rad2deg(abs(wrap_angle(error[2]))) < 0.3
    assert np.rad2deg(np.sqrt(result.covariance[2, 2])) < 0.3
