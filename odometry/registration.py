"""Scan-to-scan registration by phase correlation (PhaRaO-style) as pure functions: rotation by
Fourier-Mellin (both half turns on the coarse level) refined on a polar grid at the coarse and then
at the fine translation (docs/method.md; its use: `odometry.odometry`)."""

from __future__ import annotations

import dataclasses
import functools
import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from odometry.config import OdometryConfig
from odometry.phase_correlation import (
    ROTATION,
    PackedSpectrum,
    Peak,
    Points,
    RotationEstimate,
    correlate,
    estimate_rotation,
    forward,
    forward_rows,
    locate_peak,
    polar_grid,
    refine_rotation_against,
    signature,
)
from odometry.preprocess import (
    CartesianLevel,
    PolarScan,
    Scan,
    cartesian_level,
    motion_from_twist,
    preprocess_polar,
    render_cartesian,
    sample_scan,
    twist_from_motion,
)
from raplace.se2 import compose, inverse, rotate_covariance, wrap_angle
from raplace.units import NS_PER_S

logger = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
F32 = NDArray[np.float32]
PEAK_SMOOTHING_PX = 1.0
"""Gaussian width [pixels] of a translation peak, so that a 3 x 3 fit locates it sub-pixel."""
FINE_SEARCH_PX = 6
"""The fine peak is searched within this many fine pixels of the coarse estimate (the coarse
peak's error is under a coarse pixel, about three fine ones)."""
MAX_COARSE_FINE_DISAGREEMENT_M = 1.0
"""Coarse and fine translations further apart [m] fail (the fine peak is another structure)."""
COARSE_SIZE_PX = 256
"""Side of the coarse image [pixels]: at 0.8 m it spans +-102 m, a Navtech sensor's useful range."""
FINE_SIZE_PX = 384
"""Side of the fine image [pixels]: +-48 m at 0.25 m, where returns are dense and sharp."""
MIN_SIGMA_XY_M = 0.01
"""Floor of a registration's translation standard deviation [m] (range resolution, de-skew)."""
MIN_SIGMA_YAW_DEG = 0.05
"""Floor of its rotation standard deviation [deg] (the small rotation bias of straight steps)."""
HINT_RADIUS_M = 4.0
"""A registration seeded with a hint searches the coarse peak within this distance [m] of the
hint's translation: the error of a constant-velocity prediction at 1 Hz."""


@dataclass(frozen=True)
class MotionEstimate:
    """Relative motion between two scans (a caller must not use `motion` unless `ok`)."""

    motion: FloatArray  # (3,) the current scan's pose in the reference's frame (dx, dy [m], dyaw)
    covariance: FloatArray  # (3, 3) of `motion` [m^2, m rad, rad^2], order (x, y, yaw)
    quality: float  # peak-to-noise ratio of the final translation peak
    ok: bool  # every check passed
    reason: str = ""  # why the estimate failed ("" when ok)


class PreparedScan:
    """A conditioned scan and the spectra registration needs (each made on first use), seen from
    its image time `image_time_s` [s] after the reference time (mid-sweep; 0 with de-skew off or
    no azimuth times), at `image_pose` (3,) T_reference_image under `twist` (3,) [m/s, m/s,
    rad/s] (None: as measured; pose zeros). `empty`: nothing left after conditioning."""

    def __init__(self, polar: PolarScan, twist: FloatArray | None, cfg: OdometryConfig) -> None:
        self.polar = polar
        self.empty = not bool(polar.image.max() > 0)  # the image is non-negative
        self.twist = None if twist is None or polar.timing is None else np.asarray(twist, float)
        self.cfg = cfg
        mid = polar.mid_sweep_s
        # Without a velocity the image is the scan as measured, whose mean viewpoint is the
        # mid-sweep pose too (its offset from the reference pose is unknown: zeros).
        self.image_time_s = float(mid) if cfg.deskew and mid is not None else 0.0
        self.image_pose: FloatArray = (
            np.zeros(3) if self.twist is None else motion_from_twist(self.twist, self.image_time_s)
        )

    @property
    def timestamp_ns(self) -> int:
        return self.polar.timestamp_ns

    def _render(self, level: CartesianLevel, rotation_rad: float) -> F32:
        """The scan's windowed image on `level`, turned by `rotation_rad`, at its image time."""
        return render_cartesian(self.polar, level, rotation_rad, self.twist, self.image_time_s)

    def _sample(self, points: Points, rotation_rad: float) -> F32:
        """The scan sampled at (x, y, range, bearing) points (each (H, W)) of its image frame."""
        return sample_scan(self.polar, *points, rotation_rad, self.twist, self.image_time_s)

    @functools.cached_property
    def coarse_spectrum(self) -> PackedSpectrum:
        return forward(self._render(coarse_level(self.cfg), 0.0))

    @functools.cached_property
    def rotation_signature(self) -> PackedSpectrum:
        return signature(self.coarse_spectrum, ROTATION)

    @functools.cached_property
    def fine_spectrum(self) -> PackedSpectrum:
        return forward(self._render(fine_level(self.cfg), 0.0))

    @functools.cached_property
    def refine_image(self) -> F32:
        """The scan on the rotation-refinement polar grid."""
        grid = polar_grid(ROTATION)
        return self._sample((grid.x_m, grid.y_m, grid.range_m, grid.bearing_rad), 0.0)

    @functools.cached_property
    def refine_spectrum(self) -> PackedSpectrum:
        return forward_rows(self.refine_image)


def prepare(scan: Scan, cfg: OdometryConfig, twist: FloatArray | None = None) -> PreparedScan:
    """Condition a scan, de-skewed with `twist` (3,) [m/s, m/s, rad/s] when de-skew is on."""
    polar = preprocess_polar(scan, cfg.preprocess)
    return PreparedScan(polar, twist if cfg.deskew else None, cfg)


def coarse_level(cfg: OdometryConfig) -> CartesianLevel:
    return cartesian_level(cfg.coarse.cell_m, COARSE_SIZE_PX)


def fine_level(cfg: OdometryConfig) -> CartesianLevel:
    return cartesian_level(cfg.fine.cell_m, FINE_SIZE_PX)


def _residual_rotation(
    ref: PreparedScan, cur: PreparedScan, translation: FloatArray, yaw: float
) -> RotationEstimate:
    """Rotation left with `cur` rendered through (translation [m], yaw [rad]) on `ref`'s grid."""
    moved = cur._sample(polar_grid(ROTATION).shifted(*translation[:2]), yaw)
    return refine_rotation_against(ref.refine_spectrum, moved, ROTATION)


def register(
    ref: PreparedScan, cur: PreparedScan, cfg: OdometryConfig, hint: FloatArray | None = None
) -> MotionEstimate:
    """Pose of `cur` in the frame of `ref` between their reference times: `register_images`
    moved from the image frames; `hint` (3,) a predicted pose between the reference times."""
    image_hint = None
    if hint is not None:
        image_hint = compose(compose(inverse(ref.image_pose), hint), cur.image_pose)
    estimate = register_images(ref, cur, cfg, image_hint)
    return dataclasses.replace(
        estimate,
        motion=compose(compose(ref.image_pose, estimate.motion), inverse(cur.image_pose)),
        covariance=rotate_covariance(estimate.covariance, float(ref.image_pose[2])),
    )


def register_images(
    ref: PreparedScan, cur: PreparedScan, cfg: OdometryConfig, hint: FloatArray | None = None
) -> MotionEstimate:
    """Pose of `cur`'s image frame in `ref`'s (covariance in `ref`'s image frame): a global search
    without `hint`; with `hint` (3,) (dx, dy [m], dyaw [rad]) the rotation starts from its yaw
    and the coarse peak is searched within `HINT_RADIUS_M` of its translation (the caller
    compares the two by peak quality: a hint never overrules the images)."""
    cell = coarse_level(cfg).cell_m
    if hint is None:
        rotation = estimate_rotation(ref.rotation_signature, cur.rotation_signature, ROTATION)
        coarse_peak, yaw = _coarse_translation(ref, cur, rotation.angle_rad, cfg, None)
    else:
        rotation = RotationEstimate(angle_rad=float(hint[2]), sigma_rad=0.0, quality=np.inf)
        coarse_peak, yaw = _coarse_translation(ref, cur, float(hint[2]), cfg, hint[:2])
    t_coarse = coarse_peak.shift_px * cell
    if ROTATION.refine:
        for refinement in range(ROTATION.refine_passes):
            if refinement:
                if abs(rotation.angle_rad) <= np.deg2rad(ROTATION.refine_repeat_min_deg):
                    break  # converged: the translation was made at (about) this yaw
                # The translation again at the refined yaw (near the last one), then the rotation.
                coarse_peak, yaw = _coarse_translation(ref, cur, yaw, cfg, t_coarse)
                t_coarse = coarse_peak.shift_px * cell
            rotation = _residual_rotation(ref, cur, t_coarse, yaw)
            yaw = float(wrap_angle(yaw + rotation.angle_rad))
    level = fine_level(cfg)
    fine = cur._render(level, yaw)
    centre = (float(t_coarse[0]) / level.cell_m, float(t_coarse[1]) / level.cell_m)
    surface = correlate(ref.fine_spectrum, forward(fine), fine.shape, PEAK_SMOOTHING_PX)
    peak = locate_peak(surface, PEAK_SMOOTHING_PX, centre, FINE_SEARCH_PX)
    translation = peak.shift_px * level.cell_m
    if ROTATION.refine and ROTATION.refine_at_fine:  # At the coarse translation, its error
        # along the motion turns returns on one side only (a lane's kerb) into a rotation bias.
        rotation = _residual_rotation(ref, cur, translation, yaw)
        yaw = float(wrap_angle(yaw + rotation.angle_rad))
    motion = np.array([translation[0], translation[1], yaw])
    # Only the images fail a registration (a prior is a hint, never a veto).
    qcfg = cfg.quality
    weakest = min(peak.quality, coarse_peak.quality)
    reason = ""
    if ref.empty or cur.empty:
        reason = "a scan is empty after conditioning"
    elif rotation.quality < qcfg.min_peak_quality:
        reason = f"weak rotation peak (quality {rotation.quality:.1f})"
    elif weakest < qcfg.min_peak_quality:
        reason = f"weak translation peak (quality {weakest:.1f})"
    elif np.hypot(*(motion[:2] - t_coarse)) > MAX_COARSE_FINE_DISAGREEMENT_M:
        reason = f"coarse and fine translations disagree ({t_coarse} vs {motion[:2]})"
    if reason:
        logger.debug("registration failed: %s (motion %s)", reason, motion)
    cov = np.zeros((3, 3))
    cov[:2, :2] = peak.covariance_px() * level.cell_m**2 * qcfg.sigma_scale**2
    cov[:2, :2] += np.eye(2) * MIN_SIGMA_XY_M**2
    cov[2, 2] = (qcfg.sigma_scale * rotation.sigma_rad) ** 2 + np.deg2rad(MIN_SIGMA_YAW_DEG) ** 2
    return MotionEstimate(motion, cov, float(peak.quality), not reason, reason)


def _coarse_translation(
    ref: PreparedScan, cur: PreparedScan, yaw: float, cfg: OdometryConfig, hint: FloatArray | None
) -> tuple[Peak, float]:
    """Coarse translation peak and yaw [rad] of `cur` turned by `yaw` and by a half turn (the
    stronger wins); with `hint` (2,) [m] only `yaw`, searched within `HINT_RADIUS_M` of it."""
    level = coarse_level(cfg)
    image = cur._render(level, yaw)
    spectrum = forward(image)
    turns = (0.0, np.pi) if hint is None else (0.0,)
    centre = None if hint is None else (hint[0] / level.cell_m, hint[1] / level.cell_m)
    radius = None if hint is None else HINT_RADIUS_M / level.cell_m
    hypotheses = []
    for turn in turns:
        surface = correlate(
            ref.coarse_spectrum, spectrum, image.shape, PEAK_SMOOTHING_PX, turn != 0.0
        )
        hypotheses.append((locate_peak(surface, PEAK_SMOOTHING_PX, centre, radius), turn))
    peak, turn = max(hypotheses, key=lambda h: h[0].quality)
    return peak, float(wrap_angle(yaw + turn))


def estimate_motion(
    prev: Scan, cur: Scan, cfg: OdometryConfig | None = None, twist: FloatArray | None = None
) -> MotionEstimate:
    """Pose of scan `cur` in the frame of scan `prev` (check `ok`). `twist` (3,) de-skews both;
    without it they are registered as measured, then (with azimuth times and de-skew on) again
    de-skewed at the velocity that estimate gives."""
    cfg = OdometryConfig() if cfg is None else cfg
    ref_polar, cur_polar = (preprocess_polar(scan, cfg.preprocess) for scan in (prev, cur))
    use_twist = twist if cfg.deskew else None
    estimate = register(
        PreparedScan(ref_polar, use_twist, cfg), PreparedScan(cur_polar, use_twist, cfg), cfg
    )
    dt_s = (int(cur.timestamp_ns) - int(prev.timestamp_ns)) / NS_PER_S
    deskewable = cfg.deskew and ref_polar.timing is not None and cur_polar.timing is not None
    if twist is not None or not deskewable or dt_s <= 0 or not estimate.ok:
        return estimate
    velocity = twist_from_motion(estimate.motion, dt_s)
    return register(
        PreparedScan(ref_polar, velocity, cfg), PreparedScan(cur_polar, velocity, cfg), cfg
    )
