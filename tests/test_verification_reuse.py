"""Loop verification reusing the odometry's conditioned scans: the same decisions
and measurements as conditioning the query again, at most `OFFERS_KEPT` handed-over scans kept
(the detector verifies a scan once the next one is in)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from odometry import Odometry
from odometry.config import OdometryConfig
from odometry.registration import prepare
from radar_slam.datasets.frame import RadarFrame, RadarSequence
from radar_slam.loops import GeometricVerifier, LoopClosureConfig, LoopDetector
from radar_slam.loops.records import KeyScan, Verification
from radar_slam.loops.verification import OFFERS_KEPT
from radar_slam.pipeline import Pipeline, load_config
from radar_slam.sim.family import open_synthetic
from radar_slam.sim.generate import generate_sequence
from radar_slam.sim.scenarios import get_scenario
from raplace.se2 import between

SCAN_PERIOD_S = 0.25
QUERY, MATCH = 40, 36


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> RadarSequence:
    """The simulator's `tiny` scenario (60 scans, 1024 bins, about 100 m, no revisit)."""
    folder = tmp_path_factory.mktemp("reuse") / "tiny"
    generate_sequence(get_scenario("tiny"), folder)
    return open_synthetic(folder)


def key_scan(sequence: RadarSequence, k: int, frame: RadarFrame | None = None) -> KeyScan:
    """Scan k with its ground-truth body velocity from the previous scan."""
    gt = sequence.ground_truth
    assert gt is not None
    frame = sequence[k] if frame is None else frame
    return KeyScan(k, frame.timestamp_ns, frame, between(gt[k - 1], gt[k]) / SCAN_PERIOD_S)


def assert_same(a: Verification, b: Verification) -> None:
    assert (a.ok, a.reason) == (b.ok, b.reason)
    for field in ("measurement", "covariance", "sinogram"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    assert a.refined_quality == b.refined_quality


def fresh(sequence: RadarSequence, odometry: OdometryConfig | None = None) -> Verification:
    verifier = GeometricVerifier(LoopClosureConfig(), odometry)
    return verifier(key_scan(sequence, QUERY), key_scan(sequence, MATCH))


def test_an_offered_scan_prepared_alike_gives_the_same_verification(tiny: RadarSequence) -> None:
    query = key_scan(tiny, QUERY)
    verifier = GeometricVerifier(LoopClosureConfig())
    verifier.offer(QUERY, prepare(query.scan, OdometryConfig(), query.twist))
    result = verifier(query, key_scan(tiny, MATCH))
    assert verifier.reused == 1
    assert result.ok, result.reason
    assert_same(result, fresh(tiny))


def test_the_odometrys_conditioned_scan_gives_the_same_loop(tiny: RadarSequence) -> None:
    """The odometry's conditioned scan (de-skewed with its own velocity, some spectra made) is
    used, and the verification is exactly the one that conditions the query again."""
    odometry = Odometry(OdometryConfig())
    for k in range(QUERY + 1):
        odometry.register(tiny[k])
    prepared = odometry.prepared
    assert prepared is not None and prepared.timestamp_ns == tiny[QUERY].timestamp_ns
    verifier = GeometricVerifier(LoopClosureConfig())
    verifier.offer(QUERY, prepared)
    result = verifier(key_scan(tiny, QUERY), key_scan(tiny, MATCH))
    assert verifier.reused == 1
    assert result.ok, result.reason
    assert_same(result, fresh(tiny))


def test_only_a_matching_offer_is_used_and_only_the_latest_are_kept(tiny: RadarSequence) -> None:
    cfg, odometry = LoopClosureConfig(), OdometryConfig()
    assert OFFERS_KEPT == 2
    verifier = GeometricVerifier(cfg)
    for k in (QUERY, QUERY + 1):  # the offer of the next scan is in when a query is verified
        scan = key_scan(tiny, k)
        verifier.offer(k, prepare(scan.scan, odometry, scan.twist))
    result = verifier(key_scan(tiny, QUERY), key_scan(tiny, MATCH))
    assert verifier.reused == 1
    assert_same(result, fresh(tiny))
    verifier = GeometricVerifier(cfg)
    for k in (QUERY, QUERY + 1, QUERY + 2):  # the third drops the first
        scan = key_scan(tiny, k)
        verifier.offer(k, prepare(scan.scan, odometry, scan.twist))
    result = verifier(key_scan(tiny, QUERY), key_scan(tiny, MATCH))
    assert verifier.reused == 0
    assert_same(result, fresh(tiny))
    # A key whose scan is another one (another timestamp) is not used either.
    other = key_scan(tiny, QUERY + 2)
    verifier = GeometricVerifier(cfg)
    verifier.offer(QUERY, prepare(other.scan, odometry, other.twist))
    assert_same(verifier(key_scan(tiny, QUERY), key_scan(tiny, MATCH)), fresh(tiny))
    assert verifier.reused == 0


def test_other_refinement_settings_reuse_only_the_conditioning(tiny: RadarSequence) -> None:
    """Same conditioning, other registration settings: the conditioned polar scan is reused and
    the result is that of the verifier's own settings; other conditioning: not reused."""
    base = OdometryConfig()
    finer = dataclasses.replace(base, fine=dataclasses.replace(base.fine, cell_m=0.3))
    query = key_scan(tiny, QUERY)
    verifier = GeometricVerifier(LoopClosureConfig(), finer)
    verifier.offer(QUERY, prepare(query.scan, base, query.twist))
    result = verifier(query, key_scan(tiny, MATCH))
    assert verifier.reused == 1
    assert_same(result, fresh(tiny, finer))

    other = dataclasses.replace(
        base, preprocess=dataclasses.replace(base.preprocess, bin_size_m=0.4)
    )
    verifier = GeometricVerifier(LoopClosureConfig())
    verifier.offer(QUERY, prepare(query.scan, other, query.twist))
    assert_same(verifier(query, key_scan(tiny, MATCH)), fresh(tiny))
    assert verifier.reused == 0


def test_the_pipeline_hands_its_conditioned_scans_to_verification(tiny_loop: RadarSequence):
    """Every verified query of a run reuses the odometry's conditioned scan, in both modes, and
    the loops and trajectory are those of a run whose verifier conditions every scan itself."""
    config = load_config("synthetic")
    runs = []
    for threads in (False, True):
        concurrency = dataclasses.replace(config.concurrency, loop_thread=threads)
        pipeline = Pipeline(tiny_loop, dataclasses.replace(config, concurrency=concurrency))
        runs.append((pipeline, pipeline.run()))
    cfg = config.loop_closure
    unoffered = Pipeline(tiny_loop, config)  # its database scans from the run's records too
    assert isinstance(unoffered.loop_detector, LoopDetector)
    unoffered.loop_detector.verifier = _Wrapped(cfg)
    without = unoffered.run()
    for pipeline, results in runs:
        detector = pipeline.loop_detector
        assert isinstance(detector, LoopDetector)
        assert isinstance(detector.verifier, GeometricVerifier)
        verified_queries = {d.query_key for d in results.loops if d.refined_quality > 0}
        assert len(verified_queries) >= 3
        assert detector.verifier.reused == len(verified_queries)
        assert [(d.query_key, d.match_key, d.status) for d in results.loops] == [
            (d.query_key, d.match_key, d.status) for d in without.loops
        ]
        for ours, theirs in zip(results.loops, without.loops, strict=True):
            np.testing.assert_array_equal(ours.measurement, theirs.measurement)
        np.testing.assert_allclose(results.slam.poses, without.slam.poses, atol=1e-9, rtol=0)


class _Wrapped:
    """A `GeometricVerifier` without `offer` (conditions every query itself)."""

    def __init__(self, cfg: LoopClosureConfig) -> None:
        self.inner = GeometricVerifier(cfg)

    def __call__(self, query: KeyScan, match: KeyScan) -> Verification:
        return self.inner(query, match)

    def refine(
        self, query: KeyScan, match: KeyScan, initial: np.ndarray, initial_quality: float
    ) -> Verification:  # the checks from a prediction (`radar_slam.loops.tracking`)
        return self.inner.refine(query, match, initial, initial_quality)
