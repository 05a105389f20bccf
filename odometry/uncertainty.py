"""Covariance terms that a registration's peak does not show: moving a scan's mid-sweep image
pose to its reference time, and the bend of a de-skew velocity that lags the vehicle's."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from odometry.registration import PreparedScan
from raplace.se2 import between, rotate_covariance

FloatArray = NDArray[np.float64]

VELOCITY_LAG_FRACTION = 0.25
"""The error of the velocity that moves a pose to its reference time: this fraction of its last
change, per axis (it lags an accelerating or turning vehicle)."""
DESKEW_ERROR_FRACTION = 1.25
"""A lagging de-skew velocity bends a scan by about its last change times half a sweep; this
multiple of the bend is the translation standard deviation (the change itself lags)."""


def conversion_covariance(
    registration_covariance: FloatArray,
    velocity_change: ArrayLike,
    image_time_s: float,
    interval_s: float,
) -> FloatArray:
    """(3, 3) covariance (scan axes) of moving a scan's image pose by the velocity over
    `image_time_s` [s]: the velocity is two image poses `interval_s` [s] apart (twice
    `registration_covariance` over the interval squared) lagging by `VELOCITY_LAG_FRACTION` of
    its last change `velocity_change` (3,) [m/s, m/s, rad/s]."""
    if image_time_s == 0.0 or interval_s <= 0:
        return np.zeros((3, 3))
    lag = VELOCITY_LAG_FRACTION * np.asarray(velocity_change, dtype=float)
    velocity_covariance = 2.0 * registration_covariance / interval_s**2 + np.diag(lag * lag)
    return image_time_s**2 * velocity_covariance


def deskew_covariance(velocity_change: ArrayLike, scan: PreparedScan) -> FloatArray:
    """(3, 3) isotropic translation covariance [m^2] of the bend of a scan de-skewed with a
    velocity lagging by its last change `velocity_change` (3,) [m/s, m/s, rad/s]."""
    timing = scan.polar.timing
    half_sweep_s = 0.0 if timing is None else 0.5 * scan.polar.n_azimuths * timing.row_period_s
    bend = half_sweep_s * np.abs(np.asarray(velocity_change, dtype=float))
    sigma_xy_sq = DESKEW_ERROR_FRACTION**2 * float(bend[0] ** 2 + bend[1] ** 2)
    return np.diag([sigma_xy_sq, sigma_xy_sq, 0.0])


def factor_covariance(
    registration_covariance: FloatArray,
    reference_pose: FloatArray,
    reference_image_pose: FloatArray,
    pose: FloatArray,
    conversion: FloatArray,
    previous_turn: float,
    previous_conversion: FloatArray,
) -> FloatArray:
    """(3, 3) covariance (previous scan's axes) of the factor from the previous scan to `pose`
    (3,) registered against the reference at `reference_pose` (3,): the registration's (axes of
    `reference_image_pose`), the scan's `conversion` (own axes) and the previous scan's
    `previous_conversion` (its axes); `previous_turn` [rad] turns the reference's axes into the
    previous scan's."""
    in_reference_axes = rotate_covariance(
        registration_covariance, float(between(reference_pose, reference_image_pose)[2])
    ) + rotate_covariance(conversion, float(between(reference_pose, pose)[2]))
    return rotate_covariance(in_reference_axes, previous_turn) + previous_conversion
