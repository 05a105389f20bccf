"""PlaceRecognizer: ranking, exclusion, save/load, hierarchical = exhaustive, reverse visits."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from raplace_scenes import angle_error, relative, render_cart, synthetic_world

from raplace import RaPlaceError
from raplace.config import (
    DescriptorConfig,
    ExclusionConfig,
    RaPlaceConfig,
    RetrievalConfig,
    ScanContextConfig,
)
from raplace.config_io import from_dict, to_dict
from raplace.descriptor import coarse_descriptor, descriptor, z_normalise
from raplace.index import InvariantIndex, invariant_vectors
from raplace.retrieval import GrowingArray, PlaceRecognizer, candidate_mask
from raplace.scancontext import ScanContextRecognizer
from raplace.scoring import score, theta_spectrum

WORLD_CELL_M = 0.25
DESCRIPTOR = DescriptorConfig()
NO_EXCLUSION = ExclusionConfig(recent_keyframes=0, recent_seconds=0.0)
PATH_SPACING_M = 4.0
PATH_LENGTH = 80


def _random_descriptors(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return z_normalise(rng.standard_normal((n, DESCRIPTOR.n_theta, DESCRIPTOR.n_freq)))


def _path_pose(s_m: float) -> tuple[float, float, float]:
    """A closed 'stadium' route of about 320 m in the synthetic world; s_m is the arc length."""
    angle = s_m / 51.0
    return (51.0 * np.cos(angle), 51.0 * np.sin(angle) * 1.3, angle + np.pi / 2)


@pytest.fixture(scope="module")
def route():
    """Keyframe descriptors along the route, and the world they were cut from."""
    world = synthetic_world(1000, seed=5)  # 250 m x 250 m
    poses = [_path_pose(i * PATH_SPACING_M) for i in range(PATH_LENGTH)]
    descriptors = np.stack([_describe(world, p) for p in poses])
    return world, poses, descriptors


def _describe(world: np.ndarray, pose: tuple[float, float, float]) -> np.ndarray:
    cart = render_cart(world, WORLD_CELL_M, pose, DESCRIPTOR.image.cell_m, 60.0)
    return descriptor(cart, DESCRIPTOR.image.cell_m, DESCRIPTOR)


def test_exact_copy_is_best_with_zero_distance() -> None:
    descs = _random_descriptors(20, seed=0)
    recognizer = PlaceRecognizer(RetrievalConfig(exclusion=NO_EXCLUSION))
    recognizer.add_batch(descs, keys=np.arange(100, 120))
    best = recognizer.query(np.roll(descs[7], 11, axis=0), k=1)[0]
    assert (best.key, best.index) == (107, 7)
    assert best.distance == pytest.approx(0.0, abs=1e-5)
    # Rolling the query by +11 rows rotates its scene by +11 * 1.5 deg: the entry is at +16.5 deg.
    assert np.rad2deg(best.yaw_rad) == pytest.approx(16.5, abs=1e-3)
    assert best.yaw_period_rad == pytest.approx(np.pi)


def test_k_results_are_ranked() -> None:
    descs = _random_descriptors(30, seed=1)
    recognizer = PlaceRecognizer(RetrievalConfig(exclusion=NO_EXCLUSION))
    recognizer.add_batch(descs, keys=np.arange(30))
    ranked = recognizer.query(descs[3], k=5)
    assert len(ranked) == 5
    assert ranked[0].key == 3
    distances = [c.distance for c in ranked]
    assert distances == sorted(distances)
    assert len(recognizer.query(descs[3], k=100)) == 30


def test_exclusion_window_recent_keyframes() -> None:
    descs = _random_descriptors(10, seed=2)
    recognizer = PlaceRecognizer(
        RetrievalConfig(exclusion=ExclusionConfig(recent_keyframes=3, recent_seconds=0.0))
    )
    for i, desc in enumerate(descs):
        recognizer.add(desc, key=i)
    assert all(c.index < 7 for c in recognizer.query(descs[9], k=10))
    assert len(recognizer.query(descs[9], k=10)) == 7
    assert recognizer.query(descs[4], k=1)[0].key == 4


def test_exclusion_window_seconds() -> None:
    times = np.arange(10, dtype=float)
    exclusion = ExclusionConfig(recent_keyframes=0, recent_seconds=4.5)
    np.testing.assert_array_equal(
        np.flatnonzero(candidate_mask(times, None, exclusion)), np.arange(5)
    )
    np.testing.assert_array_equal(
        np.flatnonzero(candidate_mask(times, 20.0, exclusion)), np.arange(10)
    )
    descs = _random_descriptors(10, seed=3)
    recognizer = PlaceRecognizer(RetrievalConfig(exclusion=exclusion))
    recognizer.add_batch(descs, keys=np.arange(10), times_s=times)
    assert {c.index for c in recognizer.query(descs[8], k=10, time_s=9.0)} == set(range(5))


def test_save_load_round_trip(tmp_path) -> None:
    descs = _random_descriptors(12, seed=4)
    cfg = RetrievalConfig(coarse_candidates=2, neighbour_radius=1, exclusion=NO_EXCLUSION)
    recognizer = PlaceRecognizer(cfg)
    recognizer.add_batch(descs, keys=np.arange(12) * 1000, times_s=np.arange(12) * 0.25)
    path = tmp_path / "raplace_db.npz"
    recognizer.save(path)
    loaded = PlaceRecognizer.load(path)
    assert loaded.cfg == cfg
    np.testing.assert_array_equal(loaded.keys, recognizer.keys)
    np.testing.assert_allclose(loaded.descriptors(), descs, atol=1e-5)
    query = descs[5] + 0.3 * _random_descriptors(1, seed=9)[0]
    before, after = recognizer.query(query, k=4), loaded.query(query, k=4)
    assert [c.key for c in after] == [c.key for c in before]
    np.testing.assert_allclose([c.distance for c in after], [c.distance for c in before], atol=1e-6)
    np.testing.assert_allclose([c.yaw_rad for c in after], [c.yaw_rad for c in before], atol=1e-6)
    with pytest.raises(RaPlaceError):
        ScanContextRecognizer.load(path)


def test_empty_database_and_bad_shapes() -> None:
    recognizer = PlaceRecognizer(RetrievalConfig())
    assert recognizer.query(_random_descriptors(1, seed=0)[0]) == []
    recognizer.add(_random_descriptors(1, seed=0)[0], key=1)
    with pytest.raises(RaPlaceError):
        recognizer.add(np.zeros((10, 10), np.float32), key=2)
    with pytest.raises(RaPlaceError):
        recognizer.query(np.zeros((10, 10), np.float32))


def test_hierarchical_matches_exhaustive_and_finds_reverse_visits(route) -> None:
    world, poses, descriptors = route
    hierarchical = PlaceRecognizer(
        RetrievalConfig(coarse_candidates=3, neighbour_radius=1, exclusion=NO_EXCLUSION)
    )
    exhaustive = PlaceRecognizer(RetrievalConfig(hierarchical=False, exclusion=NO_EXCLUSION))
    keys = np.arange(PATH_LENGTH)
    hierarchical.add_batch(descriptors, keys)
    exhaustive.add_batch(descriptors, keys)
    rng = np.random.default_rng(7)
    for _ in range(8):
        s = rng.uniform(0, (PATH_LENGTH - 1) * PATH_SPACING_M)
        x, y, yaw = _path_pose(s)
        turn = rng.choice([0.0, np.pi])  # same or opposite driving direction
        query_pose = (x + rng.uniform(-2, 2), y + rng.uniform(-2, 2), yaw + turn)
        query = _describe(world, query_pose)
        fast = hierarchical.query(query, k=1)[0]
        slow = exhaustive.query(query, k=1)[0]
        assert fast.index == slow.index
        assert fast.distance == pytest.approx(slow.distance)
        assert abs(fast.index - s / PATH_SPACING_M) <= 1.5
        truth = relative(query_pose, poses[fast.index])[2]
        assert np.rad2deg(angle_error(2 * fast.yaw_rad, 2 * truth)) / 2 < 2.0


def test_growing_array_appends() -> None:
    grow = GrowingArray((2,), np.float64)
    for i in range(200):
        grow.append(np.array([i, -i]))
    assert len(grow) == 200
    np.testing.assert_array_equal(grow.values[:, 0], np.arange(200))


def test_config_round_trip_is_strict() -> None:
    cfg = RaPlaceConfig()
    assert from_dict(RaPlaceConfig, to_dict(cfg)) == cfg
    changed = from_dict(RaPlaceConfig, {"retrieval": {"exclusion": {"recent_keyframes": 7}}})
    assert changed.retrieval.exclusion.recent_keyframes == 7
    assert changed.descriptor == cfg.descriptor
    with pytest.raises(RaPlaceError):
        from_dict(RaPlaceConfig, {"retrieval": {"coarse_candidatez": 3}})
    assert dataclasses.is_dataclass(ScanContextConfig())


def _coarse_vector(desc: np.ndarray, cfg: RetrievalConfig) -> np.ndarray:
    coarse = coarse_descriptor(desc, cfg.coarse_theta_pool, cfg.coarse_n_freq)
    return invariant_vectors(theta_spectrum(coarse), coarse.shape[-2])


def test_invariant_vector_ignores_rotation_and_translation(route) -> None:
    world, poses, descriptors = route
    cfg = RetrievalConfig()
    x, y, yaw = poses[10]
    here = _coarse_vector(descriptors[10], cfg)
    # A rotation by whole coarse rows (3 descriptor rows) is a circular shift: no change at all.
    shifted = _coarse_vector(np.roll(descriptors[10], 18, axis=0), cfg)
    np.testing.assert_allclose(shifted, here, atol=1e-6)
    assert np.linalg.norm(here) == pytest.approx(1.0, abs=1e-5)  # Parseval, all harmonics kept
    # Rotated by 37 deg (not a whole row, and more than the pi period away) and moved 2 m.
    turned = _describe(world, (x + 1.5, y - 1.2, yaw + np.deg2rad(37.0) + np.pi))
    rotated = _coarse_vector(turned, cfg)
    elsewhere = _coarse_vector(descriptors[40], cfg)
    assert float(rotated @ here) > 0.98
    assert float(rotated @ here) - float(elsewhere @ here) > 0.05
    # The bound with the phases along k: invariant to whole-row shifts, best at the right place.
    coarse = coarse_descriptor(descriptors, cfg.coarse_theta_pool, cfg.coarse_n_freq)
    index = InvariantIndex(coarse.shape[1], cfg.coarse_n_freq, cfg.coarse_index_harmonics)
    index.extend(theta_spectrum(coarse))
    rolled = theta_spectrum(np.roll(coarse[10], 6, axis=0))
    np.testing.assert_allclose(
        index.bound(rolled), index.bound(theta_spectrum(coarse[10])), atol=1e-5
    )
    bound = index.bound(theta_spectrum(coarse_descriptor(turned, 3, cfg.coarse_n_freq)))
    assert abs(int(np.argmax(bound)) - 10) <= 1 and bound.max() > 0.9


def test_invariant_bound_never_exceeds_the_correlation_peak() -> None:
    cfg = RetrievalConfig()
    descs = _random_descriptors(60, seed=11)
    query = z_normalise(descs[3] + 0.5 * _random_descriptors(1, seed=12)[0])
    coarse = coarse_descriptor(descs, cfg.coarse_theta_pool, cfg.coarse_n_freq)
    coarse_query = coarse_descriptor(query, cfg.coarse_theta_pool, cfg.coarse_n_freq)
    exact, _ = score(coarse_query, theta_spectrum(coarse))
    for harmonics in (1, 4, 21):
        index = InvariantIndex(coarse.shape[1], cfg.coarse_n_freq, harmonics)
        index.extend(theta_spectrum(coarse))
        lower = 1.0 - index.bound(theta_spectrum(coarse_query))
        assert np.all(lower <= exact + 1e-5)
    # With every harmonic the bound is exact at the entry the query is a copy of (no rotation).
    lower_all = 1.0 - index.bound(theta_spectrum(coarse[7]))
    assert lower_all[7] == pytest.approx(0.0, abs=1e-5)


@pytest.fixture(scope="module")
def crowded(route):
    """The route's keyframes among 600 distractors (more than the shortlist)."""
    world, poses, descriptors = route
    distractors = _random_descriptors(600, seed=21)
    entries = np.concatenate([distractors[:300], descriptors, distractors[300:]])
    return world, poses, entries


def test_shortlisted_search_finds_what_exhaustive_finds(crowded) -> None:
    world, poses, entries = crowded
    new = PlaceRecognizer(RetrievalConfig(coarse_shortlist=40, exclusion=NO_EXCLUSION))
    old = PlaceRecognizer(RetrievalConfig(coarse_shortlist=0, exclusion=NO_EXCLUSION))
    exhaustive = PlaceRecognizer(RetrievalConfig(hierarchical=False, exclusion=NO_EXCLUSION))
    for recognizer in (new, old, exhaustive):
        recognizer.add_batch(entries, np.arange(len(entries)))
    rng = np.random.default_rng(8)
    for _ in range(6):
        i = int(rng.integers(0, PATH_LENGTH))
        x, y, yaw = poses[i]
        turn = rng.uniform(-np.pi, np.pi)
        query = _describe(world, (x + rng.uniform(-2, 2), y + rng.uniform(-2, 2), yaw + turn))
        fast, before, slow = (r.query(query, k=1)[0] for r in (new, old, exhaustive))
        assert fast.index == slow.index == before.index
        assert abs(fast.index - 300 - i) <= 1
        assert fast.distance == pytest.approx(slow.distance)


def test_shortlist_respects_the_exclusion(crowded) -> None:
    world, poses, entries = crowded
    exclusion = ExclusionConfig(recent_keyframes=0, recent_seconds=100.0)
    recognizer = PlaceRecognizer(RetrievalConfig(coarse_shortlist=40, exclusion=exclusion))
    times = np.arange(len(entries), dtype=np.float64)  # the route is at 300..379 s
    recognizer.add_batch(entries, np.arange(len(entries)), times)
    x, y, yaw = poses[30]
    query = _describe(world, (x, y, yaw + 0.4))
    assert recognizer.query(query, k=1, time_s=1000.0)[0].index == 330
    # At 429.5 s, entries after 329.5 s are too recent: the true place is excluded.
    found = recognizer.query(query, k=10, time_s=429.5)
    assert found and all(c.index <= 329 for c in found)
    mask = candidate_mask(times, 429.5, exclusion)
    index = InvariantIndex(40, 8, 16)
    cfg = RetrievalConfig()
    coarse = coarse_descriptor(entries, cfg.coarse_theta_pool, cfg.coarse_n_freq)
    index.extend(theta_spectrum(coarse))
    listed = index.shortlist(theta_spectrum(coarse[330]), mask, 40)
    assert len(listed) == 40 and np.all(mask[listed]) and 330 not in listed
    assert np.all(np.diff(listed) > 0)


def test_shortlisted_database_round_trip_and_old_versions(crowded, tmp_path) -> None:
    world, poses, entries = crowded
    recognizer = PlaceRecognizer(RetrievalConfig(coarse_shortlist=40))
    recognizer.add_batch(entries, np.arange(len(entries)) * 10)
    path = tmp_path / "db.npz"
    recognizer.save(path)
    loaded = PlaceRecognizer.load(path)
    x, y, yaw = poses[50]
    query = _describe(world, (x - 1.0, y, yaw - 2.0))
    before, after = recognizer.query(query, k=3), loaded.query(query, k=3)
    assert [c.key for c in after] == [c.key for c in before] and before[0].key == 3500
    with np.load(path) as data:
        arrays = {name: data[name] for name in data.files}
    meta = json.loads(str(arrays["meta"]))
    old = tmp_path / "old.npz"
    np.savez(old, **{**arrays, "meta": np.array(json.dumps({**meta, "version": 0}))})
    with pytest.raises(RaPlaceError, match="old.npz.*version 0, expected 'raplace' version 1"):
        PlaceRecognizer.load(old)
