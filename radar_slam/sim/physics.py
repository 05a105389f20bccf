"""The radar physics of the simulator: one named, configurable effect per dataclass.

Power units: received power is expressed in *counts*, the unit of the sensor's log-compressed
output: a pixel value is `v = floor(20 log10(n) + 0.3)` for the power rounded to an integer
count n >= 1 (0 for n <= 1), i.e. half-dB steps. This reproduces the real Navtech levels 0, 6,
9, 12, 14, 15, 17, ... and the cap at 136 seen in both the MulRan and Oxford samples; with an
exponential noise of mean 2.2 counts it also reproduces the real far-range histogram (level 0:
48 %, 6: 19 %, 9: 11 %, 12: 6 %). Object reflectivities are given
as power in dB (10 log10 counts) that a scatterer returns at `PathLoss.reference_range_m`.

Effects, in the order `render.render_scan` applies them:
    motion_distortion  each column is rendered from the sensor pose at its own time
    path_loss          power falls as (reference_range / range) ** exponent
    elevation          scatterers above ground: slant range and fan-beam elevation pattern
    occlusion          returns behind an occluder are attenuated by its penetration loss
    speckle            random phase and exponential (Swerling-I) intensity per scatterer and scan
    beam_pattern       Gaussian main lobe over neighbouring columns, sidelobes for strong returns
    multipath          delayed, attenuated copies of strong returns along the same column
    noise_floor        complex Gaussian receiver noise
    ring_noise         constant-range bands of extra noise across all columns (fixed per sensor)
    near_range         blanked first bins and decaying leakage / ground clutter near the sensor
    range_psf          range point-spread (windowed FFT) applied to signal and noise together
    saturation         soft knee and hard cap of the log output; radial streaks from clipping
    log_output         log compression to uint8 with the sensor's quantisation
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import cast

import numpy as np
from numpy.typing import NDArray

from radar_slam.sim.sensor import SensorConfig

FWHM_PER_SIGMA = 2.0 * np.sqrt(2.0 * np.log(2.0))
OUTPUT_LEVELS_PER_DECADE = 20.0
"""Log output: 20 levels per decade of power (0.5 dB per level)."""
LUT_STEPS_PER_LEVEL = 1.5
"""Resolution of the output lookup's input: 1.5 steps per output level (levels up to 170)."""
OUTPUT_QUANTISATION_OFFSET = 0.3
"""v = floor(20 log10(n) + 0.3) reproduces the real sensor's levels 0, 6, 9, 12, 14, 15, 17."""
UINT8_MAX = 255


@dataclass(frozen=True)
class MotionDistortion:
    """Render each column from the pose at its own acquisition time (else from the scan end)."""

    enabled: bool = True


@dataclass(frozen=True)
class PathLoss:
    """Range-dependent loss. Navtech sensors compensate part of the r^-4 radar equation in
    hardware up to a range; the effective exponent on point targets is about 1.6 up to
    `knee_range_m` and steeper beyond (calibrated on the real per-range intensity percentiles:
    the real 99th percentile stays near 70-80 out to ~120 m and falls to ~36 at 180 m).
    Extended targets fall one power slower (the beam footprint grows).

    Attributes:
        enabled: apply the loss (else all returns keep their reference power).
        exponent: power ~ (reference_range_m / r) ** exponent below the knee.
        far_exponent: exponent beyond the knee.
        knee_range_m: range where the exponent changes [m].
        reference_range_m: range at which reflectivities are specified [m].
        min_range_m: ranges below this are clamped (avoids the singularity) [m].
    """

    enabled: bool = True
    exponent: float = 1.6
    far_exponent: float = 5.0
    knee_range_m: float = 90.0
    reference_range_m: float = 10.0
    min_range_m: float = 1.0


@dataclass(frozen=True)
class Elevation:
    """Height of scatterers: a facade point at height z and ground range r is seen at slant range
    sqrt(r^2 + (z - h)^2) with a Gaussian elevation (fan-beam) gain; tall facades near the
    sensor smear over several metres of range, as in real scans.

    Attributes:
        enabled: use slant ranges and the elevation pattern (else everything at sensor height).
        sensor_height_m: height of the radar above the ground [m].
        beam_sigma_deg: Gaussian sigma of the elevation pattern [deg].
    """

    enabled: bool = True
    sensor_height_m: float = 1.9
    beam_sigma_deg: float = 12.0


@dataclass(frozen=True)
class Occlusion:
    """Shadowing by facades and parked cars with partial penetration.

    Each occluder segment has its own penetration loss (world.ObjectConfig); a return behind
    several occluders along its column is attenuated by the sum of their losses (at most
    `max_layers` nearest occluders per column are considered).

    Attributes:
        enabled: apply occlusion.
        max_layers: occluders tracked per column.
        tolerance_m: an occluder must be this much nearer than a return to shadow it [m].
        column_margin: extra columns around each occluder's angular extent (sensor motion).
    """

    enabled: bool = True
    max_layers: int = 3
    tolerance_m: float = 0.3
    column_margin: int = 2


@dataclass(frozen=True)
class Speckle:
    """Coherent speckle: every scatterer gets a uniform random phase and an exponential
    intensity factor (mean 1) per scan; returns sharing a resolution cell then interfere.

    Disabled: frozen speckle, i.e. the geometric phase 4 pi r / wavelength and unit intensity,
    so the image is a deterministic function of the geometry (up to receiver noise) with the
    same mean power.

    Attributes:
        enabled: random speckle per scan.
        wavelength_m: carrier wavelength of the frozen phase [m] (76.5 GHz).
    """

    enabled: bool = True
    wavelength_m: float = 0.0039


@dataclass(frozen=True)
class Glint:
    """Aspect-dependent reflectivity of static scatterers: each one's mean power varies with the
    world bearing it is seen from, by amplitude_db * sin(lobes * bearing + phase) [dB], the phase
    fixed per scatterer. Real objects (cars, poles, bushes, facade details) look different from a
    few metres further on, so real scans decorrelate with distance faster than scans of
    isotropic points (README, "Where the simulator is easier than the real scans").

    Off by default (every scenario stays as generated); probes switch it on.

    Attributes:
        enabled: modulate the static scatterers' power by bearing.
        amplitude_db: peak modulation [dB].
        lobes: lobes per turn of the bearing (angular period 360 / lobes deg).
    """

    enabled: bool = False
    amplitude_db: float = 6.0
    lobes: float = 8.0


@dataclass(frozen=True)
class BeamPattern:
    """Azimuth antenna pattern: Gaussian main lobe of the sensor's beamwidth, plus sidelobes
    that smear strong returns into faint arcs (as around bright targets in real scans).

    Attributes:
        enabled: spread returns over neighbouring columns (else only the nearest column).
        half_taps: main-lobe columns on each side of the nearest one.
        sidelobe_db: power of the first sidelobe column relative to the peak [dB].
        sidelobe_slope_db: further decrease per column [dB].
        sidelobe_columns: sidelobe columns on each side beyond the main lobe.
        sidelobe_min_db: only returns stronger than this get sidelobes [dB counts].
    """

    enabled: bool = True
    half_taps: int = 2
    sidelobe_db: float = -30.0
    sidelobe_slope_db: float = 1.0
    sidelobe_columns: int = 8
    sidelobe_min_db: float = 50.0


@dataclass(frozen=True)
class RangePsf:
    """Range point-spread of the windowed FFT, applied to signal and noise alike.

    sigma_bins is calibrated on real MulRan point targets: their power falls by 3 dB at about
    +-4.5 bins and by 10 dB at +-8 bins (a Gaussian of amplitude sigma 5.2 bins); the real
    noise's lag-1 autocorrelation along range (0.96) agrees.

    Attributes:
        enabled: apply the point-spread (else returns and noise stay in single bins).
        sigma_bins: Gaussian sigma of the amplitude point-spread [bins].
        half_width_sigmas: kernel half-length [sigmas].
    """

    enabled: bool = True
    sigma_bins: float = 5.2
    half_width_sigmas: float = 3.0


@dataclass(frozen=True)
class Multipath:
    """Ghosts: returns stronger than `threshold_db` get a copy `delay` metres further along the
    same column (each scatterer has its own delay, see world.ObjectConfig.ghost_delay_m).

    Attributes:
        enabled: add ghosts.
        threshold_db: minimum return power [dB counts] that produces a ghost.
        gain_db: ghost power relative to the direct return [dB].
    """

    enabled: bool = True
    threshold_db: float = 55.0
    gain_db: float = -16.0


@dataclass(frozen=True)
class NoiseFloor:
    """Receiver noise: complex Gaussian, exponential intensity of mean `mean_power` counts.

    2.2 counts puts 49 % of pure-noise pixels at level 0 (real far range: 48 %).
    """

    enabled: bool = True
    mean_power: float = 2.2


@dataclass(frozen=True)
class RingNoise:
    """Constant-range bands: extra noise power in fixed bins, identical for all columns and all
    scans of a sensor (a hardware property, seeded by `seed`, not by the scenario).

    Attributes:
        enabled: add the bands.
        n_bands: number of narrow bands.
        band_power_range: extra power of a band relative to the noise floor (min, max).
        band_width_bins: Gaussian sigma of a band [bins].
        ripple_power: amplitude of a slow ripple over range, relative to the noise floor.
        ripple_period_bins: period of the ripple [bins].
        seed: seed of the band positions.
    """

    enabled: bool = True
    n_bands: int = 24
    band_power_range: tuple[float, float] = (0.1, 0.8)
    band_width_bins: float = 1.5
    ripple_power: float = 0.15
    ripple_period_bins: float = 45.0
    seed: int = 204


@dataclass(frozen=True)
class NearRange:
    """The first metres: blanked bins at a constant level (as MulRan's first 5 bins at 31-32)
    then transmitter leakage decaying with range (speckled like noise); the real CIR204-H
    profile falls 27, 20, 11 and reaches the noise at bin 8 (0.5 m).

    Attributes:
        enabled: apply the near-range effects.
        blank_range_m: bins closer than this are set to `blank_level` [m].
        blank_level: output level of the blanked bins.
        leakage_power_db: extra noise power at the blank edge [dB counts].
        leakage_decay_m: e-folding range of the leakage power [m].
    """

    enabled: bool = True
    blank_range_m: float = 0.3
    blank_level: int = 31
    leakage_power_db: float = 16.0
    leakage_decay_m: float = 0.1


@dataclass(frozen=True)
class Saturation:
    """Receiver compression of strong (mostly near) returns, in output levels, and the radial
    streaks they cause: a return above `streak_threshold_db` clips the receiver, and the
    clipping products raise the noise along its whole column (bright rays in real scans).

    Attributes:
        enabled: compress and add streaks.
        knee_level: levels above this grow by `slope` per level.
        slope: compression slope above the knee.
        max_level: hard cap (136 in the real MulRan and Oxford samples).
        streak_threshold_db: return power that starts clipping [dB counts].
        streak_gain: extra column noise (in noise floors) per threshold power of clipping returns.
        streak_max: cap of the extra column noise [noise floors].
    """

    enabled: bool = True
    knee_level: int = 120
    slope: float = 0.6
    max_level: int = 136
    streak_threshold_db: float = 52.0
    streak_gain: float = 0.3
    streak_max: float = 30.0


@dataclass(frozen=True)
class LogOutput:
    """Log compression to uint8: v = floor(20 log10(n) + 0.3) for integer power n.

    Attributes:
        quantise_counts: reproduce the integer-count level gaps (no values 1-5, 7, 8, ...).
    """

    quantise_counts: bool = True


@dataclass(frozen=True)
class PhysicsConfig:
    """All physical effects; each one can be switched off or tuned independently."""

    motion_distortion: MotionDistortion = field(default_factory=MotionDistortion)
    path_loss: PathLoss = field(default_factory=PathLoss)
    elevation: Elevation = field(default_factory=Elevation)
    occlusion: Occlusion = field(default_factory=Occlusion)
    speckle: Speckle = field(default_factory=Speckle)
    glint: Glint = field(default_factory=Glint)
    beam_pattern: BeamPattern = field(default_factory=BeamPattern)
    multipath: Multipath = field(default_factory=Multipath)
    noise_floor: NoiseFloor = field(default_factory=NoiseFloor)
    ring_noise: RingNoise = field(default_factory=RingNoise)
    near_range: NearRange = field(default_factory=NearRange)
    range_psf: RangePsf = field(default_factory=RangePsf)
    saturation: Saturation = field(default_factory=Saturation)
    log_output: LogOutput = field(default_factory=LogOutput)


def range_psf_kernel(cfg: RangePsf) -> NDArray[np.float32]:
    """(2 h + 1,) amplitude point-spread along range, normalised to unit energy (sum of squares).

    Disabled: the identity kernel [1].
    """
    if not cfg.enabled or cfg.sigma_bins <= 0:
        return np.ones(1, dtype=np.float32)
    half = max(1, int(np.ceil(cfg.half_width_sigmas * cfg.sigma_bins)))
    k = np.arange(-half, half + 1, dtype=np.float64)
    h = np.exp(-0.5 * (k / cfg.sigma_bins) ** 2)
    return (h / np.sqrt(np.sum(h**2))).astype(np.float32)


def beam_sigma_columns(sensor: SensorConfig) -> float:
    """Gaussian sigma of the two-way amplitude-squared beam pattern [columns]."""
    sigma_rad = np.deg2rad(sensor.beamwidth_deg) / FWHM_PER_SIGMA
    return float(sigma_rad / sensor.azimuth_step_rad)


def beam_offsets(cfg: BeamPattern) -> NDArray[np.int64]:
    """Main-lobe column offsets (relative to the nearest column) that receive a share."""
    half = cfg.half_taps if cfg.enabled else 0
    return np.arange(-half, half + 1, dtype=np.int64)


def sidelobe_taps(cfg: BeamPattern) -> tuple[NDArray[np.int64], NDArray[np.float32]]:
    """Sidelobe column offsets and their amplitude gains (empty when disabled)."""
    if not cfg.enabled or cfg.sidelobe_columns <= 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.float32)
    k = np.arange(1, cfg.sidelobe_columns + 1)
    offsets = np.concatenate([-(cfg.half_taps + k), cfg.half_taps + k])
    power_db = cfg.sidelobe_db - cfg.sidelobe_slope_db * (np.concatenate([k, k]) - 1)
    return offsets.astype(np.int64), (10 ** (power_db / 20)).astype(np.float32)


def log_path_gain(log_range: NDArray[np.float32], cfg: PathLoss) -> NDArray[np.float32]:
    """Natural log of the path-loss power factor, from ln(range [m]) (0 at the reference range)."""
    if not cfg.enabled:
        return np.zeros_like(log_range)
    log_r = np.maximum(log_range, np.float32(np.log(cfg.min_range_m)))
    near = np.float32(cfg.exponent) * (np.float32(np.log(cfg.reference_range_m)) - log_r)
    beyond = np.maximum(log_r - np.float32(np.log(cfg.knee_range_m)), np.float32(0))
    gain = near - np.float32(cfg.far_exponent - cfg.exponent) * beyond
    # numpy's stubs drop the float32 precision of array-scalar arithmetic; all operands are float32.
    return cast(NDArray[np.float32], gain)


def path_gain(range_m: NDArray[np.float32], cfg: PathLoss) -> NDArray[np.float32]:
    """Power factor of the path loss at `range_m` (1 at the reference range)."""
    return np.exp(log_path_gain(np.log(np.maximum(range_m, np.float32(1e-6))), cfg))


def extra_noise_profile(sensor: SensorConfig, physics: PhysicsConfig) -> NDArray[np.float64]:
    """(n_bins,) noise power per bin relative to the noise floor (>= 1): ring bands and ripple
    (ring_noise) plus near-range leakage (near_range). Identical for every column and scan."""
    bins = np.arange(sensor.n_bins, dtype=np.float64)
    profile = np.ones(sensor.n_bins)
    floor = physics.noise_floor.mean_power if physics.noise_floor.enabled else 1.0
    ring = physics.ring_noise
    if ring.enabled:
        rng = np.random.default_rng(ring.seed)
        centres = rng.uniform(0, sensor.n_bins, ring.n_bands)
        powers = rng.uniform(*ring.band_power_range, ring.n_bands)
        for centre, power in zip(centres, powers, strict=True):  # a few bands, not a hot path
            profile += power * np.exp(-0.5 * ((bins - centre) / ring.band_width_bins) ** 2)
        phase = rng.uniform(0, 2 * np.pi)
        profile += (
            ring.ripple_power
            * 0.5
            * (1 + np.sin(2 * np.pi * bins / ring.ripple_period_bins + phase))
        )
    near = physics.near_range
    if near.enabled:
        range_m = (bins + 0.5) * sensor.range_resolution_m
        leak = 10 ** (near.leakage_power_db / 10) * np.exp(
            -np.maximum(range_m - near.blank_range_m, 0.0) / near.leakage_decay_m
        )
        profile += leak / floor
    return profile


def blanked_bins(sensor: SensorConfig, cfg: NearRange) -> int:
    """Number of leading bins set to the constant blank level."""
    if not cfg.enabled:
        return 0
    return int(np.ceil(cfg.blank_range_m / sensor.range_resolution_m))


def output_lut(physics: PhysicsConfig) -> NDArray[np.uint8]:
    """(256,) uint8 lookup from c = round(LUT_STEPS_PER_LEVEL * 20 log10 P) to the sensor output:
    integer-count quantisation (log_output), then knee and cap (saturation).

    Input c stands for powers around P = 10 ** (c / (20 * LUT_STEPS_PER_LEVEL)); the output is
    the level of the integer count round(P).
    """
    c = np.arange(UINT8_MAX + 1, dtype=np.float64)
    level = c / LUT_STEPS_PER_LEVEL
    if physics.log_output.quantise_counts:
        counts = np.rint(10.0 ** (level / OUTPUT_LEVELS_PER_DECADE))
        out = np.where(
            counts > 1,
            np.floor(
                OUTPUT_LEVELS_PER_DECADE * np.log10(np.maximum(counts, 1))
                + OUTPUT_QUANTISATION_OFFSET
            ),
            0.0,
        )
    else:
        out = np.floor(level + OUTPUT_QUANTISATION_OFFSET)
    sat = physics.saturation
    if sat.enabled:
        above = out > sat.knee_level
        out[above] = sat.knee_level + sat.slope * (out[above] - sat.knee_level)
        out = np.minimum(np.floor(out), sat.max_level)
    return np.clip(out, 0, UINT8_MAX).astype(np.uint8)
