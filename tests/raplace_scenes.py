"""Helpers shared by the raplace tests: a synthetic world, scan rendering, the Oxford scans.

Imported by name from the tests (pytest puts this folder on sys.path in its default import mode).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from radar_slam.datasets import OxfordSequence
from raplace.preprocess import finish_disc, radial_taper
from raplace.warp import CartesianGrid


def oxford_scans(oxford_dir: Path) -> list[tuple[NDArray[np.uint8], NDArray[np.float64], float]]:
    """(polar (400, 3768) uint8, CCW azimuths (400,) [rad], range resolution [m]) of every scan
    of the partial Oxford sequence, in time order, read by the project's Oxford loader."""
    sequence = OxfordSequence(oxford_dir)
    frames = [sequence[i] for i in range(len(sequence))]
    return [(f.polar, f.azimuths_rad, f.range_resolution_m) for f in frames]


def synthetic_world(size_px: int, seed: int) -> NDArray[np.float32]:
    """A radar-like world image (size_px, size_px) float32: building outlines, poles, clutter.

    Same image convention as raplace.warp (+x up, +y left, origin at the centre).
    """
    rng = np.random.default_rng(seed)
    world = np.zeros((size_px, size_px), dtype=np.float32)
    n_buildings = size_px * size_px // 6000
    for _ in range(n_buildings):
        centre = rng.uniform(0, size_px, 2)
        half = rng.uniform(8, 40, 2)
        angle = rng.uniform(0, 180)
        box = cv2.boxPoints(((centre[0], centre[1]), (2 * half[0], 2 * half[1]), angle))
        cv2.polylines(world, [box.astype(np.int32)], True, float(rng.uniform(80, 200)), 2)
    for _ in range(size_px * size_px // 800):
        c = rng.integers(0, size_px, 2)
        cv2.circle(
            world, (int(c[0]), int(c[1])), int(rng.integers(1, 3)), float(rng.uniform(60, 255)), -1
        )
    world += rng.uniform(0, 20, world.shape).astype(np.float32)
    return cv2.GaussianBlur(world, (0, 0), 1.0)


def world_pixel_coords(
    grid: CartesianGrid, pose: tuple[float, float, float], world_size_px: int, world_cell_m: float
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """(col, row) world-image coordinates of every grid pixel of a sensor at `pose` (x, y, yaw)."""
    x, y = grid.pixel_centres()
    c, s = np.cos(pose[2]), np.sin(pose[2])
    xw = pose[0] + c * x - s * y
    yw = pose[1] + s * x + c * y
    rows = world_size_px / 2 - xw / world_cell_m - 0.5
    cols = world_size_px / 2 - yw / world_cell_m - 0.5
    return cols.astype(np.float32), rows.astype(np.float32)


def render_cart(
    world: NDArray[np.float32],
    world_cell_m: float,
    pose: tuple[float, float, float],
    cell_m: float,
    radius_m: float,
    taper_fraction: float = 0.1,
    subtract_mean: bool = True,
) -> NDArray[np.float32]:
    """Cartesian disc image of a sensor at `pose` in the world (finished like CartesianImager)."""
    grid = CartesianGrid.covering(radius_m, cell_m)
    cols, rows = world_pixel_coords(grid, pose, world.shape[0], world_cell_m)
    cart = cv2.remap(world, cols, rows, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    return finish_disc(cart, radial_taper(grid, radius_m, taper_fraction), subtract_mean)


def render_polar(
    world: NDArray[np.float32],
    world_cell_m: float,
    pose: tuple[float, float, float],
    n_azimuths: int = 400,
    n_bins: int = 1600,
    range_resolution_m: float = 0.1,
) -> tuple[NDArray[np.uint8], NDArray[np.float64], float]:
    """A polar scan (n_azimuths, n_bins) uint8 of a sensor at `pose`, Navtech-like CW sweep."""
    azimuths = -np.arange(n_azimuths) * (2.0 * np.pi / n_azimuths)
    ranges = (np.arange(n_bins) + 0.5) * range_resolution_m
    xs = ranges[None, :] * np.cos(azimuths)[:, None]
    ys = ranges[None, :] * np.sin(azimuths)[:, None]
    c, s = np.cos(pose[2]), np.sin(pose[2])
    xw = pose[0] + c * xs - s * ys
    yw = pose[1] + s * xs + c * ys
    size = world.shape[0]
    rows = (size / 2 - xw / world_cell_m - 0.5).astype(np.float32)
    cols = (size / 2 - yw / world_cell_m - 0.5).astype(np.float32)
    polar = cv2.remap(world, cols, rows, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    return np.clip(polar, 0, 255).astype(np.uint8), azimuths, range_resolution_m


def relative(pose_q: tuple[float, float, float], pose_m: tuple[float, float, float]) -> NDArray:
    """T_q_m = T_w_q^-1 T_w_m as (dx, dy, dyaw), dyaw wrapped to (-pi, pi]."""
    dx, dy = pose_m[0] - pose_q[0], pose_m[1] - pose_q[1]
    c, s = np.cos(pose_q[2]), np.sin(pose_q[2])
    dyaw = np.mod(pose_m[2] - pose_q[2] + np.pi, 2 * np.pi) - np.pi
    return np.array([c * dx + s * dy, -s * dx + c * dy, dyaw])


def angle_error(a: float, b: float) -> float:
    """|a - b| wrapped to [0, pi] [rad]."""
    return abs(float(np.mod(a - b + np.pi, 2 * np.pi) - np.pi))
