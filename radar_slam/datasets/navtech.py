"""Navtech sensor geometry and dataset mounting constants shared by loaders and the simulator."""

from __future__ import annotations

import numpy as np

ENCODER_TICKS_PER_REV = 5600
"""Navtech encoder counts per revolution (both CIR204-H and CTS350-X)."""

SCAN_RATE_HZ = 4.0
"""Rotation rate of both sensors [Hz]."""

# MulRan: Navtech CIR204-H
MULRAN_N_AZIMUTHS = 400
MULRAN_N_BINS = 3360
MULRAN_RANGE_RESOLUTION_M = 0.05952
MULRAN_FIRST_ENCODER = 9
"""Encoder count of polar column 0; column j is at 9 + 14 j (clockwise seen from above)."""
MULRAN_ENCODER_STEP = 14
MULRAN_T_BASE_RADAR = np.array([1.50, -0.04, np.deg2rad(0.9)])
"""SE(2) pose of the radar in the vehicle base frame (x-forward, y-left): 1.50 m ahead,
0.04 m right, yaw +0.9 deg. `global_pose.csv` holds the base pose;
T_world_radar = T_world_base * MULRAN_T_BASE_RADAR."""

# Oxford Radar RobotCar: Navtech CTS350-X
OXFORD_N_AZIMUTHS = 400
OXFORD_N_BINS = 3768
OXFORD_RANGE_RESOLUTION_M = 0.0438
"""Dataset documentation value; the official SDK hard-codes 0.0432 (keep it configurable)."""
OXFORD_HEADER_BYTES = 11
"""Per-azimuth header: int64 timestamp [us], uint16 encoder count, uint8 valid flag."""


def encoder_to_azimuth_ccw(encoder: np.ndarray) -> np.ndarray:
    """Convert Navtech encoder counts (clockwise from forward) to CCW azimuths [rad]."""
    return -np.asarray(encoder, dtype=np.float64) * (2.0 * np.pi / ENCODER_TICKS_PER_REV)
