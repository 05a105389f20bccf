"""Known rotations recovered without bias: exactly rendered point-target scans.

The Fourier-Mellin rotation locks toward zero for rotations below about a degree (it finds a
few per cent of them), so the coarse translation was made at a yaw off by nearly the whole
rotation; its error leaked into the rotation refinement as a yaw error of about -3.7 % of the
rotation at a 10 m baseline (-34 mdeg mean for 0.9 deg, up to -73). The rotation is refined
again at the translation re-estimated at the refined yaw, coarse then fine, and the error no
longer follows the rotation. A registration seeded with a predicted yaw a few degrees off (a
turn's onset) needs two refinement passes at the coarse translation to converge as far.

Refined at the coarse translation only, an error of that translation along the motion turns a
scene with returns on one side only (a lane's kerb and parked cars) into a yaw bias: about 8-10
mdeg per metre of motion; refined at the fine translation, about a third of that.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from point_scenes import point_scene, render_polar, scan_frame, static_poses

from odometry import registration
from odometry.config import OdometryConfig
from odometry.phase_correlation import ROTATION
from odometry.registration import estimate_motion, prepare, register

SEEDS = range(5)
MAX_MEAN_RELATIVE_ERROR = 0.005
"""Mean yaw error over the scenes as a fraction of the rotation (a single pass: -3.7 %)."""
MAX_ERROR_MDEG = 12.0
"""Largest single yaw error [mdeg] (a single pass: up to 73 mdeg at 0.9 deg)."""
MAX_STILL_ERROR_MDEG = 1.0
"""Mean yaw error [mdeg] of a rotation without translation."""
MAX_ONE_SIDED_MDEG = 20.0
"""Mean yaw error [mdeg] of 5 m straight ahead with every target on one side."""


def _cfg() -> OdometryConfig:
    """Without de-skew."""
    return OdometryConfig(deskew=False)


def _yaw_errors_mdeg(
    translation_m: tuple[float, float],
    rotation_mdeg: float,
    cfg: OdometryConfig,
    hint_off_deg: float | None = None,
    side: float | None = None,
) -> np.ndarray:
    """Yaw error [mdeg] over the SEEDS scenes for a known motion: of `estimate_motion`, or with
    `hint_off_deg` of a registration seeded with the motion but for a yaw that far off and 0.3 m
    along, 0.2 m across; `side` keeps only the targets more than 3 m to one side (left: +1)."""
    rotation = np.radians(rotation_mdeg / 1000.0)
    errors = []
    for seed in SEEDS:
        targets = point_scene(np.random.default_rng(seed))
        if side is not None:
            targets = targets[side * targets[:, 1] > 3.0]
        ref = scan_frame(render_polar(targets, static_poses([0.0, 0.0, 0.0])), 10**9, False)
        pose = [translation_m[0], translation_m[1], rotation]
        cur = scan_frame(render_polar(targets, static_poses(pose)), 10**9 + 250_000_000, False)
        if hint_off_deg is None:
            estimate = estimate_motion(ref, cur, cfg)
        else:
            hint = np.array(pose) + [0.3, 0.2, np.radians(hint_off_deg)]
            estimate = register(prepare(ref, cfg), prepare(cur, cfg), cfg, hint=hint)
        assert estimate.ok, estimate.reason
        np.testing.assert_allclose(estimate.motion[:2], translation_m, atol=0.05)
        errors.append(np.degrees(estimate.motion[2]) * 1000.0 - rotation_mdeg)
    return np.array(errors)


@pytest.mark.parametrize("rotation_mdeg", [450.0, 900.0, -700.0])
def test_sub_degree_rotation_with_translation_is_unbiased(rotation_mdeg: float) -> None:
    errors = _yaw_errors_mdeg((10.0, 0.0), rotation_mdeg, _cfg())
    assert abs(errors.mean() / rotation_mdeg) < MAX_MEAN_RELATIVE_ERROR, errors
    assert np.abs(errors).max() < MAX_ERROR_MDEG, errors


def test_default_refinement_removes_the_bias() -> None:
    errors = _yaw_errors_mdeg((10.0, 0.0), 900.0, _cfg())
    assert abs(errors.mean() / 900.0) < MAX_MEAN_RELATIVE_ERROR, errors


@pytest.mark.parametrize("hint_off_deg", [2.0, -2.0])
def test_seeded_rotation_converges_from_a_prediction_degrees_off(hint_off_deg: float) -> None:
    errors = _yaw_errors_mdeg((10.0, 0.0), 900.0, _cfg(), hint_off_deg)
    assert np.abs(errors).max() < MAX_ERROR_MDEG, errors


def test_one_refinement_pass_stops_short_of_a_prediction_degrees_off(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(registration, "ROTATION", dataclasses.replace(ROTATION, refine_passes=1))
    errors = _yaw_errors_mdeg((10.0, 0.0), 900.0, _cfg(), -2.0)
    assert np.abs(errors).max() > MAX_ERROR_MDEG, errors


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_straight_motion_past_returns_on_one_side_turns_little(side: float) -> None:
    """5 m straight ahead with every target on one side (left: +1): a small mean yaw error
    (about 13 mdeg; 37-49 with the rotation refined at the coarse translation only)."""
    errors = _yaw_errors_mdeg((5.0, 0.0), 0.0, _cfg(), side=side)
    assert abs(errors.mean()) < MAX_ONE_SIDED_MDEG, errors


@pytest.mark.parametrize("rotation_mdeg", [225.0, 900.0])
def test_sub_degree_rotation_in_place_is_unbiased(rotation_mdeg: float) -> None:
    errors = _yaw_errors_mdeg((0.0, 0.0), rotation_mdeg, _cfg())
    assert abs(errors.mean()) < MAX_STILL_ERROR_MDEG, errors
