"""Phase-correlation radar odometry (PhaRaO-style). Takes arrays, never paths; no GTSAM."""


class OdometryError(ValueError):
    """Bad input to the odometry (wrong shape, inconsistent scan geometry, ...)."""
