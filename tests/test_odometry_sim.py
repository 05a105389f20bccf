"""The odometry against the simulator: known answers, and covariances on a short sequence.

Known answer: the `tiny` town (1024 bins, 61 m) rendered from a pose and again after a known
motion, once without motion distortion (every azimuth seen from one pose, scans without azimuth
times) and once with it (each azimuth seen from the pose at its own time under a constant
velocity, which `estimate_motion` has to estimate and undo). Covariances: the normalised errors
of the per-scan covariances over the first scans of `loop` (full MulRan geometry); the drift of
the simulated drives is a benchmark (docs/benchmarks.md), not a test bar.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from odometry import OdometryConfig, estimate_motion
from odometry.odometry import Odometry
from odometry.preprocess import motion_from_twist, twist_from_motion
from radar_slam.datasets.frame import RadarFrame
from radar_slam.sim.family import open_synthetic
from radar_slam.sim.generate import Scene, build_scene, generate_sequence, make_renderer
from radar_slam.sim.render import RenderTables, render_scan
from radar_slam.sim.scenarios import get_scenario
from raplace import se2
from raplace.units import NS_PER_S

SCAN_PERIOD_S = 0.25
MAX_ERROR_M = 0.05  # known-motion bar
MAX_ERROR_DEG = 0.1
SCENE_TIMES_S = (4.0, 9.5, 14.0)
"""Where along the `tiny` route the known-answer pairs start [s]."""
KNOWN_MOTIONS = (
    (2.4, 0.15, 3.0),  # dx [m], dy [m], dyaw [deg] between the scans (0.25 s apart)
    (1.6, -0.2, -2.0),
    (3.2, 0.1, 7.5),  # 30 deg/s: de-skewing matters
)
LOOP_FRAMES = 120  # ~270 m of `loop`
NEES_RANGE = (0.5, 6.0)
"""Mean normalised squared error of the scan-to-reference motions (3 when calibrated; 25-35
with the covariances of a de-skew that is off or referred to the end of the sweep). The peak
covariances are kept conservative (`QualityConfig.sigma_scale`)."""


@pytest.fixture(scope="module")
def tiny_scene() -> tuple[Scene, RenderTables]:
    scene = build_scene(get_scenario("tiny"))
    return scene, make_renderer(scene).tables


def render(
    scene: Scene,
    tables: RenderTables,
    end_pose: NDArray[np.float64],
    end_s: float,
    twist: NDArray[np.float64] | None,
    seed: int,
) -> RadarFrame:
    """The scan whose last azimuth is seen at `end_pose` at `end_s`; with `twist`, azimuth j
    is seen from the pose the constant twist gives at its own time (motion distortion)."""
    offsets = tables.column_offsets_s  # <= 0, the last azimuth at the scan's end
    if twist is None:
        poses = np.repeat(end_pose[None, :], len(offsets), axis=0)
    else:
        poses = np.array([se2.compose(end_pose, motion_from_twist(twist, t)) for t in offsets])
    polar = render_scan(scene.world, poses, end_s + offsets, tables, np.random.default_rng(seed))
    stamp = int(round(end_s * NS_PER_S))
    times = (stamp + np.round(offsets * NS_PER_S)).astype(np.int64)
    return RadarFrame(
        timestamp_ns=stamp,
        polar=polar,
        azimuths_rad=tables.sensor.azimuths_ccw_rad(),
        range_resolution_m=tables.sensor.range_resolution_m,
        sensor=tables.sensor.name,
        azimuth_times_ns=None if twist is None else times,
    )


def known_pair(
    scene: Scene, tables: RenderTables, case: int, distorted: bool
) -> tuple[RadarFrame, RadarFrame, NDArray[np.float64]]:
    """Two scans of the same world, the second after a known motion; returns the motion."""
    start_s = SCENE_TIMES_S[case]
    dx, dy, dyaw_deg = KNOWN_MOTIONS[case]
    motion = np.array([dx, dy, np.deg2rad(dyaw_deg)])
    twist = twist_from_motion(motion, SCAN_PERIOD_S) if distorted else None
    first = scene.trajectory.radar_poses(np.array([start_s]))[0]
    second = se2.compose(first, motion)
    a = render(scene, tables, first, start_s, twist, seed=2 * case)
    b = render(scene, tables, second, start_s + SCAN_PERIOD_S, twist, seed=2 * case + 1)
    return a, b, motion


def errors(estimate: NDArray[np.float64], truth: NDArray[np.float64]) -> tuple[float, float]:
    """Translation [m] and rotation [deg] error of an estimated motion."""
    diff = se2.between(truth, estimate)
    return float(np.hypot(diff[0], diff[1])), float(np.rad2deg(abs(diff[2])))


@pytest.mark.parametrize("case", range(len(KNOWN_MOTIONS)))
def test_known_motion_without_distortion(tiny_scene: tuple[Scene, RenderTables], case: int) -> None:
    scene, tables = tiny_scene
    a, b, motion = known_pair(scene, tables, case, distorted=False)
    estimate = estimate_motion(a, b)
    assert estimate.ok, estimate.reason
    error_m, error_deg = errors(estimate.motion, motion)
    assert error_m <= MAX_ERROR_M and error_deg <= MAX_ERROR_DEG, (error_m, error_deg)


@pytest.mark.parametrize("case", range(len(KNOWN_MOTIONS)))
def test_known_motion_with_distortion_is_deskewed(
    tiny_scene: tuple[Scene, RenderTables], case: int
) -> None:
    """Motion distortion undone from the scans' azimuth times, velocity not given: the first
    registration's motion gives the velocity, the second de-skews with it."""
    scene, tables = tiny_scene
    a, b, motion = known_pair(scene, tables, case, distorted=True)
    estimate = estimate_motion(a, b)
    assert estimate.ok, estimate.reason
    error_m, error_deg = errors(estimate.motion, motion)
    assert error_m <= MAX_ERROR_M and error_deg <= MAX_ERROR_DEG, (error_m, error_deg)


def test_deskew_sign_matters(tiny_scene: tuple[Scene, RenderTables]) -> None:
    """The fast-turning pair: the true velocity de-skews it; the reversed velocity (a sign
    error) or none at all leaves errors several times the bars."""
    scene, tables = tiny_scene
    a, b, motion = known_pair(scene, tables, len(KNOWN_MOTIONS) - 1, distorted=True)
    cfg = OdometryConfig()
    twist = twist_from_motion(motion, SCAN_PERIOD_S)
    right = errors(estimate_motion(a, b, cfg, twist).motion, motion)
    wrong = errors(estimate_motion(a, b, cfg, -twist).motion, motion)
    none = errors(estimate_motion(a, b, OdometryConfig(deskew=False)).motion, motion)
    assert right[0] <= MAX_ERROR_M and right[1] <= MAX_ERROR_DEG, right
    for bad in (wrong, none):
        assert bad[0] > 2 * MAX_ERROR_M or bad[1] > 2 * MAX_ERROR_DEG, bad


@pytest.fixture(scope="module")
def loop_start(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("sim") / "loop"
    generate_sequence(get_scenario("loop"), folder, frames=LOOP_FRAMES)
    return folder


def test_covariances_on_the_start_of_loop_are_consistent(loop_start: Path) -> None:
    """Each scan's pose relative to its reference scan against the truth, normalised by the
    reported covariance (turned back from the previous scan's axes into the reference's)."""
    sequence = open_synthetic(loop_start)
    ground_truth = sequence.ground_truth
    assert ground_truth is not None
    odometry = Odometry()
    results = [odometry.register(sequence[k]) for k in range(len(sequence))]
    assert odometry.gaps == []
    nees = []
    for r in results[1:]:
        error = r.keyframe_motion - se2.between(
            ground_truth[r.keyframe_index], ground_truth[r.index]
        )
        error[2] = se2.wrap_angle(error[2])
        turn = se2.between(results[r.index - 1].pose, results[r.keyframe_index].pose)[2]
        c, s = np.cos(turn), np.sin(turn)
        back = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
        covariance = back @ r.covariance @ back.T
        nees.append(float(error @ np.linalg.solve(covariance, error)))
    assert NEES_RANGE[0] <= np.mean(nees) <= NEES_RANGE[1], np.mean(nees)
