"""The radar scan, its conditioning, its windowed Cartesian images de-skewed by folding a constant
velocity into the backward warp (range exact, bearing to second order: under 1 cm beyond 10 m at
10 m/s) and the SE(2) twists (docs/method.md)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from odometry import OdometryError
from odometry.config import PreprocessConfig
from raplace.se2 import wrap_angle
from raplace.units import NS_PER_S
from raplace.warp import CartesianGrid, remap, remap_wrapped

TWO_PI = 2.0 * np.pi
UNIFORM_SWEEP_TOLERANCE = 0.05
"""Rows are resampled when an azimuth is off the fitted uniform sweep by this fraction of a step."""
MIN_AZIMUTHS = 8
MAX_UINT16_SUM_FACTOR = 257
"""Up to this many uint8 bins add up in a uint16."""
SMALL_ANGLE_RAD = 1e-6
MIN_RANGE_SQUARED_M2 = 1e-4
"""Guards the bearing correction's denominator at the sensor itself (that pixel is zeroed)."""

FloatImage = NDArray[np.float32]


@runtime_checkable
class Scan(Protocol):
    """One radar sweep: any object with these read-only properties (frozen dataclasses match)."""

    @property
    def timestamp_ns(self) -> int: ...  # reference time [ns]: the time its pose refers to
    @property
    def polar(self) -> NDArray[np.uint8]: ...  # (n_azimuths, n_bins) one row per azimuth
    # (n_azimuths,) [rad] CCW from +x (forward) in the sensor frame x-forward, y-left; bin k of
    # row i lies at range (k + 0.5) * range_resolution_m along azimuths_rad[i].
    @property
    def azimuths_rad(self) -> NDArray[np.float64]: ...
    @property
    def range_resolution_m(self) -> float: ...  # size of one range bin [m]
    @property
    def sensor(self) -> str: ...  # sensor / dataset name (informational)
    # (n_azimuths,) acquisition time of each row [ns], or None (then no de-skew).
    @property
    def azimuth_times_ns(self) -> NDArray[np.int64] | None: ...


@dataclass(frozen=True)
class RadarFrame:
    """One radar sweep: the concrete `Scan` (see `Scan` for the attributes)."""

    timestamp_ns: int
    polar: NDArray[np.uint8]
    azimuths_rad: NDArray[np.float64]
    range_resolution_m: float
    sensor: str
    azimuth_times_ns: NDArray[np.int64] | None = None

    @property
    def n_azimuths(self) -> int:
        return int(self.polar.shape[0])

    @property
    def n_bins(self) -> int:
        return int(self.polar.shape[1])

    @property
    def max_range_m(self) -> float:
        return self.n_bins * self.range_resolution_m


@dataclass(frozen=True)
class RowTiming:
    """Row i was measured `first_row_s + i * row_period_s` [s] after the scan's reference time."""

    first_row_s: float
    row_period_s: float


@dataclass(frozen=True)
class PolarScan:
    """A conditioned polar scan on a uniform azimuth sweep."""

    wrapped_image: FloatImage  # `image` with row 0 repeated at the end (`raplace.warp`'s seam)
    first_azimuth_rad: float  # azimuth of row 0 [rad]
    azimuth_step_rad: float  # signed step between rows [rad]; n_azimuths * |step| = 2 pi
    bin_size_m: float  # range bin size [m]
    timestamp_ns: int  # the scan's reference time [ns]
    timing: RowTiming | None  # None when the scan has no azimuth times

    @property
    def image(self) -> FloatImage:
        """(n_azimuths, n_bins) float32 non-negative intensities: row i at azimuth
        `first_azimuth_rad + i * azimuth_step_rad` (CCW from +x), bin k at (k + 0.5) bin_size_m."""
        return self.wrapped_image[:-1]

    @property
    def n_azimuths(self) -> int:
        return int(self.wrapped_image.shape[0] - 1)

    @property
    def mid_sweep_s(self) -> float | None:
        """Mean acquisition time of the rows after the reference time [s], or None."""
        if self.timing is None:
            return None
        return self.timing.first_row_s + 0.5 * (self.n_azimuths - 1) * self.timing.row_period_s


@dataclass(frozen=True)
class CartesianLevel:
    """Per-pixel (x, y, range [m], bearing [rad] CCW from +x) from the sensor at the centre of a
    `raplace.warp` grid of `cell_m` [m] pixels, and its window; arrays (size_px, size_px)."""

    cell_m: float
    x_m: FloatImage
    y_m: FloatImage
    range_m: FloatImage
    bearing_rad: FloatImage
    window: FloatImage


TAPER_FRACTION = 0.3
"""The radial window falls from 1 to 0 over this outer fraction of the inscribed radius (keeps the
image border out of the spectrum and most of the scene in)."""


@functools.lru_cache(maxsize=8)
def cartesian_level(cell_m: float, size_px: int) -> CartesianLevel:
    """The (cached) level of `size_px` (even) pixels of `cell_m` [m]; a radial Tukey window."""
    grid = CartesianGrid(cell_m=cell_m, size_px=size_px)
    x, y = grid.pixel_centres()
    rng = np.hypot(x, y)
    outer = grid.half_extent_m
    inner = (1.0 - TAPER_FRACTION) * outer
    fall = np.clip((rng - inner) / (outer - inner), 0.0, 1.0)
    window = 0.5 * (1.0 + np.cos(np.pi * fall))
    arrays = (x, y, rng, np.arctan2(y, x), window)
    return CartesianLevel(cell_m, *(a.astype(np.float32) for a in arrays))


def _uniform_sweep(azimuths_rad: NDArray[np.float64]) -> tuple[float, float, NDArray[np.float64]]:
    """(first azimuth [rad], signed step [rad], fractional source row of each uniform row) of a
    uniform full-turn sweep fitted to the azimuths (rows 0..n-1 when already uniform)."""
    az = np.unwrap(np.asarray(azimuths_rad, dtype=np.float64))
    n = len(az)
    direction = 1.0 if az[-1] > az[0] else -1.0
    step = direction * TWO_PI / n
    index = np.arange(n, dtype=np.float64)
    first = float(np.mean(az - index * step))  # least-squares offset for the full-turn step
    residual = np.abs(az - (first + index * step))
    if residual.max() <= UNIFORM_SWEEP_TOLERANCE * abs(step):
        return first, step, index
    # Non-uniform (or not a full turn): sample the rows at uniform angles, periodically.
    first = float(az[0])
    offsets = direction * (az - az[0])
    if offsets.max() >= TWO_PI or np.any(np.diff(offsets) <= 0):
        raise OdometryError("azimuths must sweep monotonically through less than one full turn")
    target = index * abs(step)
    ext_offsets = np.append(offsets, TWO_PI)
    ext_rows = np.append(index, float(n))  # row n is row 0 again (wrapped below)
    return first, step, np.interp(target, ext_offsets, ext_rows)


def _row_timing(scan: Scan, source_rows: NDArray[np.float64]) -> RowTiming | None:
    """Least-squares linear time model of the uniform rows (None without azimuth times)."""
    times = scan.azimuth_times_ns
    if times is None:
        return None
    t = (np.asarray(times, dtype=np.int64) - int(scan.timestamp_ns)).astype(np.float64) / NS_PER_S
    if t.shape != (len(source_rows),):
        raise OdometryError(
            f"azimuth_times_ns must have one entry per azimuth ({len(source_rows)}), got {t.shape}"
        )
    index = np.arange(len(t), dtype=np.float64)
    centred = index - index.mean()  # the straight line t = first + period * index, closed form
    period = float(np.dot(centred, t - t.mean()) / np.dot(centred, centred))
    first = float(t.mean() - period * index.mean())
    # Times of the uniform rows follow from where they were sampled in the source rows.
    first_uniform = first + period * source_rows[0]
    return RowTiming(first_row_s=float(first_uniform), row_period_s=float(period))


def preprocess_polar(scan: Scan, cfg: PreprocessConfig) -> PolarScan:
    """The scan on uniform azimuths, bins of about `cfg.bin_size_m`; OdometryError if malformed."""
    polar = np.asarray(scan.polar)
    az = np.asarray(scan.azimuths_rad, dtype=np.float64)
    bad = polar.ndim != 2 or az.shape != polar.shape[:1] or polar.dtype != np.uint8
    if bad or len(az) < MIN_AZIMUTHS or scan.range_resolution_m <= 0:
        raise OdometryError(
            f"a scan needs a uint8 polar (n_azimuths >= {MIN_AZIMUTHS}, n_bins), one azimuth per "
            f"row and a positive range resolution; got polar {polar.shape} {polar.dtype}, "
            f"azimuths {az.shape}, range resolution {scan.range_resolution_m}"
        )
    first, step, source_rows = _uniform_sweep(az)
    timing = _row_timing(scan, source_rows)

    res = float(scan.range_resolution_m)
    factor = max(1, int(round(cfg.bin_size_m / res)))
    n_bins = min(polar.shape[1], int(np.ceil(cfg.max_range_m / res))) // factor * factor
    if n_bins < factor:
        raise OdometryError(f"scan has {polar.shape[1]} bins: too few for max_range_m")
    # Exact integer sums of `factor` adjacent bins (faster than a float area resize, which their
    # means equal); the means are sums * scale, made in `_condition_rows` (their median by
    # counting); resampled rows need the float means.
    dtype = np.uint16 if factor <= MAX_UINT16_SUM_FACTOR else np.uint32
    sums = polar[:, :n_bins:factor].astype(dtype)
    for k in range(1, factor):
        sums += polar[:, k:n_bins:factor]
    source: NDArray = sums
    scale = np.float32(1.0 / factor)
    mid = polar.shape[0] // 2
    ring = np.zeros(sums.shape[1], dtype=np.float32)
    if not np.array_equal(source_rows, np.arange(len(source_rows))):
        means = np.multiply(sums, scale, dtype=np.float32)
        rows = np.broadcast_to(source_rows.astype(np.float32)[:, None], means.shape)
        cols = np.broadcast_to(np.arange(means.shape[1], dtype=np.float32), means.shape)
        source = remap(means, np.ascontiguousarray(cols), np.ascontiguousarray(rows))
        scale = np.float32(1.0)
        if cfg.ring_noise_removal:
            ring = np.partition(source, mid, axis=0)[mid]
    elif cfg.ring_noise_removal:
        levels = int(np.iinfo(np.uint8).max) * factor + 1
        # The mean map is monotonic: the median of the means is the mean of the median sum.
        ring = np.multiply(_column_order_statistic(sums, mid, levels), scale, dtype=np.float32)
    bin_size = factor * res
    near = min(source.shape[1], int(np.ceil(cfg.min_range_m / bin_size)))
    wrapped = np.empty((source.shape[0] + 1, source.shape[1]), dtype=np.float32)
    _condition_rows(source, scale, ring, near, float(cfg.noise_floor_sigmas), wrapped[:-1])
    wrapped[-1] = wrapped[0]
    return PolarScan(wrapped, first, step, bin_size, int(scan.timestamp_ns), timing)


@numba.njit(nogil=True, cache=True, fastmath={"reassoc", "contract"})  # vectorised sums
def _condition_rows(source, scale, ring, near, floor_sigmas, out):  # type: ignore[no-untyped-def]  # fmt: skip
    """out = source * scale - ring per row, minus (when `floor_sigmas` >= 0) the row's mean +
    floor_sigmas standard deviations of its bins from `near` on; clipped at 0, bins before
    `near` zeroed (float32)."""
    n_rows, n_bins = out.shape
    count = n_bins - near
    for i in range(n_rows):
        for j in range(near):
            out[i, j] = 0.0
        total = total_sq = 0.0
        for j in range(near, n_bins):
            value = np.float32(source[i, j] * scale) - ring[j]
            out[i, j] = value
            total += value
            total_sq += np.float64(value) * value
        floor = np.float32(0.0)
        if floor_sigmas >= 0.0 and count > 0:
            mean = total / count
            level = mean
            if floor_sigmas > 0.0:
                level += floor_sigmas * math.sqrt(max(total_sq / count - mean * mean, 0.0))
            floor = np.float32(level)
        for j in range(near, n_bins):
            out[i, j] = max(out[i, j] - floor, np.float32(0.0))


@numba.njit(nogil=True, cache=True)
def _column_order_statistic(values, rank, levels):  # type: ignore[no-untyped-def]  # fmt: skip
    """`np.partition(values, rank, axis=0)[rank]` by counting, for values below `levels`."""
    n_rows, n_cols = values.shape
    out = np.empty_like(values[0])
    counts = np.zeros(levels, dtype=np.int32)
    for j in range(n_cols):
        counts[:] = 0
        for i in range(n_rows):
            counts[values[i, j]] += 1
        seen = 0
        for v in range(levels):
            seen += counts[v]
            if seen > rank:
                out[j] = v
                break
    return out


def sample_scan(
    polar: PolarScan,
    x_m: FloatImage,
    y_m: FloatImage,
    range_m: FloatImage,
    bearing_rad: FloatImage,
    rotation_rad: float = 0.0,
    twist: NDArray[np.float64] | None = None,
    time_offset_s: float = 0.0,
) -> FloatImage:
    """(H, W) float32 intensities (bilinear, 0 beyond range) at points (H, W) [m, rad] of the
    sensor frame `time_offset_s` [s] after the reference time, turned by `rotation_rad` (CCW),
    de-skewed with `twist` (3,) [m/s, m/s, rad/s] when given and the scan has azimuth times."""
    timing = polar.timing
    times = None if timing is None else (timing.first_row_s - time_offset_s, timing.row_period_s)
    sweep = (polar.first_azimuth_rad, polar.azimuth_step_rad, polar.n_azimuths, polar.bin_size_m)
    points = (x_m, y_m, range_m, bearing_rad)
    bins, rows = sampling_maps(*points, *sweep, rotation_rad, twist, times)
    return remap_wrapped(polar.wrapped_image, bins, rows)


def render_cartesian(
    polar: PolarScan,
    level: CartesianLevel,
    rotation_rad: float = 0.0,
    twist: NDArray[np.float64] | None = None,
    time_offset_s: float = 0.0,
) -> FloatImage:
    """The level's windowed image (size_px, size_px) float32 of a scan (as `sample_scan`)."""
    points = (level.x_m, level.y_m, level.range_m, level.bearing_rad)
    image = sample_scan(polar, *points, rotation_rad, twist, time_offset_s)
    image *= level.window
    return image


def sampling_maps(
    x_m: FloatImage,
    y_m: FloatImage,
    range_m: FloatImage,
    bearing_rad: FloatImage,
    first_azimuth_rad: float,
    azimuth_step_rad: float,
    n_azimuths: int,
    bin_size_m: float,
    rotation_rad: float = 0.0,
    twist: NDArray[np.float64] | None = None,
    timing: tuple[float, float] | None = None,
) -> tuple[FloatImage, FloatImage]:
    """(bins, rows) float32 maps (H, W) for `raplace.warp.remap` (rows in [0, n]) of pixels at
    (x, y, range [m], bearing [rad] CCW from +x) (H, W) of a scan of `n_azimuths` rows from
    `first_azimuth_rad` in signed steps [rad] and bins of `bin_size_m`, turned by `rotation_rad`
    (bearing b shows the scan's b - rotation_rad), de-skewed at `twist` (3,) [m/s, m/s, rad/s]
    given `timing` (row 0's time and the row period [s]); no de-skew when either is None."""
    deskew = False
    t0 = t1 = wx = wy = yaw_rate = 0.0
    if twist is not None and timing is not None and np.any(np.asarray(twist) != 0.0):
        deskew = True
        t0, t1 = timing
        vx, vy, yaw_rate = (float(v) for v in np.asarray(twist, dtype=np.float64))
        c, s = np.cos(rotation_rad), np.sin(rotation_rad)
        wx, wy = c * vx - s * vy, s * vx + c * vy  # velocity in the rendered (rotated) frame
    bins, rows = np.empty((2, *np.shape(x_m)), dtype=np.float32)
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
