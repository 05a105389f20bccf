"""Keyframe radar odometry by phase correlation: the method, one scan at a time.

`Odometry(config).register(frame)` is called once per scan, in time order:

1. Condition the scan once (`preprocess`) and render it de-skewed at the running velocity,
   without the yaw-rate trend, to its mid-sweep pose (its *image pose*,
   `registration.PreparedScan`): there a velocity error only smears the image symmetrically.
2. Register its image against the keyframe's (`registration.register_images`, coarse and fine
   levels counting as one registration): globally, rotation over the full circle and translation
   over the whole coarse image. When that fails or disagrees with the constant-velocity
   prediction, register again seeded with the prediction; the stronger correlation wins. The
   prediction is a hint, never a veto, so a strong registration ends any run of failures.
3. Measure the velocity between the last two image poses. When it is far from the one the scan
   was rendered with (hard braking, a curvature change), re-render the scan at the measured
   velocity and register once more (`deskew_choice.redeskewed`).
4. Otherwise, while the yaw rate changes, register the scan de-skewed with the bounded yaw-rate
   trend too and keep the de-skew that correlates more strongly (`deskew_choice.with_trend`):
   past motion cannot tell a turn that tightens from one that ends, the images can. A peak far
   weaker than the previous scan's (a de-skew far off, e.g. through a yaw-rate reversal) has its
   de-skew yaw rate searched by peak quality (`deskew_choice.weak_searched`).
5. The pose at the scan's reference time (`OdometryResult.pose`) is its image pose moved by that
   velocity; the move's error does not accumulate. The covariance is the correlation peak's
   plus the terms the peak cannot show (`uncertainty`).
6. The scan becomes the keyframe when it has moved or turned far enough, when the peak weakens
   (overlap fading) or after `max_frames` scans.

Recovery (`recovery`): when the keyframe cannot be registered, the last registered scan, the
earlier keyframes and then the previous scan are tried; if all fail, the pose is the prediction,
flagged as a gap (`ok=False`, `gap=True`, a large covariance) and the keyframe stays, so the next
scan tries it first, globally. Only the images fail a registration; a motion faster than a
vehicle moves is kept but never becomes the velocity. Every scan counts its registrations
(`OdometryResult.registrations`).
"""

from __future__ import annotations

import logging

import numpy as np
from numpy.typing import ArrayLike, NDArray

from odometry import OdometryError, deskew_choice, recovery
from odometry.config import OdometryConfig
from odometry.deskew import motion_from_twist, twist_from_motion
from odometry.history import OdometryResult
from odometry.preprocess import preprocess_polar
from odometry.reference_time import (
    image_interval_s,
    image_time_ns,
    move_centre_ns,
    pose_at_reference,
    seconds_to_ns,
)
from odometry.registration import MotionEstimate, PreparedScan, register_images
from odometry.scan import Scan
from odometry.state import OdometryState, ScanNode
from odometry.uncertainty import conversion_covariance, deskew_covariance, factor_covariance
from odometry.velocity import (
    Velocity,
    bounded_twist,
)
from raplace.se2 import between, compose
from raplace.units import NS_PER_S

logger = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
GAP_SIGMA_XY_M = 1.0
"""Standard deviation [m] of a constant-velocity prediction that covers a failed registration
(a few m/s^2 of braking or acceleration over a 4 Hz interval, with margin)."""
GAP_SIGMA_YAW_DEG = 5.0
"""The same for its rotation [deg] (a steering change over the interval)."""
KEYFRAME_QUALITY_FACTOR = 2.0
"""A registration whose peak quality falls below this multiple of the failure threshold
(`quality.min_peak_quality`) makes the scan the keyframe: the overlap with the keyframe is
fading, and the next scans should not fail against it."""
FALLBACK_KEYFRAMES = 2
"""Earlier keyframes tried, most recent first, before the previous scan when the keyframe and
the last registered scan cannot be registered (a gap's pose is only a prediction;
`odometry.recovery`)."""


class Odometry:
    """Phase-correlation radar odometry over a stream of scans.

    Args:
        config: odometry settings (defaults when None).
        start_pose: (3,) T_world_radar of the first scan.
    """

    def __init__(
        self, config: OdometryConfig | None = None, start_pose: ArrayLike = (0.0, 0.0, 0.0)
    ) -> None:
        self.config = OdometryConfig() if config is None else config
        self.start_pose = np.asarray(start_pose, dtype=np.float64).reshape(3)
        self._state = OdometryState()

    # -- results ------------------------------------------------------------------------------
    @property
    def results(self) -> list[OdometryResult]:
        """One result per registered scan, in order (as `register` returned them)."""
        return list(self._state.history)

    def result(self, index: int) -> OdometryResult:
        """Scan `index`'s result as in `results`, without copying the list."""
        return self._state.history[index]

    @property
    def poses(self) -> FloatArray:
        """(N, 3) T_world_radar of every registered scan (as in `results`)."""
        return np.array([r.pose for r in self.results]).reshape(-1, 3)

    @property
    def timestamps_ns(self) -> NDArray[np.int64]:
        """(N,) reference times of the registered scans [ns]."""
        return np.array([r.timestamp_ns for r in self.results], dtype=np.int64)

    @property
    def gaps(self) -> list[int]:
        """Indices of the scans whose pose is a constant-velocity prediction."""
        return [r.index for r in self.results if r.gap]

    @property
    def longest_gap_run(self) -> int:
        """The most consecutive gaps so far (more than 2 on driven data is a defect)."""
        best = run = 0
        for result in self.results:
            run = run + 1 if result.gap else 0
            best = max(best, run)
        return best

    @property
    def registrations_per_scan(self) -> float:
        """Image registrations (`OdometryResult.registrations`) per scan after the first, on
        average (0 before the second scan)."""
        counts = [r.registrations for r in self.results[1:]]
        return float(np.mean(counts)) if counts else 0.0

    @property
    def keyframes(self) -> list[int]:
        """Indices of the scans that became keyframes."""
        return [r.index for r in self.results if r.is_keyframe]

    @property
    def velocity(self) -> FloatArray | None:
        """(3,) current body velocity estimate (vx, vy [m/s], yaw rate [rad/s]) or None."""
        state = self._state
        if state.velocity is None or state.previous is None:
            return None
        return self._velocity_at(state.previous.scan.timestamp_ns)

    @property
    def prepared(self) -> PreparedScan | None:
        """The last registered scan's conditioned form with the spectra made so far (shared:
        treat as read-only), or None before the first scan."""
        previous = self._state.previous
        return None if previous is None else previous.scan

    def reset(self) -> None:
        """Forget every scan (the next one starts again at `start_pose`)."""
        self._state = OdometryState()

    # -- the per-frame step -------------------------------------------------------------------
    def register(self, frame: Scan) -> OdometryResult:
        """Register the next scan; returns its result: its pose and how it was obtained,
        `motion` from the previous scan's pose.

        Raises:
            OdometryError: the scan is malformed or not later than the previous one.
        """
        state = self._state
        state.registrations = 0
        index = len(state.history)
        scan = self._prepare(frame)
        previous = state.previous
        if state.keyframe is None or previous is None:
            return self._start(index, scan)
        dt_s = (scan.timestamp_ns - previous.scan.timestamp_ns) / NS_PER_S
        if dt_s <= 0:
            raise OdometryError(
                f"scan {index} at {scan.timestamp_ns} ns is not later than the previous scan at "
                f"{previous.scan.timestamp_ns} ns"
            )
        predicted = self._predicted_image_pose(previous, scan, dt_s)
        reference, estimate = self._search(index, scan, predicted)
        if reference is None:
            return self._gap(index, scan, predicted, estimate)
        return self._accept(index, scan, reference, estimate, dt_s)

    # -- steps ---------------------------------------------------------------------------------
    def _prepare(self, frame: Scan) -> PreparedScan:
        """Condition a scan and render it, de-skewed at the running velocity without its trend."""
        state, cfg = self._state, self.config
        polar = preprocess_polar(frame, cfg.preprocess)
        twist = None
        if state.velocity is not None and cfg.deskew:
            twist = self._velocity_at(
                polar.timestamp_ns + seconds_to_ns(polar.mid_sweep_s or 0.0), trend=False
            )
        return PreparedScan(polar, twist, cfg)

    def _start(self, index: int, scan: PreparedScan) -> OdometryResult:
        """The first scan: placed at `start_pose`, the first keyframe."""
        state = self._state
        start = self.start_pose.copy()
        node = ScanNode(index=index, pose=start, image_pose=start.copy(), scan=scan)
        state.keyframe = state.previous = state.last_registered = node
        return self._record(
            node,
            motion=np.zeros(3),
            covariance=np.zeros((3, 3)),
            reference=node,
            reference_motion=np.zeros(3),
            is_keyframe=True,
            ok=True,
            quality=0.0,
        )

    def _predicted_image_pose(
        self, previous: ScanNode, scan: PreparedScan, dt_s: float
    ) -> FloatArray | None:
        """The image pose (world) the constant-velocity model expects for `scan` (None before
        any velocity is known)."""
        velocity = self._state.velocity
        if velocity is None:
            return None
        twist = bounded_twist(velocity.twist, self.config)
        return compose(
            previous.image_pose,
            motion_from_twist(twist, image_interval_s(previous.scan, scan, dt_s)),
        )

    def _references(self) -> list[ScanNode]:
        """Scans to register against, in order (`recovery.fallback_references`)."""
        state = self._state
        return recovery.fallback_references(
            state.keyframe, state.last_registered, state.earlier_keyframes, state.previous
        )

    def _search(
        self, index: int, scan: PreparedScan, predicted: FloatArray | None
    ) -> tuple[ScanNode | None, MotionEstimate]:
        """The reference `scan` registers against and the estimate (`recovery.chosen`; None
        and the last failed estimate when none does)."""
        tried = []
        for reference in self._references():
            estimate = self._registered(reference, scan, predicted)
            tried.append((reference, estimate))
            if estimate.ok:
                break
            logger.info(
                "scan %d: registration against scan %d failed (%s)",
                index,
                reference.index,
                estimate.reason,
            )
        return recovery.chosen(tried)

    def _registered(
        self, reference: ScanNode, scan: PreparedScan, predicted: FloatArray | None
    ) -> MotionEstimate:
        """Register `scan`'s image against `reference`'s: globally, and when that fails or
        disagrees with the prediction also seeded with the prediction; the stronger correlation
        wins (see the module docstring)."""
        cfg = self.config
        estimate = self._register_images(reference.scan, scan, cfg)
        if predicted is None:
            return estimate
        expected = between(reference.image_pose, predicted)
        if estimate.ok and recovery.agrees(estimate.motion, expected, self.config):
            return estimate
        seeded = self._register_images(reference.scan, scan, cfg, hint=expected)
        if seeded.ok and (not estimate.ok or seeded.quality > estimate.quality):
            logger.debug(
                "scan against %d: seeded estimate %s (quality %.1f) beats %s (%.1f%s)",
                reference.index,
                np.round(seeded.motion, 3),
                seeded.quality,
                np.round(estimate.motion, 3),
                estimate.quality,
                "" if estimate.ok else f", {estimate.reason}",
            )
            return seeded
        return estimate

    def _accept(
        self,
        index: int,
        scan: PreparedScan,
        reference: ScanNode,
        estimate: MotionEstimate,
        dt_s: float,
    ) -> OdometryResult:
        """Place `scan` by its registration against `reference` and update the velocity and the
        keyframe."""
        state = self._state
        previous, keyframe = state.previous, state.keyframe
        assert previous is not None and keyframe is not None
        if state.velocity is None:
            self._place_first_images(reference, scan, estimate.motion)
        # A gap's pose is a guess: measure the velocity from a registered scan instead.
        base = reference if previous.gap and reference is not previous else previous
        interval_s = image_interval_s(
            base.scan, scan, (scan.timestamp_ns - base.scan.timestamp_ns) / NS_PER_S
        )
        image_pose, change = compose(reference.image_pose, estimate.motion), np.zeros(3)
        # A motion faster than a vehicle moves, or across a gap that hid more than the
        # prediction allows, is no velocity: the one from before is kept (recovery.py).
        measured = twist_from_motion(between(base.image_pose, image_pose), interval_s)
        predicted = self._predicted_image_pose(previous, scan, dt_s) if previous.gap else None
        smooth = predicted is None or recovery.agrees(image_pose, predicted, self.config)
        if state.velocity is None or (smooth and recovery.plausible_twist(measured, self.config)):
            scan, estimate = self._rerendered(reference, base, scan, estimate, interval_s)
            image_pose = compose(reference.image_pose, estimate.motion)
            change = self._update_velocity(base, scan, image_pose, interval_s)
        else:
            logger.info("scan %d: no velocity measured since scan %d; kept", index, base.index)
        pose = self._reference_pose(image_pose, scan)
        interval_s = image_interval_s(previous.scan, scan, dt_s)
        node = ScanNode(
            index=index,
            pose=pose,
            image_pose=image_pose,
            scan=scan,
            conversion_covariance=conversion_covariance(
                estimate.covariance, change, scan.image_time_s, interval_s
            ),
        )
        covariance = self._factor_covariance(previous, reference, node, estimate, change)
        new_keyframe = reference is not keyframe or self._needs_keyframe(estimate, keyframe)
        if new_keyframe:
            node.scan = deskew_choice.refreshed(node.scan, state.velocity, self.config)
            state.earlier_keyframes = recovery.remembered_keyframes(
                state.earlier_keyframes, keyframe, FALLBACK_KEYFRAMES
            )
            state.keyframe = node
        else:
            keyframe.frames += 1
            if keyframe.scan.twist is None:  # rendered before any velocity was known
                keyframe.scan = deskew_choice.refreshed(keyframe.scan, state.velocity, self.config)
        state.previous = state.last_registered = node
        return self._record(
            node,
            motion=between(previous.pose, pose),
            covariance=covariance,
            reference=reference,
            reference_motion=between(reference.pose, pose),
            is_keyframe=new_keyframe,
            ok=True,
            quality=estimate.quality,
        )

    def _rerendered(
        self,
        reference: ScanNode,
        base: ScanNode,
        scan: PreparedScan,
        estimate: MotionEstimate,
        interval_s: float,
    ) -> tuple[PreparedScan, MotionEstimate]:
        """The scan's de-skew after steps 3 and 4 of the module docstring: re-de-skewed at the
        velocity measured since `base` (`interval_s` [s] before) when far from the rendered one,
        else the yaw-rate trend where it correlates more strongly; then a weak peak searched."""
        velocity, cfg, register = self._state.velocity, self.config, self._register_images
        rendered = deskew_choice.redeskewed(
            reference, base, (scan, estimate), interval_s, velocity, cfg, register
        )
        if rendered[0] is scan:  # the velocity held: the yaw-rate trend may still win
            rendered = deskew_choice.with_trend(reference, scan, estimate, velocity, cfg, register)
        if velocity is None:
            return rendered
        last_quality = self._state.history[-1].quality
        return deskew_choice.weak_searched(reference, rendered, last_quality, cfg, register)

    def _factor_covariance(
        self,
        previous: ScanNode,
        reference: ScanNode,
        node: ScanNode,
        estimate: MotionEstimate,
        change: FloatArray,
    ) -> FloatArray:
        """The covariance of `node`'s result (in `previous`'s axes)."""
        registration_covariance = estimate.covariance + deskew_covariance(change, node.scan)
        return factor_covariance(
            registration_covariance,
            reference.pose,
            reference.image_pose,
            node.pose,
            node.conversion_covariance,
            float(between(previous.pose, reference.pose)[2]),
            previous.conversion_covariance,
        )

    # -- helpers ------------------------------------------------------------------------------
    def _register_images(
        self,
        reference: PreparedScan,
        scan: PreparedScan,
        cfg: OdometryConfig,
        hint: FloatArray | None = None,
    ) -> MotionEstimate:
        """`registration.register_images`, counted in the scan's result (`registrations`)."""
        self._state.registrations += 1
        return register_images(reference, scan, cfg, hint)

    def _place_first_images(
        self, reference: ScanNode, scan: PreparedScan, image_motion: FloatArray
    ) -> None:
        """Place the image frames of the scans registered before any velocity was known.

        Their poses are fixed (the first is `start_pose`), but where their images were seen
        from (mid-sweep, when used) needs the velocity, which the first registration gives.
        """
        state = self._state
        dt_s = (scan.timestamp_ns - reference.scan.timestamp_ns) / NS_PER_S
        twist = twist_from_motion(image_motion, image_interval_s(reference.scan, scan, dt_s))
        for node in {id(n): n for n in (state.keyframe, state.previous, reference) if n}.values():
            node.image_pose = compose(node.pose, motion_from_twist(twist, node.scan.image_time_s))

    def _velocity_at(self, time_ns: int, trend: bool = True) -> FloatArray:
        """`deskew_choice.expected_twist` of the running velocity at `time_ns`."""
        assert self._state.velocity is not None
        return deskew_choice.expected_twist(self._state.velocity, time_ns, self.config, trend)

    def _update_velocity(
        self, base: ScanNode, scan: PreparedScan, image_pose: FloatArray, interval_s: float
    ) -> FloatArray:
        """Measure the twist between `base`'s image pose and this scan's (`interval_s` apart);
        returns its change from the last measurement (zeros for the first)."""
        state = self._state
        twist = twist_from_motion(between(base.image_pose, image_pose), interval_s)
        centre_ns = (image_time_ns(base.scan) + image_time_ns(scan)) // 2
        if state.velocity is None:
            state.velocity = Velocity(twist=twist, time_ns=centre_ns)
            return np.zeros(3)
        change = twist - state.velocity.twist
        state.velocity = state.velocity.updated(twist, centre_ns)
        return change

    def _reference_pose(self, image_pose: FloatArray, scan: PreparedScan) -> FloatArray:
        """T_world_radar at the scan's reference time from its image pose, with the velocity
        expected between the two times."""
        assert self._state.velocity is not None
        twist = self._velocity_at(move_centre_ns(scan))
        return pose_at_reference(image_pose, twist, scan.image_time_s)

    def _needs_keyframe(self, estimate: MotionEstimate, keyframe: ScanNode) -> bool:
        kcfg = self.config.keyframe
        return bool(
            np.hypot(estimate.dx, estimate.dy) >= kcfg.max_translation_m
            or abs(estimate.dyaw) >= np.deg2rad(kcfg.max_rotation_deg)
            or estimate.quality < KEYFRAME_QUALITY_FACTOR * self.config.quality.min_peak_quality
            or keyframe.frames + 1 >= kcfg.max_frames
        )

    def _gap(
        self,
        index: int,
        scan: PreparedScan,
        predicted: FloatArray | None,
        failed: MotionEstimate,
    ) -> OdometryResult:
        """Cover a failed registration with the constant-velocity prediction."""
        state = self._state
        previous = state.previous
        assert previous is not None
        if predicted is None or state.velocity is None:
            # No velocity yet: the prediction is standing still, flagged.
            pose, image_pose = previous.pose.copy(), previous.pose.copy()
        else:
            pose, image_pose = self._reference_pose(predicted, scan), predicted
        logger.warning(
            "scan %d: registration failed (%s); constant-velocity gap", index, failed.reason
        )
        motion = between(previous.pose, pose)
        sigma_yaw = np.deg2rad(GAP_SIGMA_YAW_DEG)
        covariance = np.diag([GAP_SIGMA_XY_M**2, GAP_SIGMA_XY_M**2, sigma_yaw**2])
        node = ScanNode(index=index, pose=pose, image_pose=image_pose, scan=scan, gap=True)
        state.previous = node  # the keyframe stays: the next scan tries it first
        keyframe = state.keyframe
        assert keyframe is not None
        return self._record(
            node,
            motion=motion,
            covariance=covariance,
            reference=keyframe,
            reference_motion=between(keyframe.pose, pose),
            is_keyframe=False,
            ok=False,
            quality=0.0,
            reason=failed.reason,
            gap=True,
        )

    def _record(
        self,
        node: ScanNode,
        *,
        motion: FloatArray,
        covariance: FloatArray,
        reference: ScanNode,
        reference_motion: FloatArray,
        is_keyframe: bool,
        ok: bool,
        quality: float,
        reason: str = "",
        gap: bool = False,
    ) -> OdometryResult:
        """Append and return the result of scan `node` (registered against `reference`)."""
        result = OdometryResult(
            index=node.index,
            timestamp_ns=node.scan.timestamp_ns,
            pose=np.asarray(node.pose, dtype=np.float64),
            motion=np.asarray(motion, dtype=np.float64),
            covariance=np.asarray(covariance, dtype=np.float64),
            keyframe_index=reference.index,
            keyframe_motion=np.asarray(reference_motion, dtype=np.float64),
            is_keyframe=is_keyframe,
            ok=ok,
            gap=gap,
            quality=float(quality),
            reason=reason,
            registrations=self._state.registrations,
        )
        self._state.history.append(result)
        return result
