"""Motion-distortion correction of a spinning radar under constant velocity, folded into the
backward warp (docs/method.md: range exact for the displacement, bearing to second order, under a
centimetre beyond 10 m at 10 m/s), and the SE(2) exponential and logarithm of body twists."""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from raplace.se2 import wrap_angle

FloatImage = NDArray[np.float32]
SMALL_ANGLE_RAD = 1e-6
MIN_RANGE_SQUARED_M2 = 1e-4
"""Guards the bearing correction's denominator at the sensor itself (that pixel is zeroed)."""


def sampling_maps(
    x_m: FloatImage,
    y_m: FloatImage,
    range_m: FloatImage,
    bearing_rad: FloatImage,
    *,
    first_azimuth_rad: float,
    azimuth_step_rad: float,
    n_azimuths: int,
    bin_size_m: float,
    rotation_rad: float = 0.0,
    twist: NDArray[np.float64] | None = None,
    timing: tuple[float, float] | None = None,
) -> tuple[FloatImage, FloatImage]:
    """(bins, rows) float32 maps (H, W) for `raplace.warp.remap` (rows in [0, n]) of output
    pixels at (x, y, range [m], bearing [rad] CCW from +x) (H, W), for a scan of `n_azimuths`
    rows from `first_azimuth_rad` in signed steps [rad] (one full turn) and bins of
    `bin_size_m` (bin k centred at (k + 0.5) * bin_size_m), rendered turned by `rotation_rad`
    (output bearing b shows the scan's b - rotation_rad) and de-skewed with `twist` (3,) (vx, vy
    [m/s], yaw rate [rad/s]) given `timing` (time of row 0, row period [s] after the reference
    time); no de-skew when either is None."""
    deskew = False
    t0 = t1 = wx = wy = yaw_rate = 0.0
    if twist is not None and timing is not None and np.any(np.asarray(twist) != 0.0):
        deskew = True
        t0, t1 = timing
        vx, vy, yaw_rate = (float(v) for v in np.asarray(twist, dtype=np.float64))
        c, s = np.cos(rotation_rad), np.sin(rotation_rad)
        wx, wy = c * vx - s * vy, s * vx + c * vy  # velocity in the rendered (rotated) frame
    shape = np.shape(x_m)
    bins = np.empty(shape, dtype=np.float32)
    rows = np.empty(shape, dtype=np.float32)
    f32 = np.float32
    x, y, r, b = (
        np.ascontiguousarray(a, dtype=np.float32) for a in (x_m, y_m, range_m, bearing_rad)
    )
    _maps_kernel(
        x, y, r, b, f32(1.0 / azimuth_step_rad), f32(wrap_angle(first_azimuth_rad + rotation_rad)),
        f32(n_azimuths), f32(1.0 / n_azimuths), f32(1.0 / bin_size_m), deskew, f32(t0), f32(t1),
        f32(wx), f32(wy), f32(wx * wx + wy * wy), f32(yaw_rate), bins, rows,
    )  # fmt: skip
    return bins, rows


@numba.njit(nogil=True, cache=True)
def _maps_kernel(
    x_m, y_m, range_m, bearing_rad, scale, offset, n, inv_n, inv_bin, deskew,
    t0, t1, wx, wy, w2, yaw_rate, bins, rows,
):  # type: ignore[no-untyped-def]  # fmt: skip
    """The maps of `sampling_maps` pixel by pixel, in float32. Rows are wrapped by floor (modulo
    is slow on float32); -0.0 or exactly n are valid rows of the seam-wrapped image."""
    half, two, zero = np.float32(0.5), np.float32(2.0), np.float32(0.0)
    min_r2 = np.float32(MIN_RANGE_SQUARED_M2)
    for i in range(x_m.shape[0]):
        for j in range(x_m.shape[1]):
            row = (bearing_rad[i, j] - offset) * scale
            row = row - np.floor(row * inv_n) * n
            r = range_m[i, j]
            if not deskew:
                bins[i, j] = r * inv_bin - half
                rows[i, j] = row
                continue
            x, y = x_m[i, j], y_m[i, j]
            tau = row * t1 + t0
            along = x * wx + y * wy
            across = x * wy - y * wx
            r2 = r * r
            # q = (x, y), w = (wx, wy): |q - tau w|^2 = r^2 - tau (2 q.w - tau |w|^2).
            moved = (tau * w2 - two * along) * tau + r2
            if not moved >= zero:
                moved = zero
            bins[i, j] = np.sqrt(moved) * inv_bin - half
            # Bearing of q - tau w ~ bearing - tau (q x w) / (r^2 - tau q.w); then the turn
            # during tau.
            denominator = r2 - along * tau
            if not denominator >= min_r2:
                denominator = min_r2
            moved_row = row - (across / denominator + yaw_rate) * tau * scale
            rows[i, j] = moved_row - np.floor(moved_row * inv_n) * n


def twist_from_motion(motion: ArrayLike, dt_s: float) -> NDArray[np.float64]:
    """The constant body twist (vx, vy [m/s], yaw rate [rad/s]) that moves by `motion` (dx, dy,
    dyaw: the end pose in the start pose's frame) in `dt_s` [s] (SE(2) logarithm: exact arcs)."""
    dx, dy, dyaw = (float(v) for v in np.asarray(motion, dtype=np.float64))
    if dt_s <= 0:
        raise ValueError(f"dt_s must be positive, got {dt_s}")
    if abs(dyaw) < SMALL_ANGLE_RAD:
        return np.array([dx, dy, dyaw]) / dt_s
    half = 0.5 * dyaw
    a = half / np.tan(half)  # V^-1 = [[a, half], [-half, a]]
    return np.array([a * dx + half * dy, -half * dx + a * dy, dyaw]) / dt_s


def motion_from_twist(twist: ArrayLike, dt_s: float) -> NDArray[np.float64]:
    """The motion (dx, dy, dyaw) after `dt_s` seconds at a constant body twist (SE(2) exp)."""
    vx, vy, yaw_rate = (float(v) * dt_s for v in np.asarray(twist, dtype=np.float64))
    if abs(yaw_rate) < SMALL_ANGLE_RAD:
        return np.array([vx, vy, yaw_rate])
    sn, cs = np.sin(yaw_rate), np.cos(yaw_rate)
    a, b = sn / yaw_rate, (1.0 - cs) / yaw_rate
    return np.array([a * vx - b * vy, b * vx + a * vy, yaw_rate])
