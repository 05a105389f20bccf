"""Phase-correlation radar odometry (PhaRaO-style). Takes arrays, never paths.

Public API (an import-linter contract keeps `radar_slam` off the internal submodules): the stage
`Odometry` (`OdometryConfig`, `PreprocessConfig`, `OdometryResult`); scans `Scan`, `RadarFrame`;
pairwise registration (`prepare` -> `PreparedScan`, `register` -> `MotionEstimate`,
`estimate_motion`, `searched_registration`); conditioned polar images (`preprocess_polar` ->
`PolarScan`, `sample_scan`); body velocity (`Velocity`, `twist_from_motion`,
`motion_from_twist`, `interpolated_twist`, `plausible_twist`); `OdometryError`.
"""


class OdometryError(ValueError):
    """Bad input to the odometry (wrong shape, inconsistent scan geometry, ...)."""


# After OdometryError, which the modules import.
from odometry.config import OdometryConfig, PreprocessConfig  # noqa: E402
from odometry.deskew import motion_from_twist, twist_from_motion  # noqa: E402
from odometry.deskew_choice import searched_registration  # noqa: E402
from odometry.odometry import Odometry, OdometryResult  # noqa: E402
from odometry.preprocess import PolarScan, preprocess_polar, sample_scan  # noqa: E402
from odometry.recovery import plausible_twist  # noqa: E402
from odometry.registration import (  # noqa: E402
    MotionEstimate,
    PreparedScan,
    estimate_motion,
    prepare,
    register,
)
from odometry.scan import RadarFrame, Scan  # noqa: E402
from odometry.velocity import Velocity, interpolated_twist  # noqa: E402

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
