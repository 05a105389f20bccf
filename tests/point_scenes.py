"""Exactly rendered point-target scans: known rotations and motions without radar physics.

Each polar row (azimuth) sees every target from that row's own sensor pose, with a Gaussian
beam in azimuth and a Gaussian point spread in range, so a scan of a rotated, translated or
moving sensor is exact (no resampling of another scan, no fixed-point approximation of which
azimuth sees a point). Used by the rotation-bias tests.

Imported by name from the tests (pytest puts this folder on sys.path in its default import mode).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from odometry.preprocess import motion_from_twist
from radar_slam.datasets.frame import RadarFrame
from radar_slam.datasets.mulran import column_azimuths_rad
from radar_slam.datasets.sweep import uniform_azimuth_times_ns
from raplace import se2

N_AZIMUTHS = 400
SWEEP_NS = 250_000_000
BIN_M = 0.2
N_BINS = 500
BEAM_SIGMA_DEG = 0.76
"""Gaussian sigma of the two-way beam [deg] (1.8 deg at -3 dB, the CIR204-H's)."""
RANGE_SIGMA_BINS = 1.2
MIN_WEIGHT = 1e-4
INTENSITY_SCALE = 120.0


def point_scene(
    rng: np.random.Generator, n_points: int = 600, n_walls: int = 25
) -> NDArray[np.float64]:
    """(N, 3) targets (x, y [m], amplitude): scattered points 6-95 m away and short walls
    (lines of points 0.4 m apart) in random directions, in the world frame."""
    r = rng.uniform(6.0, 95.0, n_points)
    b = rng.uniform(-np.pi, np.pi, n_points)
    parts = [np.c_[r * np.cos(b), r * np.sin(b), rng.uniform(0.3, 1.0, n_points)]]
    for _ in range(n_walls):
        centre = rng.uniform(-70.0, 70.0, 2)
        angle = rng.uniform(0.0, np.pi)
        along = np.arange(0.0, rng.uniform(5.0, 30.0), 0.4)
        xy = centre[None, :] + along[:, None] * np.array([np.cos(angle), np.sin(angle)])[None, :]
        parts.append(np.c_[xy, np.full(len(along), 0.25 * rng.uniform(0.5, 1.0))])
    return np.concatenate(parts)


def static_poses(pose: NDArray[np.float64] | list[float]) -> NDArray[np.float64]:
    """(N_AZIMUTHS, 3) the same sensor pose for every row (no motion during the sweep)."""
    return np.broadcast_to(np.asarray(pose, dtype=np.float64), (N_AZIMUTHS, 3)).copy()


def moving_poses(
    end_pose: NDArray[np.float64] | list[float], twist: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(N_AZIMUTHS, 3) the sensor pose of every row of a sweep ending at `end_pose` (world),
    the sensor moving at the constant body `twist` (vx, vy [m/s], yaw rate [rad/s]); row j is
    acquired (N - 1 - j) sweep / N before the end (the MulRan convention of the loaders)."""
    period_s = SWEEP_NS / 1e9 / N_AZIMUTHS
    tau = (np.arange(N_AZIMUTHS) - (N_AZIMUTHS - 1)) * period_s
    end = np.asarray(end_pose, dtype=np.float64)
    return np.array([se2.compose(end, motion_from_twist(twist, t)) for t in tau])


def render_polar(
    targets: NDArray[np.float64],
    row_poses: NDArray[np.float64],
    n_bins: int = N_BINS,
    bin_m: float = BIN_M,
    azimuths: NDArray[np.float64] | None = None,
) -> NDArray[np.uint8]:
    """(N_AZIMUTHS, n_bins) uint8 scan of `targets` ((N, 3), world) with row i seen from
    `row_poses[i]` (world) along azimuth i (default: MulRan's, a clockwise sweep); bin k is
    centred at (k + 0.5) * bin_m [m] (the range spread is RANGE_SIGMA_BINS * BIN_M at any bin
    size)."""
    azimuths = column_azimuths_rad(N_AZIMUTHS) if azimuths is None else azimuths
    c, s = np.cos(row_poses[:, 2:3]), np.sin(row_poses[:, 2:3])
    dx = targets[None, :, 0] - row_poses[:, 0:1]
    dy = targets[None, :, 1] - row_poses[:, 1:2]
    local_x, local_y = c * dx + s * dy, -s * dx + c * dy
    off_beam = se2.wrap_angle(np.arctan2(local_y, local_x) - azimuths[:, None])
    weight = np.exp(-0.5 * (off_beam / np.radians(BEAM_SIGMA_DEG)) ** 2) * targets[None, :, 2]
    rows, cols = np.nonzero(weight > MIN_WEIGHT)
    centre = np.hypot(local_x, local_y)[rows, cols] / bin_m - 0.5
    sigma = RANGE_SIGMA_BINS * BIN_M / bin_m
    reach = round(3.5 * sigma)
    image = np.zeros((N_AZIMUTHS, n_bins))
    for offset in range(-reach, reach + 1):
        k = np.rint(centre).astype(np.int64) + offset
        ok = (k >= 0) & (k < n_bins)
        spread = np.exp(-0.5 * ((k[ok] - centre[ok]) / sigma) ** 2)
        np.add.at(image, (rows[ok], k[ok]), weight[rows[ok], cols[ok]] * spread)
    return np.clip(image * INTENSITY_SCALE, 0, 255).astype(np.uint8)


def scan_frame(
    polar: NDArray[np.uint8], end_ns: int, with_times: bool, bin_m: float = BIN_M
) -> RadarFrame:
    """A `RadarFrame` of a rendered scan (bins of `bin_m` [m]) ending at `end_ns` (its reference
    time), with uniform MulRan azimuth times when `with_times`."""
    times = uniform_azimuth_times_ns(end_ns, SWEEP_NS, N_AZIMUTHS) if with_times else None
    return RadarFrame(
        timestamp_ns=end_ns,
        polar=polar,
        azimuths_rad=column_azimuths_rad(N_AZIMUTHS),
        range_resolution_m=bin_m,
        sensor="point-targets",
        azimuth_times_ns=times,
    )
