"""Phase-correlation radar odometry (PhaRaO-style). Takes arrays, never paths; no GTSAM.

Public API (what `radar_slam` and a user's own code import from here; the other submodules are
internal, and an import-linter contract keeps `radar_slam` off them):

- the stage: `Odometry` (one `register(frame)` per scan) with `OdometryConfig` and its
  `PreprocessConfig` section, returning `OdometryResult`;
- scans: `RadarFrame` (a scan with its identity), `Scan` (polar power and azimuth times);
- pairwise registration, reused by loop verification and map localisation: `prepare` a scan
  once into a `PreparedScan`, `register` two of them into a `MotionEstimate`
  (`estimate_motion` does both in one call), and `searched_registration` (the de-skew yaw
  rate searched at low frame rates);
- conditioned polar images, reused for map images: `preprocess_polar` -> `PolarScan`,
  `sample_scan`;
- body velocity (vx, vy [m/s], yaw rate [rad/s]): `Velocity`, `twist_from_motion`,
  `motion_from_twist`, `interpolated_twist`, `plausible_twist` (within the vehicle's limits);
- errors: `OdometryError`.
"""


class OdometryError(ValueError):
    """Bad input to the odometry (wrong shape, inconsistent scan geometry, ...)."""


# After OdometryError, which the modules import.
from odometry.config import OdometryConfig, PreprocessConfig  # noqa: E402
from odometry.deskew import motion_from_twist, twist_from_motion  # noqa: E402
from odometry.odometry import Odometry, OdometryResult  # noqa: E402
from odometry.preprocess import PolarScan, preprocess_polar, sample_scan  # noqa: E402
from odometry.rate_search import searched_registration  # noqa: E402
from odometry.recovery import plausible_twist  # noqa: E402
from odometry.reference_time import interpolated_twist  # noqa: E402
from odometry.registration import (  # noqa: E402
    MotionEstimate,
    PreparedScan,
    estimate_motion,
    prepare,
    register,
)
from odometry.scan import RadarFrame, Scan  # noqa: E402
from odometry.velocity import Velocity  # noqa: E402

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
