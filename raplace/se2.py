"""SE(2) pose algebra on (x, y, yaw) arrays: the one home of these helpers for every package.

Conventions (one for the whole project):
- Poses are `(..., 3)` float arrays `(x [m], y [m], yaw [rad])`; `compose(a, b)` is a * b, so
  `T_world_b = compose(T_world_a, T_a_b)`. Every function broadcasts over leading axes.
- Angles are wrapped to [-pi, pi) (`wrap_angle`): pi maps to -pi.
- Tangent vectors and covariances are in GTSAM's order (x, y, yaw), translation first.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


def wrap_angle(angle: ArrayLike) -> FloatArray:
    """Wrap angles [rad] into [-pi, pi)."""
    a = np.asarray(angle, dtype=np.float64)
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def adjoint(pose: ArrayLike) -> FloatArray:
    """SE(2) adjoint (..., 3, 3) of poses (..., 3) in the tangent order (x, y, yaw):
    Exp(Ad(T) xi) = T Exp(xi) T^-1 (equal to GTSAM's `Pose2.AdjointMap`)."""
    p = np.asarray(pose, dtype=np.float64)
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    ad = np.zeros(p.shape[:-1] + (3, 3))
    ad[..., 0, 0], ad[..., 0, 1], ad[..., 0, 2] = c, -s, p[..., 1]
    ad[..., 1, 0], ad[..., 1, 1], ad[..., 1, 2] = s, c, -p[..., 0]
    ad[..., 2, 2] = 1.0
    return ad


def rotate_covariance(covariance: ArrayLike, yaw_rad: float) -> FloatArray:
    """Re-express a (3, 3) covariance (x, y, yaw order) whose translation block is in frame B in
    the axes of frame A, where B is turned by `yaw_rad` relative to A (B's yaw in A).

    The translation block becomes R(yaw) C R(yaw)^T; the yaw variance is unchanged. The result is
    symmetrised (exactly symmetric, as GTSAM requires).
    """
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    out = rot @ np.asarray(covariance, dtype=np.float64) @ rot.T
    return 0.5 * (out + out.T)


def compose(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """Return a * b for poses `a`, `b` of shape (..., 3)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    return np.stack([x, y, wrap_angle(a[..., 2] + b[..., 2])], axis=-1)


def inverse(a: ArrayLike) -> FloatArray:
    """Return a^-1 for poses of shape (..., 3)."""
    a = np.asarray(a, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = -(c * a[..., 0] + s * a[..., 1])
    y = -(-s * a[..., 0] + c * a[..., 1])
    return np.stack([x, y, wrap_angle(-a[..., 2])], axis=-1)


def between(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """Return a^-1 * b: pose `b` expressed in the frame of `a`."""
    return compose(inverse(a), b)


def accumulate(relative: ArrayLike, start: ArrayLike = (0.0, 0.0, 0.0)) -> FloatArray:
    """Chain relative motions (N, 3) into absolute poses (N + 1, 3) starting at `start`."""
    rel = np.asarray(relative, dtype=np.float64).reshape(-1, 3)
    poses = np.empty((len(rel) + 1, 3))
    poses[0] = start
    for k, step in enumerate(rel):  # sequential by nature: each pose depends on the previous
        poses[k + 1] = compose(poses[k], step)
    return poses


def relative_motions(poses: ArrayLike) -> FloatArray:
    """Return the motions between consecutive poses: (N, 3) -> (N - 1, 3)."""
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    return between(p[:-1], p[1:])


def transform_points(pose: ArrayLike, points: ArrayLike) -> FloatArray:
    """Map points (..., 2) given in the frame of `pose` (3,) into its parent frame."""
    p = np.asarray(pose, dtype=np.float64)
    pts = np.asarray(points, dtype=np.float64)
    c, s = np.cos(p[2]), np.sin(p[2])
    rot = np.array([[c, -s], [s, c]])
    return pts @ rot.T + p[:2]


def to_matrix(a: ArrayLike) -> FloatArray:
    """Return homogeneous 3x3 matrices (..., 3, 3) of poses (..., 3)."""
    a = np.asarray(a, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    m = np.zeros(a.shape[:-1] + (3, 3))
    m[..., 0, 0], m[..., 0, 1], m[..., 0, 2] = c, -s, a[..., 0]
    m[..., 1, 0], m[..., 1, 1], m[..., 1, 2] = s, c, a[..., 1]
    m[..., 2, 2] = 1.0
    return m


def from_matrix(m: ArrayLike) -> FloatArray:
    """Inverse of `to_matrix`: (..., 3, 3) -> (..., 3)."""
    m = np.asarray(m, dtype=np.float64)
    return np.stack([m[..., 0, 2], m[..., 1, 2], np.arctan2(m[..., 1, 0], m[..., 0, 0])], axis=-1)
