"""GTSAM factors of SE(2) constraints: validation, noise models, loops for a user's own graph.

Conventions are `radar_slam.graph`'s: a measurement is T_i^-1 T_j (3,), a covariance (3, 3) in
GTSAM's Pose2 tangent order (x, y, yaw), symmetric positive definite.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Literal

import gtsam
import numpy as np
from numpy.typing import ArrayLike, NDArray

from radar_slam.errors import GraphError
from radar_slam.loops.records import LoopConstraint
from raplace import adjoint, between, inverse

FloatArray = NDArray[np.float64]
LoopKernel = Literal["cauchy", "huber", "none"]

POSE_DIM = 3
"""Dimension of an SE(2) pose and of its tangent space (x, y, yaw)."""

DEFAULT_LOOP_KERNEL_WIDTH = 3.0
"""Robust-kernel parameter k in whitened units (Mahalanobis distance, i.e. standard deviations).
Cauchy: weight 1 / (1 + (r / k)^2); Huber: weight 1 for r <= k, k / r beyond. k = 1 made ISAM2
all but ignore the first loops of a strongly drifting trajectory (their residual is then hundreds
of sigmas); k = 3 keeps them while still discounting gross outliers (tests/test_graph.py)."""

SYMMETRY_TOLERANCE = 1e-9
"""Largest relative asymmetry |C - C^T| / max|C| accepted in a covariance matrix."""


def as_pose(value: ArrayLike, what: str) -> FloatArray:
    """Return `value` as a finite (3,) float64 pose; GraphError naming `what` otherwise."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (POSE_DIM,):
        raise GraphError(f"{what}: expected shape (3,), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise GraphError(f"{what}: not finite: {arr}")
    return arr.copy()


def as_covariance(value: ArrayLike, what: str) -> FloatArray:
    """Return `value` as a symmetric positive definite (3, 3) covariance; GraphError otherwise.

    A matrix symmetric to `SYMMETRY_TOLERANCE` (relative) is symmetrised exactly.
    """
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (POSE_DIM, POSE_DIM):
        raise GraphError(f"{what}: expected a (3, 3) matrix, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise GraphError(f"{what}: not finite")
    scale = float(np.max(np.abs(arr)))
    if scale == 0.0 or np.max(np.abs(arr - arr.T)) > SYMMETRY_TOLERANCE * scale:
        raise GraphError(f"{what}: not a symmetric positive definite matrix:\n{arr}")
    arr = 0.5 * (arr + arr.T)
    try:
        np.linalg.cholesky(arr)
    except np.linalg.LinAlgError:
        raise GraphError(f"{what}: not positive definite:\n{arr}") from None
    return arr


def gaussian_noise(covariance: ArrayLike) -> gtsam.noiseModel.Base:
    """A GTSAM Gaussian noise model of a (3, 3) SPD covariance (validated)."""
    return gtsam.noiseModel.Gaussian.Covariance(as_covariance(covariance, "covariance"))


def loop_noise(
    covariance: ArrayLike,
    kernel: LoopKernel = "cauchy",
    kernel_width: float = DEFAULT_LOOP_KERNEL_WIDTH,
) -> gtsam.noiseModel.Base:
    """The noise model of a loop factor: Gaussian(covariance) under a robust kernel.

    Args:
        covariance: (3, 3) SPD covariance of the loop measurement.
        kernel: "cauchy", "huber" or "none" (plain Gaussian).
        kernel_width: kernel parameter k in standard deviations (whitened units).
    """
    base = gaussian_noise(covariance)
    estimator = m_estimator(kernel, kernel_width)
    return base if estimator is None else gtsam.noiseModel.Robust.Create(estimator, base)


def m_estimator(
    kernel: str, width: float
) -> gtsam.noiseModel.mEstimator.Cauchy | gtsam.noiseModel.mEstimator.Huber | None:
    if kernel == "cauchy":
        return gtsam.noiseModel.mEstimator.Cauchy.Create(width)
    if kernel == "huber":
        return gtsam.noiseModel.mEstimator.Huber.Create(width)
    if kernel == "none":
        return None
    raise GraphError(f"unknown robust kernel {kernel!r} (cauchy|huber|none)")


def pose2(pose: FloatArray) -> gtsam.Pose2:
    return gtsam.Pose2(float(pose[0]), float(pose[1]), float(pose[2]))


def add_loop_factors(
    graph: gtsam.NonlinearFactorGraph,
    loops: Iterable[LoopConstraint | tuple[int, int, ArrayLike, ArrayLike]],
    kernel: LoopKernel = "cauchy",
    kernel_width: float = DEFAULT_LOOP_KERNEL_WIDTH,
    key: Callable[[int], int] | None = None,
) -> list[int]:
    """Add verified loop constraints to a user's own GTSAM graph as robust between-factors.

    Args:
        graph: the user's `gtsam.NonlinearFactorGraph` (modified in place).
        loops: (i, j, measurement (3,), covariance (3, 3)) items, e.g. `LoopConstraint`s;
            measurement = pose of j in the frame of i.
        kernel: robust kernel "cauchy", "huber" or "none".
        kernel_width: kernel parameter in standard deviations.
        key: maps a keyframe index to the user's GTSAM key (e.g. `gtsam.symbol_shorthand.X`);
            identity by default.

    Returns:
        The indices of the added factors in `graph` (e.g. to leave them out of GNC known inliers).
    """
    to_key = key if key is not None else (lambda k: k)
    added: list[int] = []
    for n, (i, j, measurement, covariance) in enumerate(loops):
        z = as_pose(measurement, f"loop {n} ({i} -> {j}) measurement")
        noise = loop_noise(as_covariance(covariance, f"loop {n} covariance"), kernel, kernel_width)
        added.append(graph.size())
        graph.add(gtsam.BetweenFactorPose2(to_key(i), to_key(j), pose2(z), noise))
    return added


def relative_pose_covariance(
    pose_i: ArrayLike, pose_j: ArrayLike, joint_covariance: ArrayLike
) -> FloatArray:
    """First-order covariance (3, 3) of T_i^-1 T_j given the (6, 6) joint covariance of (i, j).

    The joint covariance is GTSAM's (blocks i then j, each in its own body frame); the result is in
    the frame of the relative pose. Jacobians of `between`: d/di = -Ad((T_i^-1 T_j)^-1), d/dj = I.
    """
    rel = between(pose_i, pose_j)
    h = np.hstack([-adjoint(inverse(rel)), np.eye(POSE_DIM)])
    cov = h @ np.asarray(joint_covariance, dtype=np.float64) @ h.T
    return 0.5 * (cov + cov.T)
