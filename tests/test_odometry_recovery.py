"""Odometry that never loses its way: large motions, the prediction as a hint, recovery.

Scans are rendered by the simulator in the `tiny` town (1024 bins, 61 m) from poses of our
choosing, with motion distortion, so every answer is known: single pairs with motions up to 15 m
and 45 deg (1 Hz), drives whose velocity jumps (the constant-velocity prediction is far off),
a U-turn and a three-point turn (reverse gear at full lock) driven at 1 Hz, and sequences with
unregistrable scans injected. The simulated manoeuvre drives at 1 Hz are checked for what the
odometry must do on them (no long gap, the turn kept); their drift figures are benchmarks
(docs/benchmarks.md), not test bars.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from test_odometry_sim import render

import odometry.odometry as odometry_module
from odometry import OdometryConfig, estimate_motion
from odometry.odometry import Odometry, ScanNode
from odometry.preprocess import motion_from_twist, twist_from_motion
from odometry.registration import (
    MotionEstimate,
    PreparedScan,
    prepare,
    register,
    register_images,
)
from odometry.velocity import Velocity, bounded_twist, plausible_twist, with_trend
from radar_slam.datasets import open_sequence
from radar_slam.datasets.frame import RadarFrame
from radar_slam.datasets.stride import strided
from radar_slam.sim.generate import Scene, build_scene, make_renderer
from radar_slam.sim.render import RenderTables
from radar_slam.sim.scenarios import get_scenario
from raplace import se2
from raplace.units import NS_PER_S

FloatArray = NDArray[np.float64]
LARGE_ERROR_M = 0.1
LARGE_ERROR_DEG = 0.5
START_S = (4.0, 9.5)
"""Where along the `tiny` route the scenes start [s]."""
LARGE_MOTIONS = (  # dx [m], dy [m], dyaw [deg] over one second (a 4 Hz sensor at --stride 4)
    (12.0, 0.5, 40.0),
    (-8.0, 3.0, -45.0),
    (15.0, 0.0, 10.0),
)
SMEARED_ERROR_DEG = 1.0
"""The same pair without sweep times (they no longer match the motion): not de-skewed, each image
is smeared by its sweep's turn and the rotation is off by about half a degree."""
MAX_GAP_RUN = 2
MAX_DRIVE_ERROR_FRACTION = 0.02
"""End-point error of the short drives below, as a fraction of the distance driven."""
FINE_CELL_M = OdometryConfig().fine.cell_m
"""The fine image level's pixel size [m]: the drives' position bar."""
MAX_STEP_HEADING_DEG = 2.5
"""Heading error [deg] of a scan whose sweep starts a new yaw rate (up to 35 deg/s more than the
velocity it was de-skewed with, 8.75 deg of the sweep's turn not undone: 1.4-1.8 deg measured);
the scans after it are back within LARGE_ERROR_DEG."""
MAX_TURN_ERROR_DEG = 3.0
"""Error [deg] of the whole heading change of a simulated manoeuvre at 1 Hz (180 deg turned
round, 90 deg of junction turns; 1.2-1.5 deg measured)."""


@pytest.fixture(scope="module")
def tiny_scene() -> tuple[Scene, RenderTables]:
    scene = build_scene(get_scenario("tiny"))
    return scene, make_renderer(scene).tables


def errors(estimate: FloatArray, truth: FloatArray) -> tuple[float, float]:
    """Translation [m] and rotation [deg] error of an estimated motion."""
    diff = se2.between(truth, estimate)
    return float(np.hypot(diff[0], diff[1])), float(np.rad2deg(abs(diff[2])))


def large_pair(
    scene: Scene, tables: RenderTables, start_s: float, motion: FloatArray
) -> tuple[RadarFrame, RadarFrame]:
    """Two distorted scans one second apart, the second after `motion` at a constant twist."""
    twist = twist_from_motion(motion, 1.0)
    first = scene.trajectory.radar_poses(np.array([start_s]))[0]
    a = render(scene, tables, first, start_s, twist, seed=1)
    b = render(scene, tables, se2.compose(first, motion), start_s + 1.0, twist, seed=2)
    return a, b


@pytest.mark.parametrize("start_s", START_S)
@pytest.mark.parametrize("case", LARGE_MOTIONS)
def test_large_motion_is_recovered(
    tiny_scene: tuple[Scene, RenderTables], start_s: float, case: tuple[float, float, float]
) -> None:
    """Up to 15 m and 45 deg between scans: the rotation comes from the full circle, the
    translation from the whole coarse image, both de-skewed from the scans alone."""
    scene, tables = tiny_scene
    motion = np.array([case[0], case[1], np.deg2rad(case[2])])
    a, b = large_pair(scene, tables, start_s, motion)
    estimate = estimate_motion(a, b)
    assert estimate.ok, estimate.reason
    error_m, error_deg = errors(estimate.motion, motion)
    assert error_m <= LARGE_ERROR_M and error_deg <= LARGE_ERROR_DEG, (error_m, error_deg)


def test_a_motion_faster_than_a_vehicle_is_not_vetoed(
    tiny_scene: tuple[Scene, RenderTables],
) -> None:
    """The kinematic limits never fail a registration: 15 m in a tenth of a second (150 m/s,
    beyond `QualityConfig.max_speed_mps`) is what the images show, and it is returned ok."""
    scene, tables = tiny_scene
    motion = np.array([15.0, 0.0, np.deg2rad(10.0)])
    a, b = large_pair(scene, tables, START_S[0], motion)
    b = dataclasses.replace(b, timestamp_ns=a.timestamp_ns + NS_PER_S // 10)
    b = dataclasses.replace(b, azimuth_times_ns=None)
    a = dataclasses.replace(a, azimuth_times_ns=None)
    assert not plausible_twist(twist_from_motion(motion, 0.1), OdometryConfig())
    estimate = estimate_motion(a, b)
    assert estimate.ok, estimate.reason
    error_m, error_deg = errors(estimate.motion, motion)
    assert error_m <= LARGE_ERROR_M and error_deg <= SMEARED_ERROR_DEG, (error_m, error_deg)


def test_a_hint_narrows_the_search_but_does_not_overrule(
    tiny_scene: tuple[Scene, RenderTables],
) -> None:
    """Seeded with the truth, the registration finds it; seeded 3 m and 8 deg off, it finds a
    weaker peak than the global search, which is what `Odometry` keeps."""
    scene, tables = tiny_scene
    motion = np.array([12.0, 0.5, np.deg2rad(40.0)])
    a, b = large_pair(scene, tables, START_S[0], motion)
    cfg = OdometryConfig()
    twist = twist_from_motion(motion, 1.0)
    ref, cur = prepare(a, cfg, twist), prepare(b, cfg, twist)
    glob = register_images(ref, cur, cfg)
    right = register_images(ref, cur, cfg, hint=glob.motion + np.array([0.4, -0.3, 0.02]))
    wrong = register_images(ref, cur, cfg, hint=glob.motion + np.array([-3.0, 0.0, 0.14]))
    assert glob.ok and right.ok
    np.testing.assert_allclose(right.motion, glob.motion, atol=0.02)
    assert not wrong.ok or wrong.quality < glob.quality
    assert not wrong.ok or errors(wrong.motion, glob.motion)[0] > 0.5


def drive(
    scene: Scene,
    tables: RenderTables,
    start_s: float,
    legs: list[tuple[float, FloatArray]],
    period_s: float,
) -> tuple[list[RadarFrame], FloatArray]:
    """Scans every `period_s` along legs of (duration [s], body twist (vx, vy, yaw rate)) from
    the `tiny` route's pose at `start_s`; returns the scans and their true poses (first at 0).
    Leg durations are multiples of `period_s`, so that no sweep straddles two legs."""
    first = scene.trajectory.radar_poses(np.array([start_s]))[0]
    bounds = np.cumsum([0.0] + [d for d, _ in legs])
    times = np.arange(0.0, bounds[-1] + 1e-9, period_s)
    poses, pose, t_prev = [], np.zeros(3), 0.0
    for t in times:
        while t_prev < t - 1e-12:  # integrate leg by leg up to t
            leg = min(int(np.searchsorted(bounds, t_prev, side="right")) - 1, len(legs) - 1)
            step = min(t, bounds[leg + 1]) - t_prev
            pose = se2.compose(pose, motion_from_twist(legs[leg][1], step))
            t_prev += step
        poses.append(pose)
    frames = []
    for k, (t, p) in enumerate(zip(times, poses, strict=True)):
        # A sweep ends at t: it was measured in the leg that holds the instants before t.
        leg = max(int(np.searchsorted(bounds, t, side="left")) - 1, 0)
        world = se2.compose(first, p)
        frames.append(render(scene, tables, world, start_s + t, legs[leg][1], seed=10 + k))
    return frames, np.array(poses)


def run(frames: list[RadarFrame], config: OdometryConfig | None = None) -> Odometry:
    odometry = Odometry(config)
    for frame in frames:
        odometry.register(frame)
    return odometry


def end_error_fraction(odometry: Odometry, truth: FloatArray) -> float:
    end = se2.between(truth[-1], odometry.poses[-1])
    distance = float(np.sum(np.hypot(*np.diff(truth[:, :2], axis=0).T)))
    return float(np.hypot(end[0], end[1])) / distance


def test_velocity_jumps_do_not_veto_good_registrations(
    tiny_scene: tuple[Scene, RenderTables],
) -> None:
    """Hard braking then a turn that swings the other way: the prediction is metres and tens of
    degrees off, the images decide, and no scan becomes a gap."""
    scene, tables = tiny_scene
    legs = [
        (2.0, np.array([9.0, 0.0, np.deg2rad(25.0)])),
        (1.0, np.array([2.0, 0.0, np.deg2rad(-30.0)])),
        (2.0, np.array([10.0, 0.0, np.deg2rad(-20.0)])),
    ]
    frames, truth = drive(scene, tables, START_S[0], legs, period_s=0.5)
    odometry = run(frames)
    assert odometry.gaps == []
    assert end_error_fraction(odometry, truth) <= MAX_DRIVE_ERROR_FRACTION


def test_u_turn_at_one_hertz(tiny_scene: tuple[Scene, RenderTables]) -> None:
    """A U-turn (radius 5 m, 36 deg per scan) and back, one scan a second."""
    scene, tables = tiny_scene
    legs = [
        (3.0, np.array([8.0, 0.0, 0.0])),
        (5.0, np.array([np.pi, 0.0, np.pi / 5.0])),
        (3.0, np.array([8.0, 0.0, 0.0])),
    ]
    frames, truth = drive(scene, tables, START_S[1], legs, period_s=1.0)
    odometry = run(frames)
    assert odometry.gaps == []
    assert end_error_fraction(odometry, truth) <= MAX_DRIVE_ERROR_FRACTION
    assert errors(odometry.poses[-1], truth[-1])[1] <= 1.0


def blank(frame: RadarFrame) -> RadarFrame:
    """An unregistrable scan at the same time (a sensor dropout)."""
    return dataclasses.replace(frame, polar=np.zeros_like(frame.polar))


@pytest.mark.parametrize("failures", [1, 2])
def test_recovery_after_injected_failures(
    tiny_scene: tuple[Scene, RenderTables], failures: int
) -> None:
    """`failures` dropouts in a turn at 2 Hz: exactly that many gaps, and the first good scan
    after them registers (against the keyframe before the gap) and ends the gap."""
    scene, tables = tiny_scene
    legs = [
        (1.0, np.array([8.0, 0.0, np.deg2rad(10.0)])),
        (4.0, np.array([7.0, 0.0, np.deg2rad(-25.0)])),
    ]
    frames, truth = drive(scene, tables, START_S[0], legs, period_s=0.5)
    dropped = range(5, 5 + failures)
    frames = [blank(f) if k in dropped else f for k, f in enumerate(frames)]
    odometry = run(frames)
    assert odometry.gaps == list(dropped)
    assert odometry.longest_gap_run <= MAX_GAP_RUN
    after = odometry.results[dropped[-1] + 1]
    assert after.ok and after.keyframe_index < dropped[0]
    # The scan after the gap is placed by its registration, not by the gap's prediction.
    error_m, error_deg = errors(after.pose, truth[after.index])
    assert error_m <= 0.3 and error_deg <= 1.0, (error_m, error_deg)
    assert end_error_fraction(odometry, truth) <= MAX_DRIVE_ERROR_FRACTION


def test_the_last_registered_scan_stands_in_for_a_failed_keyframe(
    tiny_scene: tuple[Scene, RenderTables],
) -> None:
    """When the keyframe cannot be registered (forced here for one scan), the last registered
    scan, nearer in time, is tried: no gap, the pose is measured and that scan's successor
    becomes the keyframe."""
    scene, tables = tiny_scene
    legs = [(4.0, np.array([8.0, 0.0, np.deg2rad(10.0)]))]
    frames, truth = drive(scene, tables, START_S[0], legs, period_s=0.5)
    plain = run(frames)
    failing = next(k for k in range(4, len(frames)) if not plain.results[k - 1].is_keyframe)

    class KeyframeFails(Odometry):
        def _registered(
            self, reference: ScanNode, scan: PreparedScan, predicted: FloatArray | None
        ) -> MotionEstimate:
            estimate = super()._registered(reference, scan, predicted)
            if len(self.results) == failing and reference is self._keyframe:
                return dataclasses.replace(estimate, ok=False, reason="forced")
            return estimate

    odometry = KeyframeFails()
    for frame in frames:
        odometry.register(frame)
    result = odometry.results[failing]
    assert result.ok and result.is_keyframe and odometry.gaps == []
    assert result.keyframe_index == failing - 1
    error_m, error_deg = errors(result.pose, truth[failing])
    assert error_m <= 0.3 and error_deg <= 1.0, (error_m, error_deg)


def test_the_motion_model_is_bounded() -> None:
    """Leaving a turn (yaw rate 0.3 -> 0.1 rad/s in 0.25 s), the trend never predicts the turn
    to swing the other way nor to change by more than it last did; twists stay plausible."""
    leaving = Velocity(twist=np.array([8.0, 0.0, 0.3]), time_ns=0).updated(
        np.array([8.0, 0.0, 0.1]), 250_000_000
    )
    soon = leaving.at(250_000_000 + 125_000_000, trend_gain=1.0)
    assert soon[2] == pytest.approx(0.0, abs=1e-12)  # 0.1 - 0.1: down to zero, not below
    for later_s in (0.5, 1.0, 5.0):
        later = leaving.at(250_000_000 + int(later_s * 1e9), trend_gain=1.0)
        assert 0.0 <= later[2] <= 0.1
    assert leaving.at(10**10, trend_gain=0.0)[2] == pytest.approx(0.1)
    entering = Velocity(twist=np.array([8.0, 0.0, 0.1]), time_ns=0).updated(
        np.array([8.0, 0.0, 0.2]), 250_000_000
    )
    assert entering.at(10**10, trend_gain=1.0)[2] == pytest.approx(0.3)  # at most +0.1 more
    cfg = OdometryConfig()
    wild = bounded_twist(np.array([80.0, 60.0, 10.0]), cfg)
    assert np.hypot(wild[0], wild[1]) == pytest.approx(cfg.quality.max_speed_mps)
    assert wild[2] == pytest.approx(np.deg2rad(cfg.quality.max_yaw_rate_dps))


def test_a_turn_ending_just_past_zero_yaw_rate_is_not_extrapolated_into_a_reversal() -> None:
    """At 1 Hz a turn ends within one interval: 0.45 rad/s, then -0.005 rad/s (noise around
    zero). The trend must not carry that change on to a turn the other way; a yaw rate that
    grows past zero (a swing to the other side) is held as measured, one that stays within a
    straight road's noise around zero is not extrapolated either; a turn starting from that noise
    (-0.02 rad/s), or a yaw rate measured over a 4 Hz interval (too short for a whole turn exit),
    keeps its trend."""
    ended = Velocity(twist=np.array([8.0, 0.0, 0.45]), time_ns=0).updated(
        np.array([8.0, 0.0, -0.005]), 1_000_000_000
    )
    for later_s in (0.125, 0.5, 1.0):
        later = ended.at(1_000_000_000 + int(later_s * 1e9), trend_gain=1.0)
        assert later[2] == 0.0
    swinging = Velocity(twist=np.array([8.0, 0.0, 0.1]), time_ns=0).updated(
        np.array([8.0, 0.0, -0.3]), 1_000_000_000
    )
    assert swinging.at(1_500_000_000, trend_gain=1.0)[2] == pytest.approx(-0.3)
    starting = Velocity(twist=np.array([8.0, 0.0, -0.02]), time_ns=0).updated(
        np.array([8.0, 0.0, 0.3]), 1_000_000_000
    )
    assert starting.at(1_500_000_000, trend_gain=1.0)[2] == pytest.approx(0.46)  # + 0.32 / 2
    wobbling = Velocity(twist=np.array([8.0, 0.0, 0.02]), time_ns=0).updated(
        np.array([8.0, 0.0, -0.01]), 1_000_000_000
    )
    assert wobbling.at(1_500_000_000, trend_gain=1.0)[2] == 0.0  # noise across zero: no turn
    quick = Velocity(twist=np.array([8.0, 0.0, 0.45]), time_ns=0).updated(
        np.array([8.0, 0.0, -0.005]), 250_000_000
    )
    assert quick.at(250_000_000 + 125_000_000, trend_gain=1.0)[2] == pytest.approx(-0.2325)


def test_a_three_point_turn_at_one_hertz(tiny_scene: tuple[Scene, RenderTables]) -> None:
    """Forward at full lock (radius 5.5 m, 31 deg per scan), reverse gear on the other lock (the
    heading keeps turning while the car backs), forward again, one scan a second: 250 deg in
    all. Every scan registers within one fine pixel of its true position; its heading is within
    `LARGE_ERROR_DEG` but for the first scan of each new yaw rate (`MAX_STEP_HEADING_DEG`), and
    so is the whole turn."""
    scene, tables = tiny_scene
    full_lock_m = 5.5
    legs = [
        (2.0, np.array([4.0, 0.0, 0.0])),
        (3.0, np.array([3.0, 0.0, 3.0 / full_lock_m])),
        (3.0, np.array([-2.0, 0.0, 2.0 / full_lock_m])),
        (3.0, np.array([3.0, 0.0, 3.0 / full_lock_m])),
        (2.0, np.array([4.0, 0.0, 0.0])),
    ]
    frames, truth = drive(scene, tables, START_S[0], legs, period_s=1.0)
    odometry = run(frames)
    assert odometry.gaps == []
    pose_errors = np.array([errors(odometry.poses[k], truth[k]) for k in range(len(frames))])
    assert pose_errors[:, 0].max() <= FINE_CELL_M, pose_errors
    starts_a_yaw_rate = np.cumsum([d for d, _ in legs[:-1]]).astype(int) + 1
    settled = np.setdiff1d(np.arange(len(frames)), starts_a_yaw_rate)
    assert pose_errors[settled, 1].max() <= LARGE_ERROR_DEG, pose_errors
    assert pose_errors[:, 1].max() <= MAX_STEP_HEADING_DEG, pose_errors
    turned = np.unwrap(odometry.poses[:, 2]) - np.unwrap(truth[:, 2])
    assert abs(np.rad2deg(turned[-1] - turned[0])) <= LARGE_ERROR_DEG


def driven(synthetic_root: Path, scenario: str, stride: int) -> tuple[Odometry, FloatArray]:
    """The odometry over every `stride`-th scan of `synthetic/<scenario>` and the ground truth
    of those scans (world frame)."""
    sequence = strided(open_sequence(f"synthetic/{scenario}", synthetic_root), stride)
    truth = sequence.ground_truth
    assert truth is not None
    return run([sequence[k] for k in range(len(sequence))]), truth


@pytest.mark.parametrize(
    ("scenario", "turned_deg"),
    [("tiny_turn_around", 180.0), ("tiny_three_point_turn", 180.0), ("tiny_junction_turns", 90.0)],
)
def test_hard_driving_at_one_hertz_keeps_the_turn(
    synthetic_root: Path, scenario: str, turned_deg: float
) -> None:
    """The driving manoeuvres (reduced bins) at --stride 4 (1 Hz; up to 35 deg between scans):
    turn-arounds, reverse gear at full lock, curvature steps. No run of more than 2 gaps, and
    the heading change from the first scan to the last is the true one."""
    odometry, truth = driven(synthetic_root, scenario, stride=4)
    assert odometry.longest_gap_run <= MAX_GAP_RUN
    true_turn = np.rad2deg(np.unwrap(truth[:, 2]))
    estimated_turn = np.rad2deg(np.unwrap(odometry.poses[:, 2]))
    assert abs(true_turn[-1] - true_turn[0]) == pytest.approx(turned_deg, abs=1.0)
    error = (estimated_turn[-1] - estimated_turn[0]) - (true_turn[-1] - true_turn[0])
    assert abs(error) <= MAX_TURN_ERROR_DEG, error


@pytest.mark.parametrize(("before_dps", "during_dps"), [(20.0, 60.0), (10.0, 40.0)])
def test_the_images_pick_the_yaw_rate_trend_where_it_matches_the_sweep(
    tiny_scene: tuple[Scene, RenderTables], before_dps: float, during_dps: float
) -> None:
    """A turn that tightens (the yaw rate measured at `before_dps`, still rising): the scan
    de-skewed with the bounded trend correlates more strongly than at constant velocity, is
    kept, and its rotation error is at most 0.6 of the constant-velocity one's."""
    scene, tables = tiny_scene
    cfg = OdometryConfig()
    start_s = START_S[0]
    start = scene.trajectory.radar_poses(np.array([start_s]))[0]
    before = np.array([8.0, 0.0, np.deg2rad(before_dps)])
    during = np.array([8.0, 0.0, np.deg2rad(during_dps)])
    truth = motion_from_twist(during, 0.25)
    first = render(scene, tables, start, start_s, before, seed=1)
    second = render(scene, tables, se2.compose(start, truth), start_s + 0.25, during, seed=2)
    reference = prepare(first, cfg, before)
    rising = np.deg2rad(during_dps - before_dps) / 2.0  # the last change, over 0.25 s
    velocity = Velocity(before, int(round((start_s - 0.125) * NS_PER_S)), rising, 0.25)
    constant = prepare(second, cfg, before)
    estimate = register_images(reference, constant, cfg)
    kept, kept_estimate = with_trend(reference, constant, estimate, velocity, cfg)
    assert kept is not constant and kept.twist is not None and kept.twist[2] > before[2]
    assert kept_estimate.quality > estimate.quality
    constant_error = errors(register(reference, constant, cfg).motion, truth)
    trend_error = errors(register(reference, kept, cfg).motion, truth)
    assert trend_error[1] <= 0.6 * constant_error[1], (trend_error, constant_error)
    assert trend_error[0] <= constant_error[0], (trend_error, constant_error)


def test_a_steady_drive_needs_one_seeded_registration_per_scan(
    tiny_scene: tuple[Scene, RenderTables], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Where the constant-velocity prediction holds, the registration seeded with it is
    unambiguous and no global search runs: one registration per scan, seeded, once the velocity
    is known (the first two scans measure it)."""
    scene, tables = tiny_scene
    legs = [(4.0, np.array([8.0, 0.0, np.deg2rad(6.0)]))]
    frames, truth = drive(scene, tables, START_S[0], legs, period_s=0.25)
    searches: list[tuple[int, bool]] = []

    def recorded(*args: Any, hint: FloatArray | None = None) -> MotionEstimate:
        searches.append((len(odometry.results), hint is None))
        return register_images(*args, hint=hint)

    monkeypatch.setattr(odometry_module, "register_images", recorded)
    odometry = Odometry()
    for frame in frames:
        odometry.register(frame)
    steady = [is_global for scan, is_global in searches if scan >= 3]
    assert steady == [False] * (len(frames) - 3)
    assert end_error_fraction(odometry, truth) < 0.01
