"""Ground-truth judging of loop closures (evaluation only; the loop detector never uses it)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from raplace import between, wrap_angle

REVISIT_CRITERION_M = 20.0
"""Two scans less than this apart (ground truth) see the same place (RaPlace's criterion)."""
TRUE_LOOP_MAX_ERROR_M = 1.0
"""A true loop's measured translation is within this of the ground-truth relative pose [m]."""
TRUE_LOOP_MAX_ERROR_DEG = 2.0
"""... and its rotation within this [deg]."""


def is_true_loop(
    measurement: ArrayLike,
    gt_query: ArrayLike,
    gt_match: ArrayLike,
    criterion_m: float = REVISIT_CRITERION_M,
    max_error_m: float = TRUE_LOOP_MAX_ERROR_M,
    max_error_deg: float = TRUE_LOOP_MAX_ERROR_DEG,
) -> bool | None:
    """Whether a loop is true: the scans lie within `criterion_m` (ground truth) AND the measured
    T_query_match is within `max_error_m` / `max_error_deg` of the ground-truth relative pose.

    Args:
        measurement: (3,) measured T_query_match (NaN: no estimate).
        gt_query, gt_match: (3,) ground-truth T_world_radar of the two scans (NaN: unknown).

    Returns:
        None when a ground-truth pose is unknown, else the verdict.
    """
    q = np.asarray(gt_query, dtype=np.float64)
    m = np.asarray(gt_match, dtype=np.float64)
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(m))):
        return None
    z = np.asarray(measurement, dtype=np.float64)
    if np.hypot(*(m[:2] - q[:2])) > criterion_m or not np.all(np.isfinite(z)):
        return False
    error = between(between(q, m), z)
    return bool(
        np.hypot(error[0], error[1]) <= max_error_m
        and abs(float(wrap_angle(error[2]))) <= np.deg2rad(max_error_deg)
    )
