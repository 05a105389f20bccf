"""Render one polar radar scan of a `World` (vectorised; no loops over columns or scatterers).

Signal model: every return is a complex amplitude placed in its (column, range bin) cell of a
complex polar field, spread over neighbouring columns by the beam pattern; complex receiver
noise is added; the field is convolved along range with the point-spread of the windowed FFT;
the output is the log-compressed power. Interference of returns sharing a cell (facades
sampled every 40 cm, vegetation) gives speckle as in a real coherent radar.

Speed: the complex field is rendered at half the range resolution (RANGE_DECIMATION); the
point-spread (sigma 5.2 bins) makes it band-limited, so the log image is resampled to the full
resolution before the output quantisation without visible loss.

Power bookkeeping: the field is kept in "raw" units where the uniform uint8 noise used as a
fast Gaussian source (it becomes Gaussian after the point-spread) has unit scale; all
conversions to counts (noise floor, ring bands, near-range leakage) are folded into one per-bin
offset applied in the log domain, and returns are pre-divided by the same per-bin factor.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from radar_slam.sim.physics import (
    LUT_STEPS_PER_LEVEL,
    OUTPUT_LEVELS_PER_DECADE,
    Glint,
    PhysicsConfig,
    beam_offsets,
    beam_sigma_columns,
    blanked_bins,
    extra_noise_profile,
    log_path_gain,
    output_lut,
    path_gain,
    range_psf_kernel,
    sidelobe_taps,
)
from radar_slam.sim.route import Trajectory
from radar_slam.sim.scatterers import Occluders, World
from radar_slam.sim.sensor import SensorConfig
from raplace import NS_PER_S

F32 = NDArray[np.float32]
UNIFORM_U8_MEAN = 127.5
UNIFORM_U8_VARIANCE = (256.0**2 - 1.0) / 12.0
"""Variance of a uniform byte; the raw complex noise power is twice this after the PSF."""
CULL_MARGIN_M = 10.0
"""Extra radius around the maximum range when culling scatterers (sensor motion) [m]."""
MIN_RANGE_M = 0.5
"""Returns closer than this are dropped (inside the radome / the vehicle) [m]."""
PROJECTION_ITERATIONS = 1
"""Fixed-point refinements matching each scatterer to the column (and pose) that sees it; one
leaves < 3 cm of pose error even at 5 m range and 15 m/s."""
STREAK_MIN_GAIN = 1.01
"""Columns whose noise gain from clipping is below this are left alone."""
RANGE_DECIMATION = 2
"""The complex field is rendered with bins this many times coarser than the output."""
MIN_VISIBLE_POWER = 0.2
"""Scatterers weaker than this at their range (before speckle) are skipped [counts]; the
noise floor is 2.2 counts."""
GOLDEN_FRACTION = 0.6180339887498949
"""Scatterer index -> glint phase: the fractional parts of multiples of it are well spread."""
TRAFFIC_MARGIN_M = 30.0
"""Moving vehicles this far beyond the maximum range are still considered [m]."""
VEHICLE_SCATTERER_HEIGHT_M = 0.8
"""Height of the scatterers of moving vehicles [m]."""


@dataclass(frozen=True)
class RenderTables:
    """Per-sensor constants of the renderer (built once by `make_tables`).

    The complex field has `n_field_bins` bins of `field_bin_m` (RANGE_DECIMATION output bins).

    Attributes:
        sensor, physics: configuration.
        n_field_bins: range bins of the internal complex field.
        field_bin_m: size of an internal bin [m].
        psf: (L,) amplitude point-spread along range in internal bins (unit energy).
        beam_sigma: beam pattern sigma [columns].
        offsets: main-lobe tap column offsets.
        sidelobe_offsets, sidelobe_gains: sidelobe column offsets and amplitude gains.
        bin_amplitude_scale: (n_field_bins,) raw amplitude per sqrt(count) of a return.
        log_offset: (n_field_bins,) offset added to ln(raw amplitude) before output scaling.
        lut: (256,) output lookup (level gaps, saturation).
        n_blank: leading output bins set to the blank level.
        azimuths_ccw: (n_azimuths,) column azimuths [rad].
        column_offsets_s: (n_azimuths,) column times relative to the scan end [s].
    """

    sensor: SensorConfig
    physics: PhysicsConfig
    n_field_bins: int
    field_bin_m: float
    psf: F32
    beam_sigma: float
    offsets: NDArray[np.int64]
    sidelobe_offsets: NDArray[np.int64]
    sidelobe_gains: F32
    bin_amplitude_scale: F32
    log_offset: F32
    lut: NDArray[np.uint8]
    n_blank: int
    azimuths_ccw: NDArray[np.float64]
    column_offsets_s: NDArray[np.float64]


def make_tables(sensor: SensorConfig, physics: PhysicsConfig) -> RenderTables:
    """Precompute everything that depends only on the sensor and the physics settings."""
    n_field = -(-sensor.n_bins // RANGE_DECIMATION)
    psf_cfg = replace(physics.range_psf, sigma_bins=physics.range_psf.sigma_bins / RANGE_DECIMATION)
    psf = range_psf_kernel(psf_cfg)
    floor = physics.noise_floor.mean_power if physics.noise_floor.enabled else 1.0
    full = extra_noise_profile(sensor, physics)
    padded = np.pad(full, (0, n_field * RANGE_DECIMATION - len(full)), mode="edge")
    profile = padded.reshape(n_field, RANGE_DECIMATION).mean(axis=1)
    raw_noise_power = 2.0 * UNIFORM_U8_VARIANCE
    # counts = raw_power * floor * profile / raw_noise_power; a return of P counts peaks at
    # (a * psf_max)^2 raw power after the PSF, hence a = sqrt(P * raw / (floor * profile)) / max.
    amp = np.sqrt(raw_noise_power / (floor * profile)) / float(psf.max())
    # level = 20 log10(counts) = (40 / ln 10) * [ln(amplitude) + 0.5 ln(floor * profile / raw)]
    log_offset = 0.5 * np.log(floor * profile / raw_noise_power)
    return RenderTables(
        sensor=sensor,
        physics=physics,
        n_field_bins=n_field,
        field_bin_m=sensor.range_resolution_m * RANGE_DECIMATION,
        psf=psf,
        beam_sigma=beam_sigma_columns(sensor),
        offsets=beam_offsets(physics.beam_pattern),
        sidelobe_offsets=sidelobe_taps(physics.beam_pattern)[0],
        sidelobe_gains=sidelobe_taps(physics.beam_pattern)[1],
        bin_amplitude_scale=amp.astype(np.float32),
        log_offset=log_offset.astype(np.float32),
        lut=output_lut(physics),
        n_blank=blanked_bins(sensor, physics.near_range),
        azimuths_ccw=sensor.azimuths_ccw_rad(),
        column_offsets_s=sensor.azimuth_offsets_ns().astype(np.float64) / NS_PER_S,
    )


@dataclass(frozen=True)
class Returns:
    """Returns to be written into the field (N,): fractional column, range [m], power [counts],
    phase [rad]."""

    column: F32
    range_m: F32
    power: F32
    phase: F32


def project(
    x: F32, y: F32, column_poses: NDArray[np.float64], tables: RenderTables
) -> tuple[F32, NDArray[np.int64], F32, F32, F32]:
    """Match world points to the column that sees them, using that column's sensor pose.

    Args:
        x, y: (N,) world positions [m].
        column_poses: (n_azimuths, 3) sensor pose of every column.

    Returns:
        column (N,) fractional column, nearest (N,) nearest column index, range (N,) [m], and
        (dx, dy) (N,) world-frame offsets from that column's sensor position [m].
    """
    sensor = tables.sensor
    n = sensor.n_azimuths
    px, py, pyaw = (np.ascontiguousarray(column_poses[:, k], dtype=np.float32) for k in range(3))
    mid = n // 2
    dx, dy = x - px[mid], y - py[mid]
    column = sensor.column_of_angle(np.arctan2(dy, dx) - pyaw[mid])
    for _ in range(PROJECTION_ITERATIONS):  # fixed point: the pose of the column that sees it
        nearest = np.rint(column).astype(np.int64) % n
        dx, dy = x - px[nearest], y - py[nearest]
        column = sensor.column_of_angle(np.arctan2(dy, dx) - pyaw[nearest])
    nearest = np.rint(column).astype(np.int64) % n
    return column, nearest, np.hypot(dx, dy), dx, dy


def occlusion_buffer(
    occluders: Occluders,
    column_poses: NDArray[np.float64],
    tables: RenderTables,
    max_range_m: float,
) -> tuple[F32, NDArray[np.int32], F32]:
    """Nearest occluders along every column's ray.

    Returns (n_azimuths, K) arrays: range [m] (inf when none), owner id (-2 when none) and
    penetration loss [dB] of the K nearest occluder crossings of each column.
    """
    sensor = tables.sensor
    cfg = tables.physics.occlusion
    n, k_max = sensor.n_azimuths, cfg.max_layers
    ranges = np.full((n, k_max), np.inf, dtype=np.float32)
    owners = np.full((n, k_max), -2, dtype=np.int32)
    losses = np.zeros((n, k_max), dtype=np.float32)
    mid = column_poses[n // 2]
    p0, p1 = occluders.p0, occluders.p1
    half = 0.5 * np.hypot(*(p1 - p0).T)
    near = np.hypot(*(0.5 * (p0 + p1) - mid[:2]).T) < max_range_m + half
    seg = np.nonzero(near)[0]
    if len(seg) == 0:
        return ranges, owners, losses
    ends = np.concatenate([p0[seg], p1[seg]])
    col = sensor.column_of_angle(np.arctan2(ends[:, 1] - mid[1], ends[:, 0] - mid[0]) - mid[2])
    ca, cb = col[: len(seg)], col[len(seg) :]
    span = np.mod(cb - ca, n)
    start = np.where(span <= n / 2, ca, cb)
    span = np.where(span <= n / 2, span, n - span)
    first = np.floor(start).astype(np.int64) - cfg.column_margin
    count = np.ceil(span).astype(np.int64) + 2 * cfg.column_margin + 2
    seg_rep = np.repeat(seg, count)
    within = np.arange(len(seg_rep)) - np.repeat(np.cumsum(count) - count, count)
    cols = (np.repeat(first, count) + within) % n
    yaw = column_poses[:, 2] + tables.azimuths_ccw
    o = column_poses[cols, :2]
    d = np.stack([np.cos(yaw[cols]), np.sin(yaw[cols])], axis=1)
    e = p1[seg_rep] - p0[seg_rep]
    w = p0[seg_rep] - o
    denom = d[:, 0] * e[:, 1] - d[:, 1] * e[:, 0]
    safe = np.where(np.abs(denom) > 1e-9, denom, 1.0)
    r = (w[:, 0] * e[:, 1] - w[:, 1] * e[:, 0]) / safe
    u = (w[:, 0] * d[:, 1] - w[:, 1] * d[:, 0]) / safe
    hit = (np.abs(denom) > 1e-9) & (u >= 0) & (u <= 1) & (r > 0) & (r < max_range_m)
    cols, r, seg_hit = cols[hit], r[hit], seg_rep[hit]
    order = np.lexsort((r, cols))
    cols, r, seg_hit = cols[order], r[order], seg_hit[order]
    first_of_col = np.searchsorted(cols, np.arange(n))
    rank = np.arange(len(cols)) - first_of_col[cols]
    keep = rank < k_max
    ranges[cols[keep], rank[keep]] = r[keep]
    owners[cols[keep], rank[keep]] = occluders.owner[seg_hit[keep]]
    losses[cols[keep], rank[keep]] = occluders.loss_db[seg_hit[keep]]
    return ranges, owners, losses


def _occlusion_gain(
    buffer: tuple[F32, NDArray[np.int32], F32],
    nearest: NDArray[np.int64],
    range_m: F32,
    owner: NDArray[np.int32],
    tolerance_m: float,
) -> F32:
    """Power factor (N,) of the penetration losses of the occluders in front of each return."""
    ranges, owners, losses = buffer
    gain = np.ones(len(range_m), dtype=np.float32)
    behind = range_m - np.float32(tolerance_m)
    candidates = np.nonzero(ranges[:, 0][nearest] < behind)[0]  # behind the nearest occluder
    col, limit, own = nearest[candidates], behind[candidates], owner[candidates]
    loss_db = np.zeros(len(candidates), dtype=np.float32)
    for k in range(ranges.shape[1]):  # a few layers; 1-D gathers are the fast path
        shadowed = (ranges[:, k][col] < limit) & (owners[:, k][col] != own)
        loss_db += np.where(shadowed, losses[:, k][col], np.float32(0))
    gain[candidates] = np.power(np.float32(10.0), loss_db * np.float32(-0.1))
    return gain


def _static_returns(
    world: World,
    column_poses: NDArray[np.float64],
    buffer: tuple[F32, NDArray[np.int32], F32] | None,
    tables: RenderTables,
) -> tuple[Returns, F32]:
    """Returns of static scatterers (phase not yet drawn) and their ghost delays [m].

    Scatterers out of range, or too weak to rise above MIN_VISIBLE_POWER even at normal
    incidence, are dropped after a first cheap pass with the mid-scan pose.
    """
    phys, all_sc = tables.physics, world.scatterers
    mid = column_poses[tables.sensor.n_azimuths // 2]
    index = world.cull(mid[:2], tables.sensor.max_range_m + CULL_MARGIN_M)
    dx0 = all_sc.x[index] - np.float32(mid[0])
    dy0 = all_sc.y[index] - np.float32(mid[1])
    log_r = np.float32(0.5) * np.log(np.maximum(dx0 * dx0 + dy0 * dy0, np.float32(1e-6)))
    log_reach = np.float32(np.log(tables.sensor.max_range_m + CULL_MARGIN_M))
    loudness = np.log(all_sc.power[index]) + log_path_gain(log_r, phys.path_loss)
    visible = (log_r < log_reach) & (loudness > np.float32(np.log(MIN_VISIBLE_POWER)))
    kept = index[visible]
    sc = all_sc.take(kept)
    column, nearest, r, dx, dy = project(sc.x, sc.y, column_poses, tables)
    ok = (r > MIN_RANGE_M) & (r < tables.sensor.max_range_m)
    column, nearest, r, dx, dy = column[ok], nearest[ok], r[ok], dx[ok], dy[ok]
    cos_inc = np.abs(dx * sc.nx[ok] + dy * sc.ny[ok]) / r
    diffuse = sc.diffuse[ok]
    incidence = diffuse + (np.float32(1) - diffuse) * cos_inc ** np.float32(world.specular_exponent)
    if phys.glint.enabled:
        incidence *= glint_gain(kept[ok], dx, dy, phys.glint)
    slant, elevation_gain = _elevation(r, sc.z[ok], phys)
    # numpy's stubs drop the float32 precision of this product; all factors are float32.
    power = cast(F32, sc.power[ok] * path_gain(slant, phys.path_loss) * incidence * elevation_gain)
    if buffer is not None:
        power *= _occlusion_gain(buffer, nearest, r, sc.owner[ok], phys.occlusion.tolerance_m)
    return Returns(column, slant, power, np.zeros(0, np.float32)), sc.ghost_delay_m[ok]


def glint_gain(scatterer: NDArray[np.int64], dx: F32, dy: F32, cfg: Glint) -> F32:
    """Power gain (N,) of scatterers (world indices) seen along world offsets (dx, dy) [m]:
    10 ** (amplitude_db * sin(lobes * bearing + phase) / 10), the phase a fixed function of the
    scatterer's index (`Glint`)."""
    phase = np.mod(scatterer.astype(np.float64) * GOLDEN_FRACTION, 1.0) * (2.0 * np.pi)
    bearing = np.arctan2(dy, dx).astype(np.float64)
    gain_db = cfg.amplitude_db * np.sin(cfg.lobes * bearing + phase)
    return np.power(10.0, 0.1 * gain_db).astype(np.float32)


def _elevation(
    ground_range_m: F32, height_m: F32 | float, physics: PhysicsConfig
) -> tuple[F32, F32]:
    """Slant range [m] and elevation-pattern power gain of scatterers at a height [m]."""
    cfg = physics.elevation
    if not cfg.enabled:
        return ground_range_m, np.ones_like(ground_range_m)
    dz = (
        (height_m - np.float32(cfg.sensor_height_m))
        if isinstance(height_m, np.ndarray)
        else np.float32(height_m) - np.float32(cfg.sensor_height_m)
    )
    slant = np.sqrt(ground_range_m * ground_range_m + dz * dz)
    sine = dz / slant  # small-angle: elevation ~ sin(elevation)
    gain = np.exp(np.float32(-0.5 / np.deg2rad(cfg.beam_sigma_deg) ** 2) * sine * sine)
    return slant, gain


def _traffic_returns(
    world: World,
    column_poses: NDArray[np.float64],
    column_times_s: NDArray[np.float64],
    buffer: tuple[F32, NDArray[np.int32], F32] | None,
    tables: RenderTables,
) -> Returns:
    """Returns of moving vehicles, each point seen at the time of the column that sees it."""
    traffic = world.traffic
    n = tables.sensor.n_azimuths
    empty = Returns(*(np.zeros(0, np.float32) for _ in range(4)))
    if len(traffic) == 0:
        return empty
    t_mid = column_times_s[n // 2]
    vehicles = np.arange(len(traffic))
    pose_mid = traffic.poses(vehicles, np.full(len(vehicles), t_mid))
    reach = tables.sensor.max_range_m + TRAFFIC_MARGIN_M
    near = np.hypot(*(pose_mid[:, :2] - column_poses[n // 2, :2]).T) < reach
    vehicles = vehicles[near]
    if len(vehicles) == 0:
        return empty
    n_points = traffic.body_xy.shape[1]
    vid = np.repeat(vehicles, n_points)
    body = traffic.body_xy[vehicles].reshape(-1, 2)
    t = np.full(len(vid), t_mid)
    for _ in range(PROJECTION_ITERATIONS):
        pose = traffic.poses(vid, t)
        c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
        x = (pose[:, 0] + c * body[:, 0] - s * body[:, 1]).astype(np.float32)
        y = (pose[:, 1] + s * body[:, 0] + c * body[:, 1]).astype(np.float32)
        column, nearest, r, _, _ = project(x, y, column_poses, tables)
        t = column_times_s[nearest]
    ok = (r > MIN_RANGE_M) & (r < tables.sensor.max_range_m)
    slant, elevation_gain = _elevation(r[ok], VEHICLE_SCATTERER_HEIGHT_M, tables.physics)
    power = traffic.body_power[vehicles].reshape(-1)[ok] * path_gain(
        slant, tables.physics.path_loss
    )
    power *= elevation_gain
    if buffer is not None:
        owner = np.full(int(ok.sum()), -1, dtype=np.int32)
        power *= _occlusion_gain(
            buffer, nearest[ok], r[ok], owner, tables.physics.occlusion.tolerance_m
        )
    return Returns(column[ok], slant, power, np.zeros(0, np.float32))


def _with_speckle_and_ghosts(
    direct: Returns, ghost_delay_m: F32, tables: RenderTables, rng: np.random.Generator
) -> Returns:
    """Draw speckle (phase, exponential intensity) and append multipath ghosts."""
    phys = tables.physics
    column, r, power = direct.column, direct.range_m, direct.power
    if phys.multipath.enabled and len(ghost_delay_m) == len(power):
        strong = power > np.float32(10 ** (phys.multipath.threshold_db / 10))
        gain = np.float32(10 ** (phys.multipath.gain_db / 10))
        column = np.concatenate([column, column[strong]])
        r = np.concatenate([r, r[strong] + ghost_delay_m[strong]])
        power = np.concatenate([power, power[strong] * gain])
    if phys.speckle.enabled:
        power = power * rng.standard_exponential(len(power), dtype=np.float32)
        phase = rng.random(len(power), dtype=np.float32) * np.float32(2 * np.pi)
    else:  # frozen speckle: geometric phase (float64: r / wavelength is ~1e5 cycles)
        cycles = r.astype(np.float64) * (2.0 / phys.speckle.wavelength_m)
        phase = ((cycles - np.floor(cycles)) * (2 * np.pi)).astype(np.float32)
    return Returns(column, r, power, phase)


def pad_rows(tables: RenderTables) -> int:
    """Rows of padding above and below the field: the widest beam tap offset (no wrap-around
    arithmetic while accumulating; `fold_padding` wraps them afterwards)."""
    offsets = np.concatenate([tables.offsets, tables.sidelobe_offsets])
    return int(np.max(np.abs(offsets))) if len(offsets) else 0


def _accumulate(padded: NDArray[np.complex64], ret: Returns, tables: RenderTables) -> None:
    """Add returns to the padded complex field (n_azimuths + 2 pad, n_field_bins) with the
    beam pattern (main lobe for all, sidelobes for strong returns)."""
    n_bins = tables.n_field_bins
    pad = pad_rows(tables)
    b = (ret.range_m * np.float32(1.0 / tables.field_bin_m)).astype(np.int64)
    ok = b < n_bins
    b, column, power, phase = b[ok], ret.column[ok], ret.power[ok], ret.phase[ok]
    amplitude = np.sqrt(power) * tables.bin_amplitude_scale[b]
    carrier = np.empty(len(b), dtype=np.complex64)
    if len(phase):
        carrier.real = amplitude * np.cos(phase)
        carrier.imag = amplitude * np.sin(phase)
    else:
        carrier.real, carrier.imag = amplitude, 0.0
    centre = np.rint(column).astype(np.int64)
    residual = centre.astype(np.float32) - column
    flat = padded.reshape(-1)
    base = (centre % tables.sensor.n_azimuths + pad) * n_bins + b
    # amplitude pattern = sqrt of the (power) beam pattern exp(-delta^2 / (2 sigma^2))
    quarter_inv_sigma2 = np.float32(-0.25 / tables.beam_sigma**2)
    for offset in tables.offsets:  # a handful of taps; each is vectorised over all returns
        index = base + offset * n_bins
        if len(tables.offsets) == 1:
            np.add.at(flat, index, carrier)
            continue
        delta = residual + np.float32(offset)
        np.add.at(flat, index, carrier * np.exp(delta * delta * quarter_inv_sigma2))
    strong = np.nonzero(
        power > np.float32(10 ** (tables.physics.beam_pattern.sidelobe_min_db / 10))
    )[0]
    if len(tables.sidelobe_offsets) and len(strong):
        index = base[strong, None] + tables.sidelobe_offsets[None, :] * n_bins
        np.add.at(
            flat, index.ravel(), (carrier[strong, None] * tables.sidelobe_gains[None, :]).ravel()
        )


def fold_padding(padded: NDArray[np.complex64], pad: int) -> NDArray[np.complex64]:
    """The (n_azimuths, n_field_bins) field, with the padding rows wrapped onto their columns."""
    if pad == 0:
        return padded
    n = padded.shape[0] - 2 * pad
    field = padded[pad : pad + n]
    field[:pad] += padded[pad + n :]
    field[-pad:] += padded[:pad]
    return field


def column_noise_gain(returns: Returns, tables: RenderTables) -> F32 | None:
    """(n_azimuths,) amplitude gain of the noise in each column from receiver clipping by
    strong returns (Saturation streaks), or None when no return clips."""
    sat = tables.physics.saturation
    if not sat.enabled or sat.streak_gain <= 0:
        return None
    threshold = np.float32(10 ** (sat.streak_threshold_db / 10))
    strong = returns.power > threshold
    if not np.any(strong):
        return None
    n = tables.sensor.n_azimuths
    column = np.rint(returns.column[strong]).astype(np.int64) % n
    excess = np.bincount(column, returns.power[strong] / threshold, minlength=n)
    extra = np.minimum(sat.streak_gain * excess, sat.streak_max)
    return np.sqrt(1.0 + extra).astype(np.float32)


def _noise_field(
    tables: RenderTables, rng: np.random.Generator, column_gain: F32 | None
) -> NDArray[np.complex64]:
    """Padded complex field (n_azimuths + 2 pad, n_field_bins) holding receiver noise made of
    uniform bytes (Gaussian after the PSF) in its real rows, or zeros; padding rows are zero.

    Not centred here: the byte mean passes the PSF as a constant that to_output removes.
    Columns with a `column_gain` above 1 get proportionally stronger noise.
    """
    n, n_bins, pad = tables.sensor.n_azimuths, tables.n_field_bins, pad_rows(tables)
    if not tables.physics.noise_floor.enabled:
        return np.zeros((n + 2 * pad, n_bins), dtype=np.complex64)
    padded = np.empty((n + 2 * pad, n_bins, 2), dtype=np.float32)
    padded[:pad] = 0.0
    padded[pad + n :] = 0.0
    raw = np.frombuffer(rng.bytes(n * n_bins * 2), dtype=np.uint8).reshape(n, n_bins, 2)
    noise = padded[pad : pad + n]
    noise[...] = raw
    if column_gain is not None:
        rows = np.nonzero(column_gain > STREAK_MIN_GAIN)[0]
        mean = np.float32(UNIFORM_U8_MEAN)
        noise[rows] = (noise[rows] - mean) * column_gain[rows, None, None] + mean
    return padded.view(np.complex64).reshape(n + 2 * pad, n_bins)


def to_output(field: NDArray[np.complex64], tables: RenderTables) -> NDArray[np.uint8]:
    """Point-spread along range, log compression, quantisation, saturation, blanking."""
    pairs = field.view(np.float32).reshape(field.shape + (2,))
    mean = UNIFORM_U8_MEAN if tables.physics.noise_floor.enabled else 0.0
    filtered = cv2.filter2D(  # a 1 x L kernel filters along range (faster than sepFilter2D)
        pairs,
        -1,
        tables.psf[None, :],
        delta=-mean * float(tables.psf.sum()),
        borderType=cv2.BORDER_REFLECT_101,
    )
    amplitude = np.abs(filtered.view(np.complex64)[..., 0])
    # OpenCV's stubs return a generic MatLike; log keeps the float32 source dtype.
    log_amp = cast(F32, cv2.log(amplitude))  # ln(0) = -inf is clamped to level 0 below
    log_amp += tables.log_offset
    # OpenCV's stubs lack the (array, scalar) overload of cv2.max that the bindings accept.
    log_amp = cv2.max(log_amp, 0.0)  # type: ignore[call-overload]
    # amplitude: 40 levels per decade; LUT input is round(LUT_STEPS_PER_LEVEL * 20 log10 P)
    scale = LUT_STEPS_PER_LEVEL * 2.0 * OUTPUT_LEVELS_PER_DECADE / np.log(10.0)
    level = cv2.convertScaleAbs(log_amp, alpha=scale)  # rounds and saturates at 255
    sensor = tables.sensor
    # Output bin k (centre k + 0.5) lies at field coordinate (k + 0.5) / D - 0.5: cv2's mapping.
    wide = cv2.resize(
        level,
        (tables.n_field_bins * RANGE_DECIMATION, sensor.n_azimuths),
        interpolation=cv2.INTER_LINEAR,
    )
    # OpenCV's stubs return a generic MatLike; LUT output has the uint8 dtype of the table.
    out = cast(NDArray[np.uint8], cv2.LUT(wide[:, : sensor.n_bins], tables.lut))
    if tables.n_blank:
        out[:, : tables.n_blank] = tables.physics.near_range.blank_level
    return out


def column_poses_and_times(
    trajectory: Trajectory, scan_end_s: float, tables: RenderTables
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Sensor pose (n_azimuths, 3) and time (n_azimuths,) [s] of every column of a scan."""
    times = scan_end_s + tables.column_offsets_s
    if tables.physics.motion_distortion.enabled:
        poses = trajectory.radar_poses(times)
    else:
        poses = np.repeat(trajectory.radar_poses(np.array([scan_end_s])), len(times), axis=0)
    return poses, times


def render_scan(
    world: World,
    column_poses: NDArray[np.float64],
    column_times_s: NDArray[np.float64],
    tables: RenderTables,
    rng: np.random.Generator,
) -> NDArray[np.uint8]:
    """One polar scan (n_azimuths, n_bins) uint8 of `world` seen from `column_poses`.

    Args:
        world: scatterers, occluders and traffic.
        column_poses: (n_azimuths, 3) radar pose T_world_radar of every column.
        column_times_s: (n_azimuths,) acquisition time of every column [s] (moves traffic).
        tables: precomputed sensor constants.
        rng: source of speckle, noise and ghost phases.
    """
    sensor, phys = tables.sensor, tables.physics
    reach = sensor.max_range_m + CULL_MARGIN_M
    buffer = (
        occlusion_buffer(world.occluders, column_poses, tables, reach)
        if phys.occlusion.enabled
        else None
    )
    static, ghost_delay = _static_returns(world, column_poses, buffer, tables)
    moving = _traffic_returns(world, column_poses, column_times_s, buffer, tables)
    direct = Returns(
        np.concatenate([static.column, moving.column]),
        np.concatenate([static.range_m, moving.range_m]),
        np.concatenate([static.power, moving.power]),
        np.zeros(0, np.float32),
    )
    ghost_delay = np.concatenate([ghost_delay, np.zeros(len(moving.power), np.float32)])
    returns = _with_speckle_and_ghosts(direct, ghost_delay, tables, rng)
    padded = _noise_field(tables, rng, column_noise_gain(returns, tables))
    _accumulate(padded, returns, tables)
    return to_output(fold_padding(padded, pad_rows(tables)), tables)


class Renderer:
    """Renders the scans of one trajectory through one world."""

    def __init__(
        self, world: World, trajectory: Trajectory, sensor: SensorConfig, physics: PhysicsConfig
    ) -> None:
        self.world = world
        self.trajectory = trajectory
        self.tables = make_tables(sensor, physics)

    def scan(self, scan_end_s: float, rng: np.random.Generator) -> NDArray[np.uint8]:
        """The scan whose last column is acquired at `scan_end_s` [s], (n_azimuths, n_bins)."""
        poses, times = column_poses_and_times(self.trajectory, scan_end_s, self.tables)
        return render_scan(self.world, poses, times, self.tables, rng)
