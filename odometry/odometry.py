"""Keyframe radar odometry by phase correlation: the method, one scan at a time.

`Odometry(config).register(frame)` is called once per scan, in time order:

1. Condition the scan once (`preprocess`) and render it de-skewed at the running velocity,
   without the yaw-rate trend, to its mid-sweep pose (its *image pose*,
   `registration.PreparedScan`): there a velocity error only smears the image symmetrically.
2. Register its image against the keyframe's (`registration.register_images`, coarse and fine
   levels counting as one registration) seeded with the constant-velocity prediction. Unless
   that peak is far above the failure threshold, register again globally (rotation over the
   full circle, translation over the whole coarse image); the stronger peak wins. The prediction
   is a hint, never a veto, so a strong registration ends any run of failures.
3. Measure the velocity between the last two image poses. When it is far from the one the scan
   was rendered with (hard braking, a curvature change), re-render the scan at the measured
   velocity and register once more (`velocity.redeskewed`).
4. Otherwise, while the yaw rate changes, register the scan de-skewed with the bounded yaw-rate
   trend too and keep the stronger peak (`velocity.with_trend`): past motion cannot tell a
   turn that tightens from one that ends, the images can. A peak below half the previous scan's
   (a de-skew far off) has its de-skew yaw rate searched (`velocity.weak_searched`).
5. The pose at the scan's reference time (`OdometryResult.pose`) is its image pose moved by that
   velocity; the move's error does not accumulate. The covariance is the correlation peak's plus
   the terms the peak cannot show (`conversion_covariance`, `deskew_covariance`).
6. The scan becomes the keyframe when it has moved or turned far enough, when the peak weakens
   (overlap fading) or after `max_frames` scans.

When the keyframe cannot be registered the last registered scan is tried (it becomes the
keyframe); if that fails too the pose is the prediction, flagged as a gap (`ok=False`,
`gap=True`, a large covariance), and the keyframe stays for the next scan's global search. Only
the images fail a registration; a motion faster than a vehicle moves (`velocity.plausible_twist`),
or one across a gap that lands off the prediction, is kept but never becomes the velocity nor
re-renders the scan: the velocity from before is kept until two registered scans in a row
measure it again. Every scan counts its registrations (`OdometryResult.registrations`).
"""

from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from odometry import OdometryError
from odometry import velocity as motion_model
from odometry.config import OdometryConfig
from odometry.preprocess import (
    PolarScan,
    Scan,
    motion_from_twist,
    preprocess_polar,
    twist_from_motion,
)
from odometry.registration import MotionEstimate, PreparedScan, register_images
from odometry.velocity import (
    Velocity,
    agrees,
    bounded_twist,
    image_interval_s,
    image_time_ns,
    plausible_twist,
    pose_at_reference,
)
from raplace.se2 import between, compose, rotate_covariance
from raplace.units import NS_PER_S

logger = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
GAP_SIGMA_XY_M = 1.0
"""Standard deviation [m] of a prediction covering a failed registration (braking, with margin)."""
GAP_SIGMA_YAW_DEG = 5.0
"""The same for its rotation [deg] (a steering change over the interval)."""
KEYFRAME_QUALITY_FACTOR = 2.0
"""A peak below this multiple of `quality.min_peak_quality` makes a keyframe (overlap fading)."""
UNAMBIGUOUS_QUALITY_FACTOR = 3.0
"""A seeded registration peaking at this multiple of `quality.min_peak_quality` needs no global
one: the global search finds the same motion there (docs/decisions.md)."""
VELOCITY_LAG_FRACTION = 0.25
"""The error of the velocity that moves a pose to its reference time: this fraction of its last
change, per axis (it lags an accelerating or turning vehicle)."""
DESKEW_ERROR_FRACTION = 1.25
"""This multiple of a scan's bend by its lagging de-skew velocity (last change x half a sweep) is
the translation standard deviation."""


@dataclass(frozen=True)
class OdometryResult:
    """The odometry's output for one scan (`pose`'s world frame: the first scan's radar frame
    moved to `start_pose`; poses and motions (3,) are x, y [m], yaw [rad])."""

    index: int  # position of the scan in the sequence registered so far (0-based)
    timestamp_ns: int  # the scan's reference time [ns] (the time `pose` refers to)
    pose: FloatArray  # T_world_radar at `timestamp_ns`
    motion: FloatArray  # this scan's pose in the previous scan's frame (zeros for the first)
    # (3, 3) covariance [m^2, m rad, rad^2] of `keyframe_motion` in the previous scan's axes.
    covariance: FloatArray
    # The scan it was registered against: the keyframe, or the last registered scan when the
    # keyframe failed (itself for the first scan; the keyframe for a gap).
    keyframe_index: int
    keyframe_motion: FloatArray  # this scan's pose in that scan's frame
    is_keyframe: bool  # the scan is the keyframe for the scans that follow
    ok: bool  # the registration succeeded
    gap: bool  # the pose is a constant-velocity prediction covering a failed registration
    quality: float  # peak-to-noise ratio of the translation peak (0 for the first scan or a gap)
    reason: str = ""  # why the registration failed ("" when ok)
    registrations: int = 0  # image registrations (`registration.register_images`) run for it


@dataclass
class ScanNode:
    """A scan: its pose at its reference time and its image frame's (`image_pose`, world, which
    registrations chain); `conversion_covariance` (own axes): what that move adds to `pose`."""

    index: int
    pose: FloatArray
    image_pose: FloatArray
    scan: PreparedScan
    frames: int = 0
    gap: bool = False
    conversion_covariance: FloatArray = field(default_factory=lambda: np.zeros((3, 3)))


class Odometry:
    """Phase-correlation radar odometry over a scan stream (`start_pose`: (3,) T_world_radar)."""

    def __init__(
        self, config: OdometryConfig | None = None, start_pose: ArrayLike = (0.0, 0.0, 0.0)
    ) -> None:
        self.config = OdometryConfig() if config is None else config
        self.start_pose = np.asarray(start_pose, dtype=np.float64).reshape(3)
        self._keyframe: ScanNode | None = None
        self._previous: ScanNode | None = None
        self._last_registered: ScanNode | None = None  # the last scan that was not a gap
        self._velocity: Velocity | None = None
        self._history: list[OdometryResult] = []
        self._registrations = 0  # image registrations run for the scan being registered

    @property
    def results(self) -> list[OdometryResult]:
        """One result per registered scan, in order (as `register` returned them)."""
        return list(self._history)

    def result(self, index: int) -> OdometryResult:
        """Scan `index`'s result as in `results`, without copying the list."""
        return self._history[index]

    @property
    def poses(self) -> FloatArray:
        """(N, 3) T_world_radar of every registered scan (as in `results`)."""
        return np.array([r.pose for r in self.results]).reshape(-1, 3)

    @property
    def gaps(self) -> list[int]:
        """Indices of the scans whose pose is a constant-velocity prediction."""
        return [r.index for r in self.results if r.gap]

    @property
    def longest_gap_run(self) -> int:
        """The most consecutive gaps so far (more than 2 on driven data is a defect)."""
        runs = itertools.groupby(r.gap for r in self.results)
        return max((len(list(run)) for gap, run in runs if gap), default=0)

    @property
    def registrations_per_scan(self) -> float:
        """Mean `OdometryResult.registrations` of the scans after the first (0 before)."""
        return float(np.mean([r.registrations for r in self._history[1:]] or [0]))

    @property
    def keyframes(self) -> list[int]:
        """Indices of the scans that became keyframes."""
        return [r.index for r in self.results if r.is_keyframe]

    @property
    def velocity(self) -> FloatArray | None:
        """(3,) current body velocity estimate (vx, vy [m/s], yaw rate [rad/s]) or None."""
        if self._velocity is None or self._previous is None:
            return None
        return self._velocity_at(self._previous.scan.timestamp_ns)

    @property
    def prepared(self) -> PreparedScan | None:
        """The last scan's conditioned form and spectra, a gap's too (read-only), or None."""
        return None if self._previous is None else self._previous.scan

    def register(self, frame: Scan, polar: PolarScan | None = None) -> OdometryResult:
        """Register the next scan (`polar`: its `preprocess_polar` form, when the caller made it);
        returns its result (`motion` from the previous scan's pose). Raises `OdometryError` when
        the scan is malformed or not later than the previous one."""
        self._registrations = 0
        index = len(self._history)
        scan = self._prepare(frame, polar)
        previous, keyframe = self._previous, self._keyframe
        if keyframe is None or previous is None:
            return self._start(index, scan)
        dt_s = (scan.timestamp_ns - previous.scan.timestamp_ns) / NS_PER_S
        if dt_s <= 0:
            raise OdometryError(
                f"scan {index} at {scan.timestamp_ns} ns is not later than the previous scan at "
                f"{previous.scan.timestamp_ns} ns"
            )
        predicted = self._predicted_image_pose(previous, scan, dt_s)
        reference, estimate = keyframe, self._registered(keyframe, scan, predicted)
        fallback = self._fallback()
        if not estimate.ok and fallback is not None:
            logger.info("scan %d: keyframe %d failed (%s)", index, keyframe.index, estimate.reason)
            reference, estimate = fallback, self._registered(fallback, scan, predicted)
        if not estimate.ok:
            return self._gap(index, scan, predicted, estimate)
        return self._accept(index, scan, reference, estimate, dt_s)

    def _fallback(self) -> ScanNode | None:
        """The last registered scan, tried when the keyframe fails (None: it is the keyframe)."""
        return None if self._last_registered is self._keyframe else self._last_registered

    def _prepare(self, frame: Scan, polar: PolarScan | None) -> PreparedScan:
        """Condition a scan (unless given) and render it, de-skewed at the running velocity."""
        cfg = self.config
        polar = preprocess_polar(frame, cfg.preprocess) if polar is None else polar
        twist = None
        if self._velocity is not None and cfg.deskew:
            mid_ns = polar.timestamp_ns + int(round((polar.mid_sweep_s or 0.0) * NS_PER_S))
            twist = self._velocity_at(mid_ns, trend=False)
        return PreparedScan(polar, twist, cfg)

    def _start(self, index: int, scan: PreparedScan) -> OdometryResult:
        """The first scan: placed at `start_pose`, the first keyframe."""
        node = ScanNode(index, self.start_pose.copy(), self.start_pose.copy(), scan)
        self._keyframe = self._previous = self._last_registered = node
        return self._record(node, np.zeros((3, 3)), node, 0.0)

    def _predicted_image_pose(
        self, previous: ScanNode, scan: PreparedScan, dt_s: float
    ) -> FloatArray | None:
        """The image pose (world) the constant-velocity model expects for `scan`, or None."""
        if self._velocity is None:
            return None
        twist = bounded_twist(self._velocity.twist, self.config)
        interval_s = image_interval_s(previous.scan, scan, dt_s)
        return compose(previous.image_pose, motion_from_twist(twist, interval_s))

    def _registered(
        self, reference: ScanNode, scan: PreparedScan, predicted: FloatArray | None
    ) -> MotionEstimate:
        """`scan`'s image registered against `reference`'s seeded with the prediction and, unless
        that peak is unambiguous, globally too: the stronger peak wins (a hint, never a veto)."""
        cfg = self.config
        seeded = None
        if predicted is not None:
            hint = between(reference.image_pose, predicted)
            seeded = self._register_images(reference.scan, scan, cfg, hint=hint)
            unambiguous = UNAMBIGUOUS_QUALITY_FACTOR * cfg.quality.min_peak_quality
            if seeded.ok and seeded.quality >= unambiguous:
                return seeded
        found = self._register_images(reference.scan, scan, cfg)
        if seeded is not None and seeded.ok and (not found.ok or seeded.quality > found.quality):
            return seeded
        return found

    def _accept(
        self, index: int, scan: PreparedScan, ref: ScanNode, estimate: MotionEstimate, dt_s: float
    ) -> OdometryResult:
        """Place `scan` by its registration against `ref`; update the velocity and keyframe."""
        cfg, previous, keyframe = self.config, self._previous, self._keyframe
        assert previous is not None and keyframe is not None
        if self._velocity is None:
            self._place_first_images(ref, scan, estimate.motion)
        base = ref if previous.gap else previous  # a gap's pose is a guess
        interval_s = image_interval_s(
            base.scan, scan, (scan.timestamp_ns - base.scan.timestamp_ns) / NS_PER_S
        )
        image_pose, change = compose(ref.image_pose, estimate.motion), np.zeros(3)
        # A motion faster than a vehicle moves, or across a gap that hid more than the
        # prediction allows, is no velocity: the one from before is kept.
        measured = twist_from_motion(between(base.image_pose, image_pose), interval_s)
        predicted = self._predicted_image_pose(previous, scan, dt_s) if previous.gap else None
        smooth = predicted is None or agrees(image_pose, predicted)
        if self._velocity is None or (smooth and plausible_twist(measured, cfg)):
            scan, estimate = self._rerendered(ref, scan, estimate, measured)
            image_pose = compose(ref.image_pose, estimate.motion)
            change = self._update_velocity(base, scan, image_pose, interval_s)
        else:
            logger.info("scan %d: no velocity measured since scan %d; kept", index, base.index)
        velocity = self._velocity
        assert velocity is not None
        twist = self._velocity_at((image_time_ns(scan) + scan.timestamp_ns) // 2)
        pose = pose_at_reference(image_pose, twist, scan.image_time_s)
        step_s = image_interval_s(previous.scan, scan, dt_s)
        conversion = conversion_covariance(estimate.covariance, change, scan.image_time_s, step_s)
        node = ScanNode(index, pose, image_pose, scan, conversion_covariance=conversion)
        registration = estimate.covariance + deskew_covariance(change, scan)
        covariance = factor_covariance(registration, ref, node, previous)
        kcfg, motion = cfg.keyframe, estimate.motion
        new_keyframe = bool(
            ref is not keyframe
            or np.hypot(motion[0], motion[1]) >= kcfg.max_translation_m
            or abs(motion[2]) >= np.deg2rad(kcfg.max_rotation_deg)
            or estimate.quality < KEYFRAME_QUALITY_FACTOR * cfg.quality.min_peak_quality
            or keyframe.frames + 1 >= kcfg.max_frames
        )
        if new_keyframe:
            node.scan = motion_model.refreshed(node.scan, velocity, cfg)
            self._keyframe = node
        else:
            keyframe.frames += 1
            if keyframe.scan.twist is None:  # rendered before any velocity was known
                keyframe.scan = motion_model.refreshed(keyframe.scan, velocity, cfg)
        self._previous = self._last_registered = node
        return self._record(node, covariance, ref, estimate.quality)

    def _rerendered(
        self, ref: ScanNode, scan: PreparedScan, estimate: MotionEstimate, measured: FloatArray
    ) -> tuple[PreparedScan, MotionEstimate]:
        """The scan's de-skew after steps 3-4 of the module docstring (`measured`: (3,) twist)."""
        velocity, cfg, register = self._velocity, self.config, self._register_images
        if velocity is None:
            return scan, estimate
        rendered = motion_model.redeskewed(ref.scan, (scan, estimate), measured, cfg, register)
        if rendered[0] is scan:  # the velocity held: the yaw-rate trend may still win
            rendered = motion_model.with_trend(ref.scan, scan, estimate, velocity, cfg, register)
        last_quality = self._history[-1].quality
        return motion_model.weak_searched(ref.scan, rendered, last_quality, cfg, register)

    def _register_images(self, *args: Any, **kwargs: Any) -> MotionEstimate:
        """`registration.register_images`, counted in the scan's result (`registrations`)."""
        self._registrations += 1
        return register_images(*args, **kwargs)

    def _place_first_images(self, ref: ScanNode, scan: PreparedScan, motion: FloatArray) -> None:
        """Place the image frames of the scans registered before any velocity was known (their
        poses are fixed; where their mid-sweep images were seen from needs the velocity)."""
        dt_s = (scan.timestamp_ns - ref.scan.timestamp_ns) / NS_PER_S
        twist = twist_from_motion(motion, image_interval_s(ref.scan, scan, dt_s))
        for node in {id(n): n for n in (self._keyframe, self._previous, ref) if n}.values():
            node.image_pose = compose(node.pose, motion_from_twist(twist, node.scan.image_time_s))

    def _velocity_at(self, time_ns: int, trend: bool = True) -> FloatArray:
        """`velocity.expected_twist` of the running velocity at `time_ns`."""
        assert self._velocity is not None
        return motion_model.expected_twist(self._velocity, time_ns, self.config, trend)

    def _update_velocity(
        self, base: ScanNode, scan: PreparedScan, image_pose: FloatArray, interval_s: float
    ) -> FloatArray:
        """Measure the twist from `base`'s image pose to `image_pose`; returns its change (or 0)."""
        twist = twist_from_motion(between(base.image_pose, image_pose), interval_s)
        centre_ns = (image_time_ns(base.scan) + image_time_ns(scan)) // 2
        if self._velocity is None:
            self._velocity = Velocity(twist=twist, time_ns=centre_ns)
            return np.zeros(3)
        change = twist - self._velocity.twist
        self._velocity = self._velocity.updated(twist, centre_ns)
        return change

    def _gap(
        self, index: int, scan: PreparedScan, predicted: FloatArray | None, failed: MotionEstimate
    ) -> OdometryResult:
        """Cover a failed registration with the constant-velocity prediction; the keyframe stays."""
        previous, keyframe = self._previous, self._keyframe
        assert previous is not None and keyframe is not None
        if predicted is None:  # no velocity yet
            pose, image_pose = previous.pose.copy(), previous.pose.copy()
        else:
            twist = self._velocity_at((image_time_ns(scan) + scan.timestamp_ns) // 2)
            pose, image_pose = pose_at_reference(predicted, twist, scan.image_time_s), predicted
        logger.warning("scan %d: registration failed (%s); gap", index, failed.reason)
        sigma_yaw = np.deg2rad(GAP_SIGMA_YAW_DEG)
        covariance = np.diag([GAP_SIGMA_XY_M**2, GAP_SIGMA_XY_M**2, sigma_yaw**2])
        node = ScanNode(index, pose, image_pose, scan, gap=True)
        self._previous = node
        return self._record(node, covariance, keyframe, 0.0, failed.reason)

    def _record(
        self, node: ScanNode, cov: FloatArray, keyframe: ScanNode, quality: float, reason: str = ""
    ) -> OdometryResult:
        """Append and return `node`'s result against `keyframe` (`reason`: why a gap failed)."""
        history = self._history
        motion = between(history[-1].pose, node.pose) if history else np.zeros(3)
        result = OdometryResult(
            index=node.index,
            timestamp_ns=node.scan.timestamp_ns,
            pose=np.asarray(node.pose, dtype=np.float64),
            motion=np.asarray(motion, dtype=np.float64),
            covariance=np.asarray(cov, dtype=np.float64),
            keyframe_index=keyframe.index,
            keyframe_motion=np.asarray(between(keyframe.pose, node.pose), dtype=np.float64),
            is_keyframe=self._keyframe is node,
            ok=not node.gap,
            gap=node.gap,
            quality=float(quality),
            reason=reason,
            registrations=self._registrations,
        )
        history.append(result)
        return result


def conversion_covariance(
    registration: FloatArray, change: ArrayLike, image_time_s: float, interval_s: float
) -> FloatArray:
    """(3, 3) covariance (scan axes) of moving the image pose by the velocity over `image_time_s`
    [s]: that of two image poses `interval_s` [s] apart (twice `registration` over the interval
    squared) lagging by `VELOCITY_LAG_FRACTION` of its last `change` (3,) [m/s, m/s, rad/s]."""
    if image_time_s == 0.0 or interval_s <= 0:
        return np.zeros((3, 3))
    lag = VELOCITY_LAG_FRACTION * np.asarray(change, dtype=float)
    velocity_covariance = 2.0 * registration / interval_s**2 + np.diag(lag * lag)
    return image_time_s**2 * velocity_covariance


def deskew_covariance(velocity_change: ArrayLike, scan: PreparedScan) -> FloatArray:
    """(3, 3) isotropic translation covariance [m^2] of the bend of a scan de-skewed with a
    velocity lagging by its last change `velocity_change` (3,) [m/s, m/s, rad/s]."""
    timing = scan.polar.timing
    half_sweep_s = 0.0 if timing is None else 0.5 * scan.polar.n_azimuths * timing.row_period_s
    bend = half_sweep_s * np.abs(np.asarray(velocity_change, dtype=float))
    sigma_xy_sq = DESKEW_ERROR_FRACTION**2 * float(bend[0] ** 2 + bend[1] ** 2)
    return np.diag([sigma_xy_sq, sigma_xy_sq, 0.0])


def factor_covariance(
    registration: FloatArray, reference: ScanNode, node: ScanNode, previous: ScanNode
) -> FloatArray:
    """(3, 3) covariance (`previous`'s axes) of the factor from `previous` to `node`: the
    `registration` against `reference` (axes of its image pose) plus both scans'
    `conversion_covariance` (own axes)."""
    in_reference_axes = rotate_covariance(
        registration, float(between(reference.pose, reference.image_pose)[2])
    ) + rotate_covariance(node.conversion_covariance, float(between(reference.pose, node.pose)[2]))
    previous_turn = float(between(previous.pose, reference.pose)[2])
    return rotate_covariance(in_reference_axes, previous_turn) + previous.conversion_covariance
