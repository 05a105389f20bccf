"""Radar Scan Context baseline: ordering of places, column-shift rotation, recognizer interface."""

from __future__ import annotations

import numpy as np
import pytest
from raplace_scenes import angle_error, render_polar, synthetic_world

from raplace import RaPlaceError
from raplace.config import ExclusionConfig, ScanContextConfig
from raplace.retrieval import PlaceRecognizer
from raplace.scancontext import (
    ScanContextExtractor,
    ScanContextRecognizer,
    column_shift_distance,
    ring_key,
    scan_context,
)

CFG = ScanContextConfig()
SECTOR_DEG = 360.0 / CFG.n_sectors


def _distance(query: np.ndarray, entry: np.ndarray) -> tuple[float, float]:
    distance, yaw = column_shift_distance(query, entry[None])
    return float(distance[0]), float(yaw[0])


def test_context_bins_follow_the_convention() -> None:
    polar = np.zeros((360, 800), np.uint8)
    azimuths = np.deg2rad(np.arange(360) + 0.5)  # CCW, one row per degree
    polar[45, 400] = 200  # azimuth 45.5 deg -> sector 7; range 40.05 m -> ring 10
    cfg = ScanContextConfig(range_cell_m=0.1)
    context = scan_context(polar, azimuths, 0.1, cfg)
    assert context.shape == (CFG.n_rings, CFG.n_sectors)
    assert np.unravel_index(np.argmax(context), context.shape) == (10, 7)
    np.testing.assert_allclose(ring_key(context)[10], context[10].mean())


@pytest.mark.realdata
def test_same_place_closer_than_other_places(oxford_polar_scans) -> None:
    extract = ScanContextExtractor(CFG)
    first, second = extract(*oxford_polar_scans[0]), extract(*oxford_polar_scans[1])
    polar, azimuths, res = oxford_polar_scans[0]
    shuffled = extract(polar[np.random.default_rng(0).permutation(len(polar))], azimuths, res)
    other = extract(*render_polar(synthetic_world(1600, seed=1), 0.25, (0.0, 0.0, 0.0)))
    near = _distance(second, first)[0]
    assert near < _distance(shuffled, first)[0]
    assert near < _distance(other, first)[0]


@pytest.mark.realdata
@pytest.mark.parametrize("rows", [100, 200, 300])
def test_rotation_by_whole_sectors_is_exact(oxford_polar_scans, rows: int) -> None:
    """Rolling the 400 polar rows by a multiple of 100 turns the scene by whole sectors."""
    polar, azimuths, res = oxford_polar_scans[0]
    extract = ScanContextExtractor(CFG)
    distance, yaw = _distance(
        extract(np.roll(polar, rows, axis=0), azimuths, res), extract(polar, azimuths, res)
    )
    assert distance == pytest.approx(0.0, abs=1e-6)
    assert np.rad2deg(angle_error(yaw, np.deg2rad(-0.9 * rows))) < 1e-6


@pytest.mark.realdata
@pytest.mark.parametrize("rows", [37, 171, 250])
def test_rotation_by_any_angle_within_a_sector(oxford_polar_scans, rows: int) -> None:
    polar, azimuths, res = oxford_polar_scans[0]
    extract = ScanContextExtractor(CFG)
    reference = extract(polar, azimuths, res)
    distance, yaw = _distance(extract(np.roll(polar, rows, axis=0), azimuths, res), reference)
    assert distance < _distance(extract(*oxford_polar_scans[1]), reference)[0]
    assert np.rad2deg(angle_error(yaw, np.deg2rad(-0.9 * rows))) <= SECTOR_DEG


def test_recognizer_interface_matches_raplace(tmp_path) -> None:
    for method in ("add", "add_batch", "query", "save", "load", "is_loop", "keys"):
        assert hasattr(ScanContextRecognizer, method) and hasattr(PlaceRecognizer, method)
    rng = np.random.default_rng(0)
    contexts = rng.uniform(0, 50, (15, CFG.n_rings, CFG.n_sectors)).astype(np.float32)
    cfg = ScanContextConfig(exclusion=ExclusionConfig(recent_keyframes=4, recent_seconds=0.0))
    recognizer = ScanContextRecognizer(cfg)
    for i, context in enumerate(contexts):
        recognizer.add(context, key=10 * i, time_s=float(i))
    best = recognizer.query(np.roll(contexts[3], 5, axis=1), k=1)[0]
    assert (best.key, best.index) == (30, 3)
    assert best.distance == pytest.approx(0.0, abs=1e-6)
    assert np.rad2deg(best.yaw_rad) == pytest.approx(5 * SECTOR_DEG)
    assert all(c.index < 11 for c in recognizer.query(contexts[14], k=20))
    path = tmp_path / "sc.npz"
    recognizer.save(path)
    loaded = ScanContextRecognizer.load(path)
    assert loaded.cfg == cfg
    assert loaded.query(contexts[6], k=3) == recognizer.query(contexts[6], k=3)
    with pytest.raises(RaPlaceError):
        PlaceRecognizer.load(path)
    with pytest.raises(RaPlaceError):
        recognizer.add(np.zeros((3, 3)), key=0)
