"""The loop detector's de-skew twist: the odometry's velocity at the middle of each scan's sweep,
interpolated between the steps before and after the scan (known constant-curvature motion with
a linearly rising speed, at the full and a quarter of the scan rate)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from odometry import OdometryResult
from odometry.config import OdometryConfig
from odometry.preprocess import twist_from_motion
from radar_slam.datasets.frame import RadarSequence
from radar_slam.loops import KeyScan, LoopClosureConfig, LoopDetector, Verification
from radar_slam.loops.sweep_twist import (
    scan_sweep_twist,
    step_twist,
    step_velocities,
    sweep_twist,
)
from raplace.retrieval import Candidate
from raplace.se2 import between
from raplace.units import NS_PER_S

SWEEP_S = 0.25
SPEED_0_MPS = 4.0
ACCELERATION_MPS2 = 1.0
CURVATURE_PER_M = 0.05
T0_NS = 1_000 * NS_PER_S
LIMITS = OdometryConfig()


def arc_pose(t_s: float) -> np.ndarray:
    """(3,) pose at `t_s` on a circle of curvature `CURVATURE_PER_M`, speed rising linearly."""
    s = SPEED_0_MPS * t_s + 0.5 * ACCELERATION_MPS2 * t_s**2
    yaw = CURVATURE_PER_M * s
    return np.array([np.sin(yaw), 1.0 - np.cos(yaw), 0.0]) / CURVATURE_PER_M + [0.0, 0.0, yaw]


def true_sweep_twist(t_s: float) -> np.ndarray:
    """The body twist at `t_s`: forward at the speed, turning at curvature x speed."""
    speed = SPEED_0_MPS + ACCELERATION_MPS2 * t_s
    return np.array([speed, 0.0, CURVATURE_PER_M * speed])


def step(a_s: float, b_s: float) -> np.ndarray:
    return between(arc_pose(a_s), arc_pose(b_s))


def ns(t_s: float) -> int:
    return T0_NS + round(t_s * NS_PER_S)


def twists_around(t_s: float, period_s: float) -> tuple:
    """The step velocities before and after a scan at `t_s` scanned every `period_s`."""
    before = step_twist(step(t_s - period_s, t_s), ns(t_s - period_s), ns(t_s), LIMITS)
    after = step_twist(step(t_s, t_s + period_s), ns(t_s), ns(t_s + period_s), LIMITS)
    assert before.plausible and after.plausible
    return before.velocity, after.velocity


@pytest.mark.parametrize("t_s", [3.0, 6.0])
def test_sweep_twist_at_one_hertz_is_the_velocity_mid_sweep(t_s: float) -> None:
    # Scans stamped at the end of their sweep (MulRan, synthetic), one a second.
    period_s = 1.0
    before, after = twists_around(t_s, period_s)
    mid_sweep_s = t_s - SWEEP_S / 2
    twist = sweep_twist(before, after, ns(mid_sweep_s))
    assert twist is not None
    np.testing.assert_allclose(twist, true_sweep_twist(mid_sweep_s), atol=1e-6)
    # The step before the scan (the old de-skew twist) lags the sweep by 3/8 s.
    backward = twist_from_motion(step(t_s - period_s, t_s), period_s)
    lag_mps = 3 / 8 * ACCELERATION_MPS2
    assert backward[0] == pytest.approx(true_sweep_twist(mid_sweep_s)[0] - lag_mps, abs=1e-6)


def test_sweep_twist_at_the_full_rate_is_the_step_before() -> None:
    period_s = SWEEP_S
    t_s = 5.0
    before, after = twists_around(t_s, period_s)
    twist = sweep_twist(before, after, ns(t_s - SWEEP_S / 2))
    assert before is not None and twist is not None
    np.testing.assert_array_equal(twist, before.twist)
    np.testing.assert_allclose(twist, true_sweep_twist(t_s - SWEEP_S / 2), atol=1e-6)


def test_sweep_twist_of_a_mid_sweep_stamp_is_the_central_difference() -> None:
    # Oxford stamps the middle of the sweep: the mean acquisition time is the scan's own.
    period_s, t_s = 1.0, 4.0
    before, after = twists_around(t_s, period_s)
    twist = sweep_twist(before, after, ns(t_s))
    assert before is not None and after is not None
    np.testing.assert_allclose(twist, 0.5 * (before.twist + after.twist), atol=1e-12)
    np.testing.assert_allclose(twist, true_sweep_twist(t_s), atol=1e-6)


def test_an_implausible_step_is_not_used() -> None:
    period_s, t_s = 1.0, 4.0
    before = step_twist(step(t_s - period_s, t_s), ns(t_s - period_s), ns(t_s), LIMITS)
    jump = step_twist(np.array([80.0, 0.0, 0.0]), ns(t_s), ns(t_s + period_s), LIMITS)
    assert not jump.plausible and jump.velocity is None
    assert before.velocity is not None
    twist = sweep_twist(before.velocity, jump.velocity, ns(t_s - SWEEP_S / 2))
    np.testing.assert_array_equal(twist, before.velocity.twist)
    assert sweep_twist(None, None, ns(t_s)) is None


def odometry_run(times_s: list[float]) -> list[OdometryResult]:
    """Exact odometry results of scans at `times_s` on the accelerating arc."""
    results = []
    for n, t_s in enumerate(times_s):
        motion = np.zeros(3) if n == 0 else step(times_s[n - 1], t_s)
        results.append(
            OdometryResult(
                n,
                ns(t_s),
                arc_pose(t_s),
                motion,
                np.eye(3) * 1e-4,
                max(n - 1, 0),
                motion,
                True,
                True,
                False,
                10.0,
                "",
            )
        )
    return results


class SweptScan:
    """The timing of a scan stamped at the end of a 400-azimuth sweep (what the twist needs)."""

    def __init__(self, t_s: float) -> None:
        self.timestamp_ns = ns(t_s)
        offsets_s = (np.arange(400) + 0.5) / 400 * SWEEP_S - SWEEP_S
        self.azimuth_times_ns = ns(t_s) + np.round(offsets_s * NS_PER_S).astype(np.int64)


def test_a_whole_run_gives_each_scan_its_mid_sweep_twist() -> None:
    # What maps use: the twists of every scan of a finished run at 1 Hz.
    times_s = [2.0, 3.0, 4.0, 5.0]
    velocities = step_velocities(odometry_run(times_s), LIMITS)
    assert velocities[0] is None and all(v is not None for v in velocities[1:])
    for n in (1, 2):
        twist = scan_sweep_twist(velocities, n, SweptScan(times_s[n]))  # type: ignore[arg-type]
        np.testing.assert_allclose(twist, true_sweep_twist(times_s[n] - SWEEP_S / 2), atol=1e-6)
    # The last scan has no step after it: the step before, which lags its sweep by 3/8 s.
    last = scan_sweep_twist(velocities, 3, SweptScan(times_s[3]))  # type: ignore[arg-type]
    assert last is not None and velocities[3] is not None
    np.testing.assert_array_equal(last, velocities[3].twist)
    assert last[0] == pytest.approx(true_sweep_twist(times_s[3] - SWEEP_S / 2)[0] - 3 / 8, abs=1e-6)
    first = scan_sweep_twist(velocities, 0, SweptScan(times_s[0]))  # type: ignore[arg-type]
    assert first is not None and velocities[1] is not None
    np.testing.assert_array_equal(first, velocities[1].twist)


class EveryEntry:
    """A place database that proposes every earlier entry (the loop test needs no places)."""

    def __init__(self) -> None:
        self.keys: list[int] = []

    def add(self, descriptor: np.ndarray, key: int, time_s: float | None = None) -> None:
        self.keys.append(key)

    def query(self, descriptor: np.ndarray, k: int = 1, time_s: float | None = None):
        return [Candidate(key, i, 0.0, 0.0, np.pi) for i, key in enumerate(self.keys)][:1]


class Recorder:
    """A verifier that records the query scans it is given and rejects every proposal."""

    def __init__(self) -> None:
        self.queries: dict[int, KeyScan] = {}

    def __call__(self, query: KeyScan, match: KeyScan) -> Verification:
        self.queries[query.key] = query
        nan = np.full(3, np.nan)
        return Verification(False, "recorded", nan, np.full((3, 3), np.nan), nan, 0.0)


def test_detector_de_skews_each_scan_with_its_mid_sweep_velocity(tiny: RadarSequence) -> None:
    # Scans of the tiny drive re-timed to 1 Hz (each keeps its 0.25 s sweep ending at its stamp)
    # on the known arc: every query, the last one included, gets the velocity at mid-sweep.
    period_s, n = 1.0, 6
    recorder = Recorder()
    # every scan queries and every candidate is verified, however far apart on the arc
    cfg = LoopClosureConfig(query_spacing_m=0.0, odometry_drift_fraction=np.inf)
    detector = LoopDetector(cfg, recognizer=EveryEntry(), verifier=recorder)
    for k in range(n):
        frame = tiny[k]
        times = frame.azimuth_times_ns
        assert times is not None
        shift = ns(k * period_s) - frame.timestamp_ns
        scan = dataclasses.replace(
            frame, timestamp_ns=frame.timestamp_ns + shift, azimuth_times_ns=times + shift
        )
        assert detector.add(scan, arc_pose(k * period_s), k) == []
    assert detector.finish() == []
    assert sorted(recorder.queries) == list(range(1, n))  # scan 0 has nothing to match yet
    for k, query in recorder.queries.items():
        offset_s = float(np.mean(query.scan.azimuth_times_ns - query.timestamp_ns)) / NS_PER_S
        assert offset_s == pytest.approx(-SWEEP_S / 2, abs=0.01)
        expected = true_sweep_twist(k * period_s + offset_s)
        if k == n - 1:  # the last scan has no step after it: the step before
            expected = twist_from_motion(step(k - period_s, k), period_s)
        np.testing.assert_allclose(query.twist, expected, atol=1e-6)
        # the steps' middles the twist lies between are one period apart (none after the last)
        span = query.twist_span_s
        assert span is None if k == n - 1 else span == pytest.approx(period_s, abs=1e-6)
