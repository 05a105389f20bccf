"""Phase-correlation radar odometry (PhaRaO-style). Takes arrays, never paths; no GTSAM."""


class OdometryError(ValueError):
    """Bad input to the odometry (wrong shape, inconsistent scan geometry, ...)."""


from odometry.config import OdometryConfig  # noqa: E402  (after OdometryError, which they use)
from odometry.odometry import Odometry, OdometryResult  # noqa: E402
from odometry.registration import MotionEstimate, estimate_motion  # noqa: E402
from odometry.scan import RadarFrame, Scan  # noqa: E402

__all__ = [
    "MotionEstimate",
    "Odometry",
    "OdometryConfig",
    "OdometryError",
    "OdometryResult",
    "RadarFrame",
    "Scan",
    "estimate_motion",
]
