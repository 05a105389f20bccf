"""Phase-correlation radar odometry (PhaRaO-style; the method: `odometry.odometry`). Takes
arrays, never paths. `__all__` is the public API (an import-linter contract keeps `radar_slam`
off the submodules)."""
# ruff: noqa: E402


class OdometryError(ValueError):
    """Bad input to the odometry (wrong shape, inconsistent scan geometry, ...)."""


# After OdometryError, which the modules import.
from odometry.config import OdometryConfig, PreprocessConfig
from odometry.odometry import Odometry, OdometryResult
from odometry.preprocess import (
    PolarScan,
    RadarFrame,
    Scan,
    motion_from_twist,
    preprocess_polar,
    sample_scan,
    twist_from_motion,
)
from odometry.registration import MotionEstimate, PreparedScan, estimate_motion, prepare, register
from odometry.velocity import Velocity, interpolated_twist, plausible_twist, searched_registration

__all__ = [
    "MotionEstimate",
    "Odometry",
    "OdometryConfig",
    "OdometryError",
    "OdometryResult",
    "PolarScan",
    "PreparedScan",
    "PreprocessConfig",
    "RadarFrame",
    "Scan",
    "Velocity",
    "estimate_motion",
    "interpolated_twist",
    "motion_from_twist",
    "plausible_twist",
    "prepare",
    "preprocess_polar",
    "register",
    "sample_scan",
    "searched_registration",
    "twist_from_motion",
]
