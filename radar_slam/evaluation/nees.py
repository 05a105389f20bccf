"""Consistency of pose-graph factors against ground truth: NEES of between-factors.

A between-factor states T_i^-1 T_j = `measurement` with a covariance in GTSAM's tangent space,
perturbed on the right (the frame of pose j). Its error against the truth is the truth's relative
pose seen from the measurement, `between(measurement, between(truth_i, truth_j))`, (x, y, yaw) in
that frame; the normalised estimation error squared (NEES) is e^T C^-1 e, 3 on average (3 DoF)
when the covariances are calibrated. Used by `scripts/bench_nees.py` and the tests; the library
core never imports it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raplace import between, wrap_angle

FloatArray = NDArray[np.float64]


def factor_error(measurement: ArrayLike, truth_i: ArrayLike, truth_j: ArrayLike) -> FloatArray:
    """(3,) error (x, y [m], yaw [rad]) of a between-factor's `measurement` (T_i^-1 T_j) against
    the ground-truth poses `truth_i`, `truth_j` (3,), in the frame of the measurement's end."""
    error = between(measurement, between(truth_i, truth_j))
    error[2] = wrap_angle(error[2])
    return error


@dataclass(frozen=True)
class FactorNees:
    """NEES of one between-factor.

    Attributes:
        nees: e^T C^-1 e (3 DoF; 3 on average when calibrated).
        axes: (3,) per-axis normalised squared errors e_k^2 / C_kk (x, y, yaw; 1 on average when
            calibrated).
        error: (3,) the error e (x, y [m], yaw [rad]).
    """

    nees: float
    axes: FloatArray
    error: FloatArray


def factor_nees(
    measurement: ArrayLike, covariance: ArrayLike, truth_i: ArrayLike, truth_j: ArrayLike
) -> FactorNees:
    """NEES of a between-factor (`measurement` (3,) T_i^-1 T_j, `covariance` (3, 3) in GTSAM's
    tangent, the frame of pose j) against the ground-truth poses `truth_i`, `truth_j` (3,)."""
    error = factor_error(measurement, truth_i, truth_j)
    cov = np.asarray(covariance, dtype=np.float64)
    nees = float(error @ np.linalg.solve(cov, error))
    return FactorNees(nees, error * error / np.diag(cov), error)
