"""The odometry (`Odometry`, keyframes and all) at low frame rates on real scans: every 2nd to
4th scan of the RADIATE fog frames and of the Oxford scans (4 Hz data; steps to 7.5 m and 10 m).

What this checks is registration and keyframing at large steps on real radar.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from odometry import Odometry
from radar_slam.datasets import OxfordSequence, open_sequence
from radar_slam.datasets.frame import RadarSequence
from raplace import se2

MAX_RADIATE_END_FRACTION = 0.01
"""End pose of the strided run against the 4 Hz run, fog frames (about 40 m): translation at
most this fraction of the distance ..."""
MAX_RADIATE_END_DEG = 0.25
"""... and rotation at most this [deg] (0.05, 0.02, 0.07 at strides 2, 3, 4; the 4 Hz run has no
ground truth to say which is nearer the truth, and a wrong registration is degrees off)."""
MAX_OXFORD_END_M = 0.3
"""End pose against the composed GT over the 7 Oxford scans (12.5 m): at most this [m] (0.24,
0.23, 0.18 at strides 1, 2, 3: the GT's own per-pair jitter, see the README) ..."""
MAX_OXFORD_END_DEG = 0.3
"""... and at most this [deg] (0.21, 0.20, 0.13)."""


def poses_at(sequence: RadarSequence, indices: list[int]) -> tuple[NDArray[np.float64], list[int]]:
    """The odometry's (revised) poses (N, 3) over the scans `indices` of `sequence`, defaults,
    and its gaps."""
    odometry = Odometry()
    for index in indices:
        odometry.register(sequence[index])
    return odometry.poses, odometry.gaps


def end_error(truth: NDArray[np.float64], poses: NDArray[np.float64]) -> tuple[float, float]:
    """Translation [m] and rotation [deg] between the first-to-last motions of two runs."""
    diff = se2.between(se2.between(truth[0], truth[-1]), se2.between(poses[0], poses[-1]))
    return float(np.hypot(diff[0], diff[1])), float(np.rad2deg(abs(diff[2])))


@pytest.mark.realdata
@pytest.mark.parametrize("stride", [2, 3, 4])
def test_fog_frames_at_low_frame_rates_agree_with_4_hz(shared_data: Path, stride: int) -> None:
    """No GT comes with the RADIATE frames: the 4 Hz odometry (smooth, forward; see
    `test_datasets_boreas_radiate.py`) is the reference for every `stride`-th frame."""
    sequence = open_sequence(shared_data / "radiate" / "fog_6_0-partial")
    every, _ = poses_at(sequence, list(range(len(sequence))))
    indices = list(range(0, len(sequence), stride))
    strided, gaps = poses_at(sequence, indices)
    assert gaps == []
    reference = every[indices]
    distance = float(np.hypot(*se2.between(reference[0], reference[-1])[:2]))
    err_m, err_deg = end_error(reference, strided)
    assert err_m <= MAX_RADIATE_END_FRACTION * distance, (err_m, distance)
    assert err_deg <= MAX_RADIATE_END_DEG, err_deg


@pytest.mark.realdata
@pytest.mark.parametrize("stride", [1, 2, 3])
def test_oxford_scans_at_low_frame_rates_against_gt(oxford_dir: Path, stride: int) -> None:
    """Every `stride`-th Oxford scan (steps to 7.5 m), against the composed GT."""
    sequence = OxfordSequence(oxford_dir)
    truth = sequence.ground_truth
    assert truth is not None
    indices = list(range(0, len(sequence), stride))
    poses, gaps = poses_at(sequence, indices)
    assert gaps == []
    err_m, err_deg = end_error(truth[indices], poses)
    assert err_m <= MAX_OXFORD_END_M, err_m
    assert err_deg <= MAX_OXFORD_END_DEG, err_deg
