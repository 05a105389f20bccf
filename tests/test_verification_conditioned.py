"""Loop verification from each scan's one conditioned form (the odometry's, in a run): the same
decisions and measurements as conditioning the scans in the verifier."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from odometry import Odometry, preprocess_polar
from odometry.config import OdometryConfig
from odometry.registration import prepare
from radar_slam.datasets.frame import RadarFrame, RadarSequence
from radar_slam.loops import GeometricVerifier, LoopClosureConfig, LoopDetector
from radar_slam.loops.records import KeyScan, Verification
from radar_slam.loops.verification import turned_twist
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


def test_the_odometrys_conditioned_scan_gives_the_same_loop(tiny: RadarSequence) -> None:
    """The odometry's conditioned scan (de-skewed with its own velocity, some spectra made) is
    used, and the verification is exactly the one that conditions the query again."""
    odometry = Odometry(OdometryConfig())
    for k in range(QUERY + 1):
        odometry.register(tiny[k])
    prepared = odometry.prepared
    assert prepared is not None and prepared.timestamp_ns == tiny[QUERY].timestamp_ns
    query = dataclasses.replace(key_scan(tiny, QUERY), polar=prepared.polar)
    result = GeometricVerifier(LoopClosureConfig())(query, key_scan(tiny, MATCH))
    assert result.ok, result.reason
    assert_same(result, fresh(tiny))


@pytest.mark.parametrize("turn_rad", [0.4, np.pi, -2.5])
def test_a_turned_scan_is_its_conditioned_form_turned(tiny: RadarSequence, turn_rad: float) -> None:
    """The match turned by the sinogram rotation is registered from its one conditioned form,
    turned: the conditioning of the turned scan, to rounding of its first azimuth."""
    match = key_scan(tiny, MATCH)
    ours = GeometricVerifier(LoopClosureConfig()).prepared(match, turn_rad)
    frame = tiny[MATCH]
    moved = dataclasses.replace(frame, azimuths_rad=frame.azimuths_rad + turn_rad)
    theirs = prepare(moved, OdometryConfig(), turned_twist(match.twist, turn_rad))
    np.testing.assert_array_equal(ours.polar.wrapped_image, theirs.polar.wrapped_image)
    assert ours.polar.first_azimuth_rad == pytest.approx(theirs.polar.first_azimuth_rad, abs=1e-12)
    assert ours.polar.first_azimuth_rad != pytest.approx(
        preprocess_polar(frame, OdometryConfig().preprocess).first_azimuth_rad, abs=0.1
    )
    assert ours.polar.timing == theirs.polar.timing
    assert ours.twist is not None and theirs.twist is not None
    np.testing.assert_array_equal(ours.twist, theirs.twist)


def test_the_pipeline_hands_its_conditioned_scans_to_verification(tiny_loop: RadarSequence):
    """Every verified query of a run comes with the odometry's conditioned scan, in both modes,
    and the loops and trajectory are those of a run whose verifier conditions every scan
    itself."""
    config = load_config("synthetic")
    runs = []
    for threads in (False, True):
        concurrency = dataclasses.replace(config.concurrency, loop_thread=threads)
        pipeline = Pipeline(tiny_loop, dataclasses.replace(config, concurrency=concurrency))
        runs.append(pipeline.run())
    cfg = config.loop_closure
    unhanded = Pipeline(tiny_loop, config)  # its database scans from the run's records too
    assert isinstance(unhanded.loop_detector, LoopDetector)
    stripping = _Stripping(cfg)
    unhanded.loop_detector.verifier = stripping
    without = unhanded.run()
    verified_queries = {d.query_key for d in without.loops if d.refined_quality > 0}
    assert len(verified_queries) >= 3
    assert stripping.handed == stripping.verified >= len(verified_queries)
    for results in runs:
        assert [(d.query_key, d.match_key, d.status) for d in results.loops] == [
            (d.query_key, d.match_key, d.status) for d in without.loops
        ]
        for ours, theirs in zip(results.loops, without.loops, strict=True):
            np.testing.assert_array_equal(ours.measurement, theirs.measurement)
        np.testing.assert_allclose(results.slam.poses, without.slam.poses, atol=1e-9, rtol=0)


class _Stripping:
    """A `GeometricVerifier` that counts the queries handed with their conditioned form, then
    drops it (the verifier conditions every query itself)."""

    def __init__(self, cfg: LoopClosureConfig) -> None:
        self.inner = GeometricVerifier(cfg)
        self.verified = self.handed = 0

    def _strip(self, query: KeyScan) -> KeyScan:
        self.verified += 1
        self.handed += query.polar is not None
        return dataclasses.replace(query, polar=None)

    def __call__(self, query: KeyScan, match: KeyScan) -> Verification:
        return self.inner(self._strip(query), match)

    def refine(
        self, query: KeyScan, match: KeyScan, initial: np.ndarray, initial_quality: float
    ) -> Verification:  # the checks from a prediction (`radar_slam.loops.tracking`)
        return self.inner.refine(self._strip(query), match, initial, initial_quality)
