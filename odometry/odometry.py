"""Keyframe-based radar odometry: the thin stateful wrapper around `registration`.

`Odometry(config).register(frame)` is called once per scan, in time order. Each scan is registered
against the current keyframe (fewer, longer registrations drift less than chaining every pair);
the scan becomes the new keyframe when it has moved or turned far enough from the keyframe, when
the correlation peak weakens (overlap fading), or after `max_frames` scans. Scans are de-skewed
with the running velocity (constant-velocity model over the sweep).

A failed registration (weak peak, implausible or off-prediction motion) is retried against the
previous scan (which then becomes the reference and the scan the new keyframe); if that fails
too, the pose comes from the constant-velocity prediction, the result says so (`ok=False`,
`gap=True`, a large covariance), and the keyframe stays, so the next scan tries it first. The
motion is never silently set to zero.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from odometry import OdometryError
from odometry.config import OdometryConfig
from odometry.deskew import motion_from_twist, twist_from_motion
from odometry.preprocess import preprocess_polar
from odometry.registration import MotionEstimate, PreparedScan, register
from odometry.scan import Scan
from odometry.se2 import between, compose

logger = logging.getLogger(__name__)

NS_PER_S = 1e9
FloatArray = NDArray[np.float64]
TWIST_REFRESH_MPS = 0.25
"""A new keyframe is re-rendered when its de-skew velocity is off by more than this [m/s]."""
TWIST_REFRESH_RADPS = np.deg2rad(2.0)
"""... or its yaw rate by more than this [rad/s]."""


@dataclass(frozen=True)
class OdometryResult:
    """The odometry's output for one scan.

    Attributes:
        index: position of the scan in the sequence registered so far (0-based).
        timestamp_ns: the scan's reference time [ns] (the time `pose` refers to).
        pose: (3,) T_world_radar (x, y [m], yaw [rad]) at `timestamp_ns`; the world frame is the
            first scan's radar frame moved to `start_pose`.
        motion: (3,) this scan's pose in the previous scan's frame (zeros for the first scan).
        covariance: (3, 3) covariance of `motion` [m^2, m rad, rad^2], order (x, y, yaw).
        keyframe_index: index of the scan it was registered against (the keyframe, or the
            previous scan after a failure; itself for the first scan; the keyframe for a gap).
        keyframe_motion: (3,) this scan's pose in that scan's frame.
        is_keyframe: the scan is the keyframe for the scans that follow.
        ok: the registration succeeded.
        gap: the pose is a constant-velocity prediction covering a failed registration.
        quality: peak-to-noise ratio of the translation peak (0 for the first scan or a gap).
        reason: why the registration failed ("" when ok).
    """

    index: int
    timestamp_ns: int
    pose: FloatArray
    motion: FloatArray
    covariance: FloatArray
    keyframe_index: int
    keyframe_motion: FloatArray
    is_keyframe: bool
    ok: bool
    gap: bool
    quality: float
    reason: str = ""


@dataclass
class _Keyframe:
    index: int
    pose: FloatArray
    scan: PreparedScan
    frames: int = 0


@dataclass
class _State:
    keyframe: _Keyframe | None = None
    previous: _Keyframe | None = None  # the previous scan (same fields as a keyframe)
    twist: FloatArray | None = None  # running body velocity (vx, vy, yaw rate)
    results: list[OdometryResult] = field(default_factory=list)


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
        self._state = _State()

    # -- results ------------------------------------------------------------------------------
    @property
    def results(self) -> list[OdometryResult]:
        """One result per registered scan, in order."""
        return list(self._state.results)

    @property
    def poses(self) -> FloatArray:
        """(N, 3) T_world_radar of every registered scan."""
        return np.array([r.pose for r in self._state.results]).reshape(-1, 3)

    @property
    def timestamps_ns(self) -> NDArray[np.int64]:
        """(N,) reference times of the registered scans [ns]."""
        return np.array([r.timestamp_ns for r in self._state.results], dtype=np.int64)

    @property
    def gaps(self) -> list[int]:
        """Indices of the scans whose pose is a constant-velocity prediction."""
        return [r.index for r in self._state.results if r.gap]

    @property
    def keyframes(self) -> list[int]:
        """Indices of the scans that became keyframes."""
        return [r.index for r in self._state.results if r.is_keyframe]

    @property
    def velocity(self) -> FloatArray | None:
        """(3,) current body velocity estimate (vx, vy [m/s], yaw rate [rad/s]) or None."""
        return None if self._state.twist is None else self._state.twist.copy()

    def reset(self) -> None:
        """Forget every scan (the next one starts again at `start_pose`)."""
        self._state = _State()

    # -- the per-frame step -------------------------------------------------------------------
    def register(self, frame: Scan) -> OdometryResult:
        """Register the next scan; returns its pose and how it was obtained.

        Raises:
            OdometryError: the scan is malformed or not later than the previous one.
        """
        state, cfg = self._state, self.config
        index = len(state.results)
        twist = state.twist if cfg.deskew.enabled else None
        scan = PreparedScan(preprocess_polar(frame, cfg.preprocess), twist, cfg)

        if state.keyframe is None or state.previous is None:
            node = _Keyframe(index=index, pose=self.start_pose.copy(), scan=scan)
            state.keyframe = state.previous = node
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

        previous = state.previous
        dt_s = (int(frame.timestamp_ns) - previous.scan.timestamp_ns) / NS_PER_S
        if dt_s <= 0:
            raise OdometryError(
                f"scan {index} at {frame.timestamp_ns} ns is not later than the previous scan at "
                f"{previous.scan.timestamp_ns} ns"
            )
        predicted = None
        if state.twist is not None:
            predicted = compose(previous.pose, motion_from_twist(state.twist, dt_s))

        keyframe = state.keyframe
        references = [keyframe] if previous is keyframe else [keyframe, previous]
        estimate = None
        for reference in references:
            estimate = self._checked(register(reference.scan, scan, cfg), reference, predicted)
            if estimate.ok:
                break
            logger.info(
                "scan %d: registration against scan %d failed (%s)",
                index,
                reference.index,
                estimate.reason,
            )
        assert estimate is not None
        if not estimate.ok:
            return self._gap(index, scan, dt_s, predicted, estimate)

        pose = compose(reference.pose, estimate.motion)
        motion = between(previous.pose, pose)
        covariance = _rotate_covariance(estimate.covariance, between(previous.pose, reference.pose))
        state.twist = twist_from_motion(motion, dt_s)
        node = _Keyframe(index=index, pose=pose, scan=scan)
        new_keyframe = reference is not keyframe or self._needs_keyframe(estimate, keyframe)
        if new_keyframe:
            node.scan = self._refreshed(node.scan)
            state.keyframe = node
        else:
            keyframe.frames += 1
            if keyframe.scan.twist is None:  # rendered before any velocity was known
                keyframe.scan = self._refreshed(keyframe.scan)
        state.previous = node
        return self._record(
            node,
            motion=motion,
            covariance=covariance,
            reference=reference,
            reference_motion=estimate.motion,
            is_keyframe=new_keyframe,
            ok=True,
            quality=estimate.quality,
        )

    # -- helpers ------------------------------------------------------------------------------
    def _checked(
        self, estimate: MotionEstimate, reference: _Keyframe, predicted: FloatArray | None
    ) -> MotionEstimate:
        """Reject an estimate far from the constant-velocity prediction (direction of travel)."""
        if not estimate.ok or predicted is None:
            return estimate
        qcfg = self.config.quality
        expected = between(reference.pose, predicted)
        off = estimate.motion - expected
        off_yaw = abs(float(np.arctan2(np.sin(off[2]), np.cos(off[2]))))
        if np.hypot(off[0], off[1]) <= qcfg.max_prediction_error_m and off_yaw <= np.deg2rad(
            qcfg.max_prediction_error_deg
        ):
            return estimate
        reason = (
            f"motion {np.round(estimate.motion, 3)} is off the constant-velocity prediction "
            f"{np.round(expected, 3)}"
        )
        return dataclasses.replace(estimate, ok=False, reason=reason)

    def _needs_keyframe(self, estimate: MotionEstimate, keyframe: _Keyframe) -> bool:
        kcfg = self.config.keyframe
        return bool(
            np.hypot(estimate.dx, estimate.dy) >= kcfg.max_translation_m
            or abs(estimate.dyaw) >= np.deg2rad(kcfg.max_rotation_deg)
            or estimate.quality < kcfg.min_peak_quality
            or keyframe.frames + 1 >= kcfg.max_frames
        )

    def _refreshed(self, scan: PreparedScan) -> PreparedScan:
        """Re-render a new keyframe whose de-skew velocity is stale (e.g. the first scans)."""
        new = self._state.twist if self.config.deskew.enabled else None
        used = scan.twist
        if new is None or scan.polar.timing is None:
            return scan
        if used is not None and (
            np.hypot(*(new[:2] - used[:2])) <= TWIST_REFRESH_MPS
            and abs(new[2] - used[2]) <= TWIST_REFRESH_RADPS
        ):
            return scan
        return PreparedScan(scan.polar, new, self.config)

    def _gap(
        self,
        index: int,
        scan: PreparedScan,
        dt_s: float,
        predicted: FloatArray | None,
        failed: MotionEstimate,
    ) -> OdometryResult:
        """Cover a failed registration with the constant-velocity prediction."""
        state, qcfg = self._state, self.config.quality
        previous = state.previous
        assert previous is not None
        if predicted is None:  # no velocity yet: the prediction is standing still, flagged
            predicted = previous.pose.copy()
        logger.warning(
            "scan %d: registration failed (%s); constant-velocity gap", index, failed.reason
        )
        motion = between(previous.pose, predicted)
        sigma_yaw = np.deg2rad(qcfg.gap_sigma_yaw_deg)
        covariance = np.diag([qcfg.gap_sigma_xy_m**2, qcfg.gap_sigma_xy_m**2, sigma_yaw**2])
        node = _Keyframe(index=index, pose=predicted, scan=scan)
        state.previous = node  # the keyframe stays: the next scan tries it first
        keyframe = state.keyframe
        assert keyframe is not None
        return self._record(
            node,
            motion=motion,
            covariance=covariance,
            reference=keyframe,
            reference_motion=between(keyframe.pose, predicted),
            is_keyframe=False,
            ok=False,
            quality=0.0,
            reason=failed.reason,
            gap=True,
        )

    def _record(
        self,
        node: _Keyframe,
        *,
        motion: FloatArray,
        covariance: FloatArray,
        reference: _Keyframe,
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
        )
        self._state.results.append(result)
        return result


def _rotate_covariance(covariance: FloatArray, keyframe_in_previous: FloatArray) -> FloatArray:
    """A keyframe-to-scan covariance (keyframe axes) turned into the previous scan's axes.

    Used as the covariance of the previous-to-current motion: conservative, since it ignores
    that registrations against the same keyframe share its errors (which partly cancel).
    """
    pose = keyframe_in_previous
    c, s = np.cos(pose[2]), np.sin(pose[2])
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return rot @ covariance @ rot.T
