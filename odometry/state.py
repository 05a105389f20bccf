"""The odometry's working state: one node per scan it placed, and what it carries from scan to
scan (keyframes, velocity, history). Used by `odometry.Odometry` only."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from odometry.history import OdometryResult
from odometry.registration import PreparedScan
from odometry.velocity import Velocity

FloatArray = NDArray[np.float64]


@dataclass
class ScanNode:
    """A scan: its pose at its reference time and the pose of its image frame (`image_pose`,
    world frame; see `PreparedScan`), which the registrations chain. A gap's (`gap`) poses are
    the constant-velocity prediction."""

    index: int
    pose: FloatArray
    image_pose: FloatArray
    scan: PreparedScan
    frames: int = 0
    gap: bool = False
    conversion_covariance: FloatArray = field(default_factory=lambda: np.zeros((3, 3)))
    """Covariance (own axes) that moving the image pose to the reference time adds to `pose`."""


@dataclass
class OdometryState:
    keyframe: ScanNode | None = None
    previous: ScanNode | None = None  # the previous scan (same fields as a keyframe)
    last_registered: ScanNode | None = None  # the last scan that was not a gap
    earlier_keyframes: list[ScanNode] = field(default_factory=list)  # most recent first
    velocity: Velocity | None = None
    history: list[OdometryResult] = field(default_factory=list)
    registrations: int = 0  # image registrations run for the scan being registered
