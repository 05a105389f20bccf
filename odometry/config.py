"""The `odometry:` config section: what a user tunes for a sensor or a vehicle (everything else
is a named constant beside its code). Frozen and hashable: derived geometry is cached per config."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from raplace import checks
from raplace.config_io import replaced_by_constant


@dataclass(frozen=True)
class PreprocessConfig:
    """Polar-scan conditioning before any Cartesian image is made."""

    # Range bins are averaged down to about this size [m] (speckle, speed); the finest
    # Cartesian cell should not be smaller.
    bin_size_m: float = 0.2
    min_range_m: float = 3.0  # nearer returns are zeroed [m] (saturated near range, vehicle)
    max_range_m: float = 150.0  # farther returns are dropped [m]
    # Subtract each range bin's median over azimuths (bands that do not move with the vehicle).
    ring_noise_removal: bool = True
    # Per azimuth, subtract mean + this many standard deviations of the row (a CFAR-like noise
    # floor); negative values disable the floor.
    noise_floor_sigmas: float = 0.0

    def __post_init__(self) -> None:
        checks.positive("bin_size_m", self.bin_size_m)
        checks.non_negative("min_range_m", self.min_range_m)
        checks.positive("max_range_m", self.max_range_m)
        checks.less("min_range_m", self.min_range_m, "max_range_m", self.max_range_m)
        checks.finite("noise_floor_sigmas", self.noise_floor_sigmas)


@dataclass(frozen=True)
class LevelConfig:
    """One Cartesian image level: `cell_m`, its pixel size [m] (its side in pixels is a constant,
    `odometry.registration.COARSE_SIZE_PX` and `FINE_SIZE_PX`)."""

    REMOVED_KEYS: ClassVar[dict[str, str]] = {
        "size_px": replaced_by_constant("odometry.registration.COARSE_SIZE_PX, FINE_SIZE_PX"),
        "taper_fraction": replaced_by_constant("odometry.preprocess.TAPER_FRACTION"),
    }
    cell_m: float

    def __post_init__(self) -> None:
        checks.positive("cell_m", self.cell_m)


@dataclass(frozen=True)
class QualityConfig:
    """When a registration counts as failed, what a vehicle can do, and the covariance scale."""

    REMOVED_KEYS: ClassVar[dict[str, str]] = {
        "max_prediction_error_m": replaced_by_constant("odometry.velocity.PREDICTION_TOLERANCE_M"),
        "max_prediction_error_deg": replaced_by_constant(
            "odometry.velocity.PREDICTION_TOLERANCE_DEG"
        ),
        "min_sigma_xy_m": replaced_by_constant("odometry.registration.MIN_SIGMA_XY_M"),
        "min_sigma_yaw_deg": replaced_by_constant("odometry.registration.MIN_SIGMA_YAW_DEG"),
        "velocity_lag_fraction": replaced_by_constant("odometry.odometry.VELOCITY_LAG_FRACTION"),
        "deskew_error_fraction": replaced_by_constant("odometry.odometry.DESKEW_ERROR_FRACTION"),
        "sigma_yaw_deg_per_deg": "removed: rotation terms in turns cost SLAM accuracy",
        "deskew_yaw_error_fraction": "removed: rotation terms in turns cost SLAM accuracy",
    }
    min_peak_quality: float = 6.0  # of the translation and rotation peaks (peak-to-noise)
    max_speed_mps: float = 45.0  # a faster motion is never taken as the velocity [m/s]
    max_yaw_rate_dps: float = 120.0  # a faster rotation is never taken as its yaw rate [deg/s]
    sigma_scale: float = 3.0  # multiplies the peak-derived standard deviations (calibration)

    def __post_init__(self) -> None:
        for name in ("min_peak_quality", "max_speed_mps", "max_yaw_rate_dps"):
            checks.non_negative(name, getattr(self, name), allow_inf=True)
        checks.positive("sigma_scale", self.sigma_scale)


@dataclass(frozen=True)
class KeyframeConfig:
    """When the scan just registered replaces the keyframe (also when the peak falls below
    `odometry.odometry.KEYFRAME_QUALITY_FACTOR` times `quality.min_peak_quality`)."""

    REMOVED_KEYS: ClassVar[dict[str, str]] = {
        "min_peak_quality": replaced_by_constant(
            "odometry.odometry.KEYFRAME_QUALITY_FACTOR, times quality.min_peak_quality"
        ),
    }
    max_translation_m: float = 10.0  # distance from the keyframe [m]
    max_rotation_deg: float = 15.0  # rotation from the keyframe [deg]
    max_frames: int = 8  # at most this many scans are registered against one keyframe

    def __post_init__(self) -> None:
        checks.positive("max_translation_m", self.max_translation_m, allow_inf=True)
        checks.positive("max_rotation_deg", self.max_rotation_deg, allow_inf=True)
        checks.at_least("max_frames", self.max_frames, 1)


@dataclass(frozen=True)
class OdometryConfig:
    """The odometry stage's settings (the `odometry` section of a radar-slam config)."""

    preprocess: PreprocessConfig = field(default_factory=PreprocessConfig)
    # The wide, low-resolution level (global search, rotation) and the near, full-resolution
    # one (sub-pixel translation).
    coarse: LevelConfig = field(default_factory=lambda: LevelConfig(cell_m=0.8))
    fine: LevelConfig = field(default_factory=lambda: LevelConfig(cell_m=0.25))
    quality: QualityConfig = field(default_factory=QualityConfig)
    keyframe: KeyframeConfig = field(default_factory=KeyframeConfig)
    # Correct each scan's motion distortion with the running velocity when it has per-azimuth
    # times (off: register the scans as measured).
    deskew: bool = True
