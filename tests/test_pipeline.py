"""The SLAM pipeline on short simulated sequences (`synthetic/tiny_loop` and `synthetic/tiny`,
fixtures in conftest.py): a revisit closes the loop and the ATE drops, 30 % injected false loops
change little, loops disabled gives SLAM == odometry, configuration layering and strictness, and
loops added to another odometry's g2o graph."""

from __future__ import annotations

import dataclasses
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from scan_counts import counting
from slam_bars import loops_corrected

from odometry import Scan
from radar_slam.datasets.frame import RadarSequence
from radar_slam.errors import ConfigError, RadarSlamError
from radar_slam.evaluation.false_loops import FakeLoopConfig, FalseLoopInjection
from radar_slam.evaluation.metrics import evaluate
from radar_slam.evaluation.truth import is_true_loop
from radar_slam.g2o import G2oEdge, G2oGraph
from radar_slam.graph import PoseGraph
from radar_slam.loops import (
    GeometricVerifier,
    LoopDetector,
)
from radar_slam.loops.config import LOOP_RAPLACE
from radar_slam.loops.detector import DescriptorListener
from radar_slam.pipeline import (
    Pipeline,
    PipelineConfig,
    Results,
    close_loops_on_graph,
    load_config,
)
from radar_slam.pipeline import slam as runner
from radar_slam.trajectory import Trajectory
from raplace.retrieval import PlaceRecognizer
from raplace.se2 import between

FALSE_FRACTION = 0.3
FAKE_LOOP = FakeLoopConfig(
    min_distance_m=50.0,
    max_offset_m=3.0,
    max_offset_yaw_rad=0.2,
    sigma_xy_m=0.05,
    sigma_yaw_rad=float(np.deg2rad(0.1)),
    sinogram_quality=0.9,
    refined_quality=100.0,
)
MAX_ATE_RISE = 0.10
INJECTION_SEED = 3


@pytest.fixture(scope="module")
def baseline(tiny_loop: RadarSequence) -> Results:
    return Pipeline(tiny_loop, load_config("synthetic")).run()


def test_a_revisit_closes_the_loop_and_the_ate_drops(tiny_loop: RadarSequence, baseline: Results):
    m = baseline.metrics
    assert m.frames == len(tiny_loop) == len(baseline.slam) == len(baseline.odometry)
    np.testing.assert_array_equal(baseline.slam.timestamps_ns, tiny_loop.timestamps_ns)
    assert m.loops_accepted >= 3
    assert m.loops_accepted_true == m.loops_accepted  # every accepted loop is true
    assert m.ate_slam_m is not None and m.ate_odometry_m is not None
    assert loops_corrected(m.ate_slam_m, m.ate_odometry_m)
    assert m.ate_reduction == pytest.approx(1 - m.ate_slam_m / m.ate_odometry_m)
    assert set(baseline.timings_s) >= {"read", "odometry", "graph", "loop detection"}
    assert m.frames_per_second > 0


def test_loops_batched_into_fewer_isam2_updates_give_the_same_result(
    tiny_loop: RadarSequence, monkeypatch: pytest.MonkeyPatch
) -> None:
    """ISAM2 runs at most every `LOOP_UPDATE_INTERVAL` (10) scans, and every
    `SETTLED_UPDATE_INTERVAL` (100) while the new loops agree with the estimate, instead of
    after every scan with new loops: the same loops, and the final batch pass lands on the same
    trajectory."""
    updates: list[int] = []
    original = PoseGraph.update

    def counted(graph: PoseGraph) -> None:
        updates.append(len(graph.keys()))
        original(graph)

    monkeypatch.setattr(PoseGraph, "update", counted)
    config = load_config("synthetic")
    with monkeypatch.context() as every_scan:
        every_scan.setattr(runner, "LOOP_UPDATE_INTERVAL", 1)
        every_scan.setattr(runner, "SETTLED_UPDATE_INTERVAL", 1)
        eager = Pipeline(tiny_loop, config).run()
    eager_updates = len(updates)
    updates.clear()
    batched = Pipeline(tiny_loop, config).run()
    assert len(updates) < eager_updates
    during_run = [n for n in updates if n < len(tiny_loop)]  # not the final ones
    assert np.all(np.diff(during_run) >= runner.LOOP_UPDATE_INTERVAL)
    assert batched.metrics.loops_accepted == eager.metrics.loops_accepted >= 3
    # A loop that agreed with the estimate waited longer than 10 scans for its update.
    lag = config.concurrency.loop_lag_scans
    frames = len(tiny_loop)
    added = sorted({min(d.query_key + lag + 1, frames) for d in batched.accepted_loops})
    waits = [min(n for n in updates if n >= k) - k for k in added]
    assert max(waits) > runner.LOOP_UPDATE_INTERVAL
    offsets = np.hypot(*(batched.slam.poses[:, :2] - eager.slam.poses[:, :2]).T)
    assert offsets.max() < 1e-3, offsets.max()


def test_thirty_percent_false_loops_raise_the_ate_at_most_ten_percent(
    tiny_loop: RadarSequence, baseline: Results
) -> None:
    gt = tiny_loop.ground_truth
    assert gt is not None
    config = load_config("synthetic")
    # every candidate verified, however far the odometry puts it: the false loops reach the graph
    cfg = dataclasses.replace(config.loop_closure, odometry_drift_fraction=np.inf)
    injection = FalseLoopInjection(
        np.asarray(gt), FALSE_FRACTION, np.random.default_rng(INJECTION_SEED), FAKE_LOOP
    )

    def detector(scans: Callable[[int], Scan], descriptors: DescriptorListener) -> LoopDetector:
        return LoopDetector(
            cfg,
            scan_loader=scans,
            recognizer=injection.recognizer(PlaceRecognizer(LOOP_RAPLACE.retrieval)),
            verifier=injection.verifier(GeometricVerifier(cfg, config.odometry)),
            on_describe=descriptors,
            odometry=config.odometry,
        )

    with counting(tiny_loop) as counts:
        injected = Pipeline(tiny_loop, config, loop_detector_factory=detector).run()
    # the injected detector verifies from the run's records: each scan is read once
    assert counts.decodes == Counter(range(len(tiny_loop)))
    assert counts.records_read >= len(injected.loops) > 0
    assert len(injection.passed) >= 5  # false loops did pass the (fake) verification
    accepted = {(d.query_key, d.match_key) for d in injected.accepted_loops}
    assert not accepted & injection.passed
    base, slam = baseline.metrics.ate_slam_m, injected.metrics.ate_slam_m
    assert base is not None and slam is not None
    assert slam <= (1 + MAX_ATE_RISE) * base


def test_without_loops_slam_equals_odometry(tiny: RadarSequence) -> None:
    config = PipelineConfig()
    config = dataclasses.replace(
        config, loop_closure=dataclasses.replace(config.loop_closure, enabled=False)
    )
    results = Pipeline(tiny, config, max_frames=30).run()
    assert len(results.slam) == 30 and results.loops == []
    np.testing.assert_allclose(results.slam.poses, results.odometry.poses, atol=1e-6)
    assert results.metrics.loops_proposed == 0 and results.metrics.ate_reduction is not None


def test_max_frames_must_be_positive(tiny: RadarSequence) -> None:
    with pytest.raises(RadarSlamError, match="at least 1"):
        Pipeline(tiny, max_frames=0)


def test_config_layers_and_strictness(tmp_path: Path) -> None:
    default = load_config()
    assert default == PipelineConfig()
    assert load_config("synthetic") == default  # the shipped file only comments
    override = tmp_path / "override.yaml"
    override.write_text(
        "loop_closure:\n  candidates: 4\n  verification: {max_translation_m: 12.5}\n"
        "graph: {final_pass: lm}\nodometry: {keyframe: {max_frames: 4}}\n"
    )
    config = load_config("synthetic", override)
    assert config.loop_closure.candidates == 4
    assert config.loop_closure.verification.max_translation_m == 12.5
    assert config.graph.final_pass == "lm" and config.odometry.keyframe.max_frames == 4
    assert config.maps == default.maps  # untouched sections stay
    typo = tmp_path / "typo.yaml"
    typo.write_text("loop_closure:\n  candidatse: 4\n")
    with pytest.raises(ConfigError, match="candidatse"):
        load_config("synthetic", typo)
    with pytest.raises(ConfigError, match="not found"):
        load_config(None, tmp_path / "missing.yaml")
    with pytest.raises(ConfigError, match="expected an integer"):
        load_config(None, overrides={"loop_closure": {"candidates": "many"}})


def odometry_g2o(results: Results) -> G2oGraph:
    """Another odometry's pose graph: one vertex per scan, chained odometry edges."""
    poses = results.odometry.poses
    info = np.linalg.inv(np.diag([0.05**2, 0.05**2, np.deg2rad(0.2) ** 2]))
    vertices = {k: pose for k, pose in enumerate(poses)}
    edges = [
        G2oEdge(k, k + 1, between(poses[k], poses[k + 1]), info) for k in range(len(poses) - 1)
    ]
    return G2oGraph(vertices, edges, [0])


def test_loops_added_to_another_odometrys_graph(
    tiny_loop: RadarSequence, baseline: Results
) -> None:
    record = odometry_g2o(baseline)
    run = close_loops_on_graph(record, tiny_loop, load_config("synthetic"))
    assert run.n_accepted >= 3
    gt = tiny_loop.ground_truth
    assert gt is not None
    for d in run.loops:
        if d.accepted:
            assert is_true_loop(d.measurement, gt[d.query_key], gt[d.match_key])
    stamps = tiny_loop.timestamps_ns
    gt_traj = Trajectory(stamps, gt)
    before = evaluate(Trajectory(stamps, record.poses()), gt_traj).ate_rmse_m
    after = evaluate(Trajectory(stamps, run.graph.estimates()), gt_traj).ate_rmse_m
    assert loops_corrected(after, before)
    short = G2oGraph({k: v for k, v in record.vertices.items() if k < 10}, [], [])
    with pytest.raises(RadarSlamError, match="one vertex per scan"):
        close_loops_on_graph(short, tiny_loop)
