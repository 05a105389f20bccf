"""SE(2) algebra: known answers and identities."""

from __future__ import annotations

import numpy as np
import pytest

from raplace import se2


def test_compose_known_answer() -> None:
    a = np.array([1.0, 2.0, np.pi / 2])
    b = np.array([3.0, 0.0, 0.0])
    np.testing.assert_allclose(se2.compose(a, b), [1.0, 5.0, np.pi / 2], atol=1e-12)


def test_inverse_and_between_identities() -> None:
    rng = np.random.default_rng(0)
    poses = rng.uniform(-5, 5, size=(50, 3))
    ident = se2.compose(poses, se2.inverse(poses))
    np.testing.assert_allclose(ident, 0.0, atol=1e-12)
    rel = se2.between(poses[:-1], poses[1:])
    np.testing.assert_allclose(se2.compose(poses[:-1], rel)[:, :2], poses[1:, :2], atol=1e-12)
    np.testing.assert_allclose(
        se2.wrap_angle(se2.compose(poses[:-1], rel)[:, 2] - poses[1:, 2]), 0.0, atol=1e-12
    )


def test_accumulate_inverts_relative_motions() -> None:
    steps = np.tile([1.0, 0.0, np.pi / 2], (4, 1))  # a unit square
    poses = se2.accumulate(steps)
    np.testing.assert_allclose(poses[-1], [0.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(se2.relative_motions(poses), steps, atol=1e-12)


def test_matrix_round_trip_and_points() -> None:
    p = np.array([2.0, -1.0, 0.3])
    np.testing.assert_allclose(se2.from_matrix(se2.to_matrix(p)), p, atol=1e-12)
    pts = np.array([[1.0, 0.0], [0.0, 1.0]])
    hom = np.c_[pts, np.ones(2)] @ se2.to_matrix(p).T
    np.testing.assert_allclose(se2.transform_points(p, pts), hom[:, :2], atol=1e-12)


@pytest.mark.parametrize("angle", [np.pi, -np.pi, 3 * np.pi, 7.0])
def test_wrap_angle_range(angle: float) -> None:
    w = float(se2.wrap_angle(angle))
    assert -np.pi <= w < np.pi
    assert np.isclose(np.cos(w), np.cos(angle)) and np.isclose(np.sin(w), np.sin(angle))
