"""Settings of the phase-correlation odometry: one frozen dataclass per step, defaults in code.

`OdometryConfig` is the stage's whole section (`radar_slam.config.merge` applies YAML overrides to
it; unknown keys are errors there). Every tunable number of the odometry lives here; the modules
hold only physical constants. The dataclasses are frozen and hashable, so derived geometry (window,
sampling grids) can be cached per config.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from raplace import checks

MIN_IMAGE_PX = 8
"""Smallest Cartesian image side accepted [pixels] (a peak fit needs a few pixels each side)."""


@dataclass(frozen=True)
class PreprocessConfig:
    """Polar-scan conditioning before any Cartesian image is made.

    Attributes:
        bin_size_m: range bins are averaged down to about this size [m] (speckle suppression and
            speed); the finest Cartesian cell should not be smaller.
        min_range_m: returns nearer than this are zeroed [m] (saturated near range, vehicle body).
        max_range_m: returns farther than this are dropped [m].
        ring_noise_removal: subtract each range bin's median over azimuths (constant-range bands
            that do not move with the vehicle).
        noise_floor_sigmas: per azimuth, subtract mean + this many standard deviations of the
            row (a CFAR-like noise floor); negative values disable the floor.
    """

    bin_size_m: float = 0.2
    min_range_m: float = 3.0
    max_range_m: float = 150.0
    ring_noise_removal: bool = True
    noise_floor_sigmas: float = 0.0

    def __post_init__(self) -> None:
        checks.positive("bin_size_m", self.bin_size_m)
        checks.non_negative("min_range_m", self.min_range_m)
        checks.positive("max_range_m", self.max_range_m)
        checks.less("min_range_m", self.min_range_m, "max_range_m", self.max_range_m)
        checks.finite("noise_floor_sigmas", self.noise_floor_sigmas)


@dataclass(frozen=True)
class LevelConfig:
    """One Cartesian image level.

    Attributes:
        cell_m: pixel size [m].
        size_px: image side [pixels] (the image spans +-size_px * cell_m / 2).
        taper_fraction: the radial apodisation window falls from 1 to 0 over this outer fraction
            of the image's inscribed radius (a Tukey window in radius).
    """

    cell_m: float
    size_px: int
    taper_fraction: float = 0.3

    def __post_init__(self) -> None:
        checks.positive("cell_m", self.cell_m)
        checks.at_least("size_px", self.size_px, MIN_IMAGE_PX)
        checks.even("size_px", self.size_px)
        checks.in_range("taper_fraction", self.taper_fraction, 0.0, 1.0, open_low=True)


@dataclass(frozen=True)
class QualityConfig:
    """When an estimate counts as failed, and how its covariance is scaled.

    Attributes:
        min_peak_quality: minimum peak-to-noise ratio of the translation and rotation peaks.
        max_speed_mps: a motion faster than this is implausible [m/s].
        max_yaw_rate_dps: a rotation faster than this is implausible [deg/s].
        max_prediction_error_m: in `Odometry`, an estimate farther than this from the
            constant-velocity prediction is checked against a registration seeded with the
            prediction; the stronger correlation wins (the prediction never vetoes) [m].
        max_prediction_error_deg: the same for the rotation [deg].
        min_sigma_xy_m: floor of the translation standard deviation [m].
        min_sigma_yaw_deg: floor of the rotation standard deviation [deg].
        sigma_scale: multiplies the peak-derived standard deviations (calibration factor).
        velocity_lag_fraction: in `Odometry`, the error of the velocity that moves a pose from
            mid-sweep to the scan's reference time is taken as this fraction of the velocity's
            last change (it lags an accelerating or turning vehicle), per axis.
        sigma_yaw_deg_per_deg: in `Odometry`, a registration's rotation error that its peak
            does not show grows with the turn (less overlap, a changed perspective): this
            fraction of the turn, as a standard deviation [deg/deg].
        deskew_error_fraction: in `Odometry`, a scan de-skewed with a velocity that lags the
            vehicle's (braking, a yaw-rate step) is bent by about the velocity's last change
            times half a sweep; this multiple of the translation bend is added as a standard
            deviation [m] (above 1 because the measured change itself lags the true one).
        deskew_yaw_error_fraction: the same for the rotation bend [rad].
        The translation term is on (1.25: it calibrates the translation of turning steps at
        1 Hz) and the rotation floor is 0.05 deg (it leaves room for the straight steps'
        rotation bias); the two rotation terms are off (0): 0.1 and 1.25 make the odometry's own
        rotation covariances consistent in tight turns, but looser rotations in turns let the
        pose graph put the straight steps' rotation bias into the turns (SLAM ATE worse; the
        covariance notes in docs/odometry_notes.md, `scripts/bench_nees.py`).
    """

    min_peak_quality: float = 6.0
    max_speed_mps: float = 45.0
    max_yaw_rate_dps: float = 120.0
    max_prediction_error_m: float = 1.5
    max_prediction_error_deg: float = 5.0
    min_sigma_xy_m: float = 0.01
    min_sigma_yaw_deg: float = 0.05
    sigma_scale: float = 3.0
    velocity_lag_fraction: float = 0.25
    sigma_yaw_deg_per_deg: float = 0.0
    deskew_error_fraction: float = 1.25
    deskew_yaw_error_fraction: float = 0.0

    def __post_init__(self) -> None:
        for name in (
            "min_peak_quality",
            "max_speed_mps",
            "max_yaw_rate_dps",
            "max_prediction_error_m",
            "max_prediction_error_deg",
        ):
            checks.non_negative(name, getattr(self, name), allow_inf=True)
        for name in (
            "min_sigma_xy_m",
            "min_sigma_yaw_deg",
            "sigma_scale",
        ):
            checks.positive(name, getattr(self, name))
        for name in (
            "velocity_lag_fraction",
            "sigma_yaw_deg_per_deg",
            "deskew_error_fraction",
            "deskew_yaw_error_fraction",
        ):
            checks.non_negative(name, getattr(self, name))


@dataclass(frozen=True)
class KeyframeConfig:
    """When the current keyframe is replaced by the frame just registered.

    Attributes:
        max_translation_m: distance from the keyframe [m].
        max_rotation_deg: rotation from the keyframe [deg].
        min_peak_quality: peak quality below which the keyframe is renewed (overlap fading).
        max_frames: at most this many frames are registered against one keyframe.
    """

    max_translation_m: float = 10.0
    max_rotation_deg: float = 15.0
    min_peak_quality: float = 12.0
    max_frames: int = 8

    def __post_init__(self) -> None:
        checks.positive("max_translation_m", self.max_translation_m, allow_inf=True)
        checks.positive("max_rotation_deg", self.max_rotation_deg, allow_inf=True)
        checks.non_negative("min_peak_quality", self.min_peak_quality)
        checks.at_least("max_frames", self.max_frames, 1)


@dataclass(frozen=True)
class DeskewConfig:
    """Motion-distortion correction (constant velocity over a sweep).

    Attributes:
        enabled: correct each scan with the current velocity estimate when it has per-azimuth
            times.
        iterations: `estimate_motion` re-registers this many extra times with the velocity of its
            own previous estimate (the `Odometry` class uses the running velocity instead).
        mid_sweep: de-skew the images to the mid-sweep pose and register those (a velocity
            error then smears an image symmetrically instead of displacing it); the motion
            between the scans' reference times follows with the velocity.
        yaw_rate_extrapolation: in `Odometry`, the yaw rate wanted at a time (to move a pose
            from mid-sweep to the reference time, to re-render a new keyframe, and as the second
            de-skew hypothesis of a new scan, first de-skewed at constant velocity; the stronger
            correlation picks the de-skew) is the last measured one plus this fraction of its
            trend extrapolated to that time (0: constant velocity); the extrapolated change is
            bounded by the last measured change and never turns the yaw rate to the other side.
            It never enters the prediction a registration is compared with.
    """

    enabled: bool = True
    iterations: int = 1
    mid_sweep: bool = True
    yaw_rate_extrapolation: float = 1.0

    def __post_init__(self) -> None:
        checks.at_least("iterations", self.iterations, 0)
        checks.finite("yaw_rate_extrapolation", self.yaw_rate_extrapolation)


def _coarse() -> LevelConfig:
    return LevelConfig(cell_m=0.8, size_px=256)


def _fine() -> LevelConfig:
    return LevelConfig(cell_m=0.25, size_px=384)


@dataclass(frozen=True)
class OdometryConfig:
    """The odometry stage's settings (the `odometry` section of a radar-slam config)."""

    preprocess: PreprocessConfig = field(default_factory=PreprocessConfig)
    coarse: LevelConfig = field(default_factory=_coarse)
    fine: LevelConfig = field(default_factory=_fine)
    quality: QualityConfig = field(default_factory=QualityConfig)
    keyframe: KeyframeConfig = field(default_factory=KeyframeConfig)
    deskew: DeskewConfig = field(default_factory=DeskewConfig)
