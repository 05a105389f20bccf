"""Covariance terms of the odometry that a registration's correlation peak does not show.

Pure functions used by `odometry.Odometry`: the error of moving a scan's mid-sweep image pose to
its reference time with a measured velocity, and the registration errors that grow with the turn
and with a de-skew velocity that lags the vehicle's (`QualityConfig`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from odometry.registration import PreparedScan
from raplace.se2 import between, rotate_covariance

FloatArray = NDArray[np.float64]

VELOCITY_LAG_FRACTION = 0.25
"""The velocity that moves a pose from mid-sweep to the scan's reference time lags an
accelerating or turning vehicle: its error is taken as this fraction of its last change, per
axis."""
DESKEW_ERROR_FRACTION = 1.25
"""A scan de-skewed with a velocity that lags the vehicle's (braking, a steering change) is bent
by about the velocity's last change times half a sweep; this multiple of that bend is its
translation standard deviation (above 1: the measured change itself lags the true one)."""


def conversion_covariance(
    registration_covariance: FloatArray,
    velocity_change: ArrayLike,
    image_time_s: float,
    interval_s: float,
) -> FloatArray:
    """(3, 3) covariance (scan axes) of moving a scan's image pose to its reference time.

    The offset is the velocity times `image_time_s` [s]; the velocity is a difference of two
    image poses `interval_s` [s] apart (about twice a registration's covariance
    `registration_covariance` over the interval squared) and lags a changing velocity by
    `VELOCITY_LAG_FRACTION` of its last change `velocity_change` (3,) [m/s, m/s, rad/s].
    """
    if image_time_s == 0.0 or interval_s <= 0:
        return np.zeros((3, 3))
    lag = VELOCITY_LAG_FRACTION * np.asarray(velocity_change, dtype=float)
    velocity_covariance = 2.0 * registration_covariance / interval_s**2 + np.diag(lag * lag)
    return image_time_s**2 * velocity_covariance


def deskew_covariance(velocity_change: ArrayLike, scan: PreparedScan) -> FloatArray:
    """(3, 3) covariance [m^2] of a registration error the correlation peak does not show: the
    bend of a scan de-skewed with a velocity that lags the vehicle's by about `velocity_change`
    (3,) (its last change [m/s, m/s, rad/s]) over half a sweep, scaled by
    `DESKEW_ERROR_FRACTION`. It is isotropic in translation, so its axes do not matter."""
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
    """(3, 3) covariance (previous scan's axes) of the factor from the previous scan to the pose
    `pose` (3,), registered against the reference at `reference_pose` (3,): the registration of
    the image frames (`registration_covariance`, in the axes of the reference's image pose
    `reference_image_pose`), the scan's conversion to its reference time (`conversion`, its own
    axes) and the previous scan's (`previous_conversion`, its axes). `previous_turn` [rad] turns
    the reference's axes into the previous scan's. The factor joins the previous scan's pose, so
    its conversion enters, not the reference's (they differ after a keyframe)."""
    in_reference_axes = rotate_covariance(
        registration_covariance, float(between(reference_pose, reference_image_pose)[2])
    ) + rotate_covariance(conversion, float(between(reference_pose, pose)[2]))
    return rotate_covariance(in_reference_axes, previous_turn) + previous_conversion
