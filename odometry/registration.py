"""Scan-to-scan registration by phase correlation (PhaRaO-style), as pure functions.

`estimate_motion(prev, cur, cfg)` returns the pose of `cur` in the frame of `prev`
(dx, dy [m], dyaw [rad]; x forward, y left, yaw CCW) with a covariance and a quality flag:

1. Both scans are conditioned (`preprocess_polar`) and rendered as windowed Cartesian images;
   the coarse level (wide, low resolution) is made at once, the fine level (near range, full
   resolution) when the scan serves as a reference. With a velocity, the images are de-skewed
   to the mid-sweep pose (`PreparedScan.image_pose`); `register_images` returns the motion
   between those image frames and `register` moves it to the scans' reference times.
2. Rotation: Fourier-Mellin on the coarse spectra (`odometry.rotation`), known modulo pi.
3. Translation: `cur` is re-rendered rotated into `prev`'s orientation (rotation folded into the
   polar sampling maps, so no second interpolation); both half-turn hypotheses are phase
   correlated on the coarse level (the second is the first image turned by pi, computed in the
   Fourier domain) and the stronger peak wins; the fine level then refines the translation near
   the coarse peak to a fraction of a fine pixel.
4. Quality: peak-to-noise ratios, coarse/fine agreement and plausible speeds decide `ok`; the
   covariance comes from the peaks' widths and heights.

`prepare` and `register` split the work so that a caller (the `Odometry` class) conditions each
scan once and keeps a reference's spectra while registering many scans against it.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from odometry.config import OdometryConfig
from odometry.deskew import motion_from_twist, twist_from_motion
from odometry.phase_correlation import (
    PackedSpectrum,
    Peak,
    correlate,
    forward,
    locate_peak,
)
from odometry.preprocess import (
    CartesianLevel,
    PolarScan,
    cartesian_level,
    preprocess_polar,
    render_cartesian,
    sample_scan,
)
from odometry.rotation import (
    ROTATION,
    RotationEstimate,
    Signature,
    angular_spectrum,
    estimate_rotation,
    polar_grid,
    refine_rotation_against,
    signature,
)
from odometry.scan import Scan
from raplace.se2 import compose, inverse, rotate_covariance, wrap_angle
from raplace.units import NS_PER_S

logger = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]


PEAK_SMOOTHING_PX = 1.0
"""Gaussian width [pixels] of a translation correlation peak (low-pass on the normalised
cross-power spectrum), so that a 3 x 3 Gaussian fit locates it to a fraction of a pixel."""
FINE_SEARCH_PX = 6
"""The fine peak is searched within this many fine pixels of the coarse estimate (the coarse
peak's error is under a coarse pixel, about three fine ones)."""
MAX_COARSE_FINE_DISAGREEMENT_M = 1.0
"""Coarse and fine translations further apart than this [m] fail a registration (more than a
coarse pixel: the fine peak is another structure)."""
COARSE_SIZE_PX = 256
"""Side of the coarse image [pixels]: at the default 0.8 m it spans +-102 m, the useful range of
a Navtech sensor, so the global search sees every structure both scans share."""
FINE_SIZE_PX = 384
"""Side of the fine image [pixels]: at the default 0.25 m it spans +-48 m, the near range where
returns are dense and sharp enough for a sub-pixel translation."""
MIN_SIGMA_XY_M = 0.01
"""Floor of a registration's translation standard deviation [m] (a sharp peak is not a
centimetre-exact motion: the scan's range resolution and de-skew remain)."""
MIN_SIGMA_YAW_DEG = 0.05
"""Floor of its rotation standard deviation [deg]; it leaves room for the small rotation bias of
straight steps."""
HINT_RADIUS_M = 4.0
"""A registration seeded with a hint searches the coarse translation peak within this distance of
the hint's translation [m]: the error of a constant-velocity prediction at 1 Hz (a few m/s^2 of
braking or acceleration over the interval)."""


@dataclass(frozen=True)
class MotionEstimate:
    """Relative motion between two scans.

    Attributes:
        motion: (3,) pose of the current scan in the reference scan's frame: dx, dy [m], dyaw
            [rad] (x forward, y left, yaw CCW), between the scans' reference times.
        covariance: (3, 3) covariance of `motion` [m^2, m rad, rad^2], order (x, y, yaw).
        quality: peak-to-noise ratio of the final translation peak (higher is better).
        rotation_quality: peak-to-noise ratio of the rotation peak.
        ok: True when every check passed; a caller must not use `motion` when False.
        reason: why the estimate failed ("" when ok).
        coarse_motion: (3,) the coarse level's estimate (for diagnostics).
    """

    motion: FloatArray
    covariance: FloatArray
    quality: float
    rotation_quality: float
    ok: bool
    reason: str = ""
    coarse_motion: FloatArray = field(default_factory=lambda: np.zeros(3))

    @property
    def dx(self) -> float:
        return float(self.motion[0])

    @property
    def dy(self) -> float:
        return float(self.motion[1])

    @property
    def dyaw(self) -> float:
        return float(self.motion[2])


class PreparedScan:
    """A conditioned scan with the spectra registration needs, computed once.

    The images show the scene from the sensor pose at the scan's *image time*: mid-sweep when
    the scan is de-skewed (an error in the velocity then only smears the image symmetrically
    instead of displacing it), the reference time otherwise.
    `image_pose` is that pose in the scan's reference frame, under the de-skew velocity.

    Attributes:
        polar: the conditioned polar scan.
        twist: (3,) body velocity used for de-skewing (None: as measured).
        image_time_s: image time relative to the scan's reference time [s] (0 when de-skewing
            is disabled or the scan has no azimuth times).
        image_pose: (3,) T_reference_image, the image frame in the reference frame under
            `twist` (zeros without a twist).
        empty: nothing is left after conditioning (the scan cannot be registered).
        coarse_spectrum: packed spectrum (`odometry.packed`) of the unrotated coarse image.
        rotation_signature: Fourier-Mellin signature of the coarse image.
    """

    def __init__(
        self,
        polar: PolarScan,
        twist: FloatArray | None,
        cfg: OdometryConfig,
    ) -> None:
        self.polar = polar
        self.empty = not bool(polar.image.max() > 0)  # the image is non-negative
        self.twist = None if twist is None or polar.timing is None else np.asarray(twist, float)
        self.cfg = cfg
        mid = polar.mid_sweep_s
        use_mid = cfg.deskew and mid is not None
        # Without a velocity the image is the scan as measured, whose mean viewpoint is the
        # mid-sweep pose too (its offset from the reference pose is unknown: zeros).
        self.image_time_s = float(mid) if use_mid and mid is not None else 0.0
        self.image_pose: FloatArray = (
            motion_from_twist(self.twist, self.image_time_s)
            if self.twist is not None
            else np.zeros(3)
        )

    @property
    def timestamp_ns(self) -> int:
        return self.polar.timestamp_ns

    def _render(self, level: CartesianLevel, rotation_rad: float) -> NDArray[np.float32]:
        """The scan's windowed image on `level`, turned by `rotation_rad`, at its image time."""
        return render_cartesian(self.polar, level, rotation_rad, self.twist, self.image_time_s)

    def _sample(
        self,
        points: tuple[
            NDArray[np.float32], NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]
        ],
        rotation_rad: float,
    ) -> NDArray[np.float32]:
        """The scan sampled at (x, y, range, bearing) points of its image frame."""
        return sample_scan(self.polar, *points, rotation_rad, self.twist, self.image_time_s)

    # The spectra are made on first use: a scan re-rendered only to be registered again with a
    # hint (or never used as a reference) needs none of them.
    @functools.cached_property
    def coarse_spectrum(self) -> PackedSpectrum:
        """Packed spectrum of the unrotated coarse image."""
        return forward(self._render(coarse_level(self.cfg), 0.0))

    @functools.cached_property
    def rotation_signature(self) -> Signature:
        """Fourier-Mellin signature of the coarse image."""
        return signature(self.coarse_spectrum, ROTATION)

    @functools.cached_property
    def fine_spectrum(self) -> PackedSpectrum:
        """Packed spectrum of the unrotated fine image (made when the scan is a reference)."""
        return forward(self._render(fine_level(self.cfg), 0.0))

    @functools.cached_property
    def refine_image(self) -> NDArray[np.float32]:
        """The scan on the rotation-refinement polar grid (made when the scan is a reference)."""
        grid = polar_grid(ROTATION)
        return self._sample((grid.x_m, grid.y_m, grid.range_m, grid.bearing_rad), 0.0)

    @functools.cached_property
    def refine_spectrum(self) -> PackedSpectrum:
        """`angular_spectrum` of `refine_image` (made when the scan is a reference)."""
        return angular_spectrum(self.refine_image)


def prepare(scan: Scan, cfg: OdometryConfig, twist: FloatArray | None = None) -> PreparedScan:
    """Condition a scan and compute its coarse spectrum and rotation signature.

    Args:
        scan: the raw scan.
        cfg: odometry settings.
        twist: (3,) body velocity (vx, vy [m/s], yaw rate [rad/s]) to de-skew with; ignored when
            de-skewing is disabled or the scan has no azimuth times.
    """
    polar = preprocess_polar(scan, cfg.preprocess)
    return PreparedScan(polar, twist if cfg.deskew else None, cfg)


def coarse_level(cfg: OdometryConfig) -> CartesianLevel:
    """The coarse image level of `cfg`."""
    return cartesian_level(cfg.coarse.cell_m, COARSE_SIZE_PX)


def fine_level(cfg: OdometryConfig) -> CartesianLevel:
    """The fine image level of `cfg`."""
    return cartesian_level(cfg.fine.cell_m, FINE_SIZE_PX)


def _peak_to_metres(peak: Peak, cell_m: float) -> FloatArray:
    """Translation (x, y) [m] of the moved scan's sensor from a peak of correlate(ref, moved).

    The moved image's content is the reference's displaced by -t; +1 row is -cell in x and
    +1 column is -cell in y, so t = (rows, cols) * cell.
    """
    return peak.shift_px * cell_m


def _residual_rotation(
    ref: PreparedScan, cur: PreparedScan, translation: FloatArray, yaw: float, cfg: OdometryConfig
) -> RotationEstimate:
    """Rotation left after rendering `cur` through (translation, yaw) onto the polar grid about
    `ref`'s sensor."""
    grid = polar_grid(ROTATION)
    moved = cur._sample(grid.shifted(float(translation[0]), float(translation[1])), yaw)
    return refine_rotation_against(ref.refine_spectrum, moved, ROTATION)


def register(
    ref: PreparedScan, cur: PreparedScan, cfg: OdometryConfig, hint: FloatArray | None = None
) -> MotionEstimate:
    """Pose of `cur` in the frame of `ref` between their reference times (see the module
    docstring): `register_images` moved from the image frames to the reference frames; `hint`
    (3,) a predicted pose between the reference times, as `register_images`' hint."""
    image_hint = None
    if hint is not None:
        image_hint = compose(compose(inverse(ref.image_pose), hint), cur.image_pose)
    estimate = register_images(ref, cur, cfg, image_hint)
    return dataclasses.replace(
        estimate,
        motion=image_to_reference(estimate.motion, ref, cur),
        covariance=rotate_covariance(estimate.covariance, float(ref.image_pose[2])),
        coarse_motion=image_to_reference(estimate.coarse_motion, ref, cur),
    )


def image_to_reference(
    image_motion: FloatArray, ref: PreparedScan, cur: PreparedScan
) -> FloatArray:
    """T_ref_cur between the scans' reference times from T between their image frames."""
    return compose(compose(ref.image_pose, image_motion), inverse(cur.image_pose))


def register_images(
    ref: PreparedScan,
    cur: PreparedScan,
    cfg: OdometryConfig,
    hint: FloatArray | None = None,
) -> MotionEstimate:
    """Pose of `cur`'s image frame in `ref`'s image frame (see `PreparedScan`); the covariance's
    translation is in `ref`'s image frame.

    Without `hint` the search is global: rotation over the full circle (Fourier-Mellin modulo
    pi, the half turn resolved by the stronger translation peak), translation anywhere in the
    coarse image. With `hint` (3,) (dx, dy [m], dyaw [rad], e.g. a motion model's prediction)
    the registration is seeded with it: the rotation starts from the hint's yaw and the coarse
    translation peak is searched within `HINT_RADIUS_M` of the hint's
    translation; the refinements that follow are the same. The caller compares the two by their
    peak quality (a hint narrows the search, it never overrules the images).
    """
    coarse = coarse_level(cfg)
    if hint is None:
        rotation = estimate_rotation(ref.rotation_signature, cur.rotation_signature, ROTATION)
        coarse_peak, yaw = _coarse_translation(ref, cur, rotation.angle_rad, cfg, None)
    else:
        rotation = RotationEstimate(angle_rad=float(hint[2]), sigma_rad=0.0, quality=np.inf)
        coarse_peak, yaw = _coarse_translation(ref, cur, float(hint[2]), cfg, hint[:2])
    t_coarse = _peak_to_metres(coarse_peak, coarse.cell_m)
    coarse_motion = np.array([t_coarse[0], t_coarse[1], yaw])
    if ROTATION.refine:
        for refinement in range(ROTATION.refine_passes):
            if refinement:
                if abs(rotation.angle_rad) <= np.deg2rad(ROTATION.refine_repeat_min_deg):
                    break  # converged: the translation was made at (about) this yaw
                # The translation again at the refined yaw (near the last one), then the rotation.
                coarse_peak, yaw = _coarse_translation(ref, cur, yaw, cfg, t_coarse)
                t_coarse = _peak_to_metres(coarse_peak, coarse.cell_m)
            rotation = _residual_rotation(ref, cur, t_coarse, yaw, cfg)
            yaw = float(wrap_angle(yaw + rotation.angle_rad))

    peak, cell = coarse_peak, coarse.cell_m
    peak, cell = _fine_translation(ref, cur, t_coarse, yaw, cfg)
    translation = _peak_to_metres(peak, cell)
    motion = np.array([translation[0], translation[1], yaw])
    # Only the images can fail a registration: a motion faster than a vehicle moves is still
    # what they show (a prior is a hint, never a veto); it just never becomes a velocity.
    reason = _failure_reason(ref, cur, rotation, coarse_peak, peak, t_coarse, motion, cfg)
    if reason:
        logger.debug("registration failed: %s (motion %s)", reason, motion)
    return MotionEstimate(
        motion=motion,
        covariance=_covariance(peak, cell, rotation, cfg),
        quality=float(peak.quality),
        rotation_quality=rotation.quality,
        ok=not reason,
        reason=reason,
        coarse_motion=coarse_motion,
    )


def _coarse_translation(
    ref: PreparedScan,
    cur: PreparedScan,
    angle_rad: float,
    cfg: OdometryConfig,
    hint_xy: FloatArray | None,
) -> tuple[Peak, float]:
    """Coarse translation peak and yaw [rad] with `cur` rendered turned by `angle_rad`.

    Without `hint_xy` both half-turn hypotheses are correlated and the stronger peak wins (the
    Fourier-Mellin rotation is known modulo pi); with `hint_xy` (2,) [m] only `angle_rad` is
    tried and the peak is searched within `hint_radius_m` of that translation."""
    level = coarse_level(cfg)
    image = cur._render(level, angle_rad)
    spectrum = forward(image)
    shape = image.shape
    turns = (0.0, np.pi) if hint_xy is None else (0.0,)
    centre = (
        None
        if hint_xy is None
        else (float(hint_xy[0]) / level.cell_m, float(hint_xy[1]) / level.cell_m)
    )
    radius = None if hint_xy is None else HINT_RADIUS_M / level.cell_m
    hypotheses = []
    for turn in turns:
        surface = correlate(ref.coarse_spectrum, spectrum, shape, PEAK_SMOOTHING_PX, turn != 0.0)
        hypotheses.append((locate_peak(surface, PEAK_SMOOTHING_PX, centre, radius), turn))
    peak, turn = max(hypotheses, key=lambda h: h[0].quality)
    return peak, float(wrap_angle(angle_rad + turn))


def _fine_translation(
    ref: PreparedScan, cur: PreparedScan, t_coarse: FloatArray, yaw: float, cfg: OdometryConfig
) -> tuple[Peak, float]:
    """The fine level's translation peak near the coarse estimate, and the fine cell [m]."""
    level = fine_level(cfg)
    fine = cur._render(level, yaw)
    centre = t_coarse / level.cell_m
    surface = correlate(ref.fine_spectrum, forward(fine), fine.shape, PEAK_SMOOTHING_PX)
    peak = locate_peak(
        surface, PEAK_SMOOTHING_PX, (float(centre[0]), float(centre[1])), FINE_SEARCH_PX
    )
    return peak, level.cell_m


def _covariance(
    peak: Peak, cell_m: float, rotation: RotationEstimate, cfg: OdometryConfig
) -> FloatArray:
    """(3, 3) covariance of a registration from its translation and rotation peaks."""
    qcfg = cfg.quality
    cov = np.zeros((3, 3))
    cov[:2, :2] = peak.covariance_px() * cell_m**2 * qcfg.sigma_scale**2
    cov[:2, :2] += np.eye(2) * MIN_SIGMA_XY_M**2
    cov[2, 2] = (qcfg.sigma_scale * rotation.sigma_rad) ** 2 + np.deg2rad(MIN_SIGMA_YAW_DEG) ** 2
    return cov


def _failure_reason(
    ref: PreparedScan,
    cur: PreparedScan,
    rotation: RotationEstimate,
    coarse_peak: Peak,
    peak: Peak,
    t_coarse: FloatArray,
    motion: FloatArray,
    cfg: OdometryConfig,
) -> str:
    """Why the images do not support a registration ("" when every check passes): empty scans,
    weak peaks, coarse/fine disagreement."""
    qcfg = cfg.quality
    if ref.empty or cur.empty:
        return "a scan is empty after conditioning"
    if rotation.quality < qcfg.min_peak_quality:
        return f"weak rotation peak (quality {rotation.quality:.1f})"
    if min(peak.quality, coarse_peak.quality) < qcfg.min_peak_quality:
        return f"weak translation peak (quality {min(peak.quality, coarse_peak.quality):.1f})"
    if np.hypot(*(motion[:2] - t_coarse)) > MAX_COARSE_FINE_DISAGREEMENT_M:
        return f"coarse and fine translations disagree ({t_coarse} vs {motion[:2]})"
    return ""


def kinematic_reason(twist: FloatArray, cfg: OdometryConfig) -> str:
    """Why the body twist (vx, vy [m/s], yaw rate [rad/s]) is faster than the vehicle can move
    or turn (`QualityConfig.max_speed_mps`, `max_yaw_rate_dps`); "" when it is not."""
    qcfg = cfg.quality
    speed = float(np.hypot(twist[0], twist[1]))
    if speed > qcfg.max_speed_mps:
        return f"implausible speed {speed:.1f} m/s"
    yaw_rate_dps = float(np.rad2deg(abs(twist[2])))
    if yaw_rate_dps > qcfg.max_yaw_rate_dps:
        return f"implausible yaw rate {yaw_rate_dps:.1f} deg/s"
    return ""


def estimate_motion(
    prev: Scan,
    cur: Scan,
    cfg: OdometryConfig | None = None,
    twist: FloatArray | None = None,
) -> MotionEstimate:
    """Pose of scan `cur` in the frame of scan `prev` (pure; see the module docstring).

    Args:
        prev, cur: the two scans (any objects with the `Scan` attributes).
        cfg: odometry settings (defaults when None).
        twist: (3,) body velocity (vx, vy [m/s], yaw rate [rad/s]) to de-skew both scans with.
            None: the scans are registered as measured and, when both carry azimuth times and
            de-skewing is on, registered once more de-skewed with the velocity that first
            estimate gives.

    Returns:
        The motion estimate; check `ok` before using it.
    """
    cfg = OdometryConfig() if cfg is None else cfg
    ref_polar = preprocess_polar(prev, cfg.preprocess)
    cur_polar = preprocess_polar(cur, cfg.preprocess)
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
