"""PR evaluation core: known-answer sweeps, revisit truth with the exclusion window, modes."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from raplace_scenes import render_polar, synthetic_world

from radar_slam.datasets import RadarFrame, RadarSequence
from radar_slam.placerec import (
    NO_MATCH,
    BestMatches,
    PlaceRecognitionError,
    build_map,
    evaluate_matches,
    intra_session_candidate_counts,
    match_intra_session,
    match_queries,
    match_within_criterion,
    method_runs,
    path_length_m,
    pr_curve,
    revisit_truth,
    standing_queries,
    sweep_thresholds,
    with_exclusion,
)
from radar_slam.sim.family import open_synthetic
from radar_slam.sim.generate import generate_sequence
from radar_slam.sim.scenarios import SCENARIOS
from raplace.config import ExclusionConfig, RaPlaceConfig
from raplace.retrieval import candidate_mask
from raplace.units import NS_PER_S

INF = float("inf")
# Six queries with hand-counted outcomes: best-match distance, match within the criterion,
# query is a true revisit (4 revisits; query 4 is a revisit without any candidate match).
DISTANCES = np.array([0.1, 0.2, 0.3, 0.4, INF, 0.5])
CORRECT = np.array([True, False, True, False, False, False])
REVISIT = np.array([True, True, True, False, True, False])


def test_sweep_counts_at_given_thresholds() -> None:
    curve = pr_curve(DISTANCES, CORRECT, REVISIT, thresholds=np.array([0.05, 0.25, 0.35, 1.0]))
    np.testing.assert_array_equal(curve.true_positives, [0, 1, 2, 2])
    np.testing.assert_array_equal(curve.false_positives, [0, 1, 1, 3])
    np.testing.assert_allclose(curve.precision, [1.0, 0.5, 2 / 3, 0.4])
    np.testing.assert_allclose(curve.recall, [0.0, 0.25, 0.5, 0.5])
    assert curve.queries == 6
    assert curve.true_revisits == 4
    assert curve.recall_at_1 == pytest.approx(0.5)
    assert curve.max_f1 == pytest.approx(4 / 7)  # P 2/3, R 1/2
    assert curve.threshold_at_max_f1 == pytest.approx(0.35)


def test_full_sweep_is_exact() -> None:
    curve = pr_curve(DISTANCES, CORRECT, REVISIT)
    # One threshold below everything, then one just above each distinct finite distance.
    assert len(curve.thresholds) == 6
    np.testing.assert_array_equal(curve.true_positives, [0, 1, 1, 2, 2, 2])
    np.testing.assert_array_equal(curve.false_positives, [0, 0, 1, 1, 2, 3])
    assert curve.max_f1 == pytest.approx(4 / 7)
    # Trapezoids over (R, P): (0, 1) (.25, 1) (.25, .5) (.5, 2/3) (.5, .5) (.5, .4).
    assert curve.auc == pytest.approx(0.25 + 0.25 * (0.5 + 2 / 3) / 2)
    np.testing.assert_allclose(curve.f1[3], 4 / 7)


def test_a_distance_equal_to_the_threshold_is_negative() -> None:
    curve = pr_curve(np.array([0.2]), np.array([True]), np.array([True]), np.array([0.2]))
    assert curve.true_positives[0] == 0
    thresholds = sweep_thresholds(np.array([0.2, 0.2, INF]))
    assert thresholds[0] == 0.2 and thresholds[1] > 0.2 and len(thresholds) == 2


def test_no_revisit_and_no_candidate() -> None:
    curve = pr_curve(np.array([INF, 0.3]), np.array([False, False]), np.array([False, False]))
    assert curve.true_revisits == 0
    assert curve.max_f1 == 0.0 and curve.auc == 0.0 and curve.recall_at_1 == 0.0
    empty = pr_curve(np.array([INF]), np.array([False]), np.array([True]))
    assert len(empty.thresholds) == 0 and empty.max_f1 == 0.0


def test_bad_inputs_are_errors() -> None:
    with pytest.raises(PlaceRecognitionError, match="exclusion window"):
        pr_curve(np.array([0.1]), np.array([True]), np.array([False]))
    with pytest.raises(PlaceRecognitionError, match="one length"):
        pr_curve(np.array([0.1, 0.2]), np.array([True]), np.array([True]))
    with pytest.raises(PlaceRecognitionError, match="increasing"):
        pr_curve(DISTANCES, CORRECT, REVISIT, thresholds=np.array([0.3, 0.1]))


def out_and_back(n_out: int = 10, step_m: float = 1.0) -> np.ndarray:
    """(2 n_out, 2) positions: x = 0..n_out-1 steps out along x, then the same back."""
    x = np.arange(n_out) * step_m
    return np.stack([np.concatenate([x, x[::-1]]), np.zeros(2 * n_out)], axis=1)


def brute_force_revisits(xy: np.ndarray, counts: np.ndarray, criterion_m: float) -> np.ndarray:
    return np.array(
        [
            any(np.hypot(*(xy[i] - xy[j])) <= criterion_m for j in range(counts[i]))
            for i in range(len(xy))
        ]
    )


def test_revisit_truth_respects_the_exclusion_window() -> None:
    xy = out_and_back()  # frame 10 at x = 9, frame 15 at x = 4, frame 19 at x = 0
    counts = intra_session_candidate_counts(np.arange(20.0), ExclusionConfig(5, 0.0))
    np.testing.assert_array_equal(counts[:7], [0, 0, 0, 0, 0, 0, 1])
    revisit = revisit_truth(xy, xy, counts, criterion_m=1.5)
    assert not revisit[:12].any()  # outbound frames and the turn: neighbours are excluded
    assert not revisit[10]  # x = 9 may match only x <= 4
    assert revisit[15] and revisit[19]  # x = 4 matches frame 4, x = 0 matches frame 0
    np.testing.assert_array_equal(revisit, brute_force_revisits(xy, counts, 1.5))
    # Without exclusion every frame after the first is a revisit of its predecessor.
    everything = intra_session_candidate_counts(np.arange(20.0), ExclusionConfig(0, 0.0))
    assert revisit_truth(xy, xy, everything, 1.5)[1:].all()


def test_revisit_truth_in_blocks_matches_brute_force(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(3)
    xy = np.cumsum(rng.normal(0, 3, (200, 2)), axis=0)
    counts = intra_session_candidate_counts(np.arange(200.0), ExclusionConfig(7, 0.0))
    expected = brute_force_revisits(xy, counts, 10.0)
    monkeypatch.setattr("radar_slam.placerec.TRUTH_BLOCK_ELEMENTS", 1000)  # 5 queries a block
    np.testing.assert_array_equal(revisit_truth(xy, xy, counts, 10.0), expected)


def test_candidate_counts_agree_with_the_recognizers_mask() -> None:
    times = np.cumsum(np.full(30, 0.25)) + np.r_[np.zeros(15), np.full(15, 3.0)]  # with a gap
    for exclusion in (ExclusionConfig(4, 0.0), ExclusionConfig(2, 2.0), ExclusionConfig(0, 0.9)):
        counts = intra_session_candidate_counts(times, exclusion)
        for i in range(len(times)):
            mask = candidate_mask(times[:i], float(times[i]), exclusion)
            assert mask.sum() == counts[i] and mask[: counts[i]].all()


def test_candidate_counts_need_increasing_times() -> None:
    with pytest.raises(PlaceRecognitionError, match="increasing"):
        intra_session_candidate_counts(np.array([0.0, 2.0, 1.0]), ExclusionConfig(0, 1.0))


def test_multi_session_evaluation() -> None:
    map_xy = np.stack([np.arange(0.0, 100.0, 5.0), np.zeros(20)], axis=1)  # along x
    query_xy = np.array([[12.0, 3.0], [48.0, -2.0], [0.0, 60.0], [90.0, 0.0]])
    counts = np.full(4, len(map_xy))
    np.testing.assert_array_equal(
        revisit_truth(query_xy, map_xy, counts, 10.0), [True, True, False, True]
    )
    matches = BestMatches(
        method="raplace",
        query_index=np.arange(4),
        match_index=np.array([2, 15, 3, NO_MATCH]),  # right, wrong, (not a revisit), none
        distance=np.array([0.1, 0.2, 0.3, INF]),
        yaw_rad=np.zeros(4),
        seconds=0.0,
        descriptor_seconds=0.0,
    )
    np.testing.assert_array_equal(
        match_within_criterion(query_xy, map_xy, matches.match_index, 10.0),
        [True, False, False, False],
    )
    curve = evaluate_matches(matches, query_xy, map_xy, counts, 10.0)
    assert curve.true_revisits == 3
    assert curve.recall_at_1 == pytest.approx(1 / 3)
    assert curve.max_f1 == pytest.approx(0.5)  # P 1, R 1/3


# A small world and a route: out along a 200 m street with turns, then back the opposite way.
WORLD_CELL_M = 0.5
WORLD_PX = 1000


def route(step_m: float = 4.0) -> np.ndarray:
    """(n, 3) poses: 160 m out along x, then back in the opposite direction, 3 m to the side."""
    out = np.arange(-80.0, 80.0, step_m)
    back = out[::-1]
    outbound = np.stack([out, np.zeros_like(out), np.zeros_like(out)], axis=1)
    inbound = np.stack([back, np.full_like(back, -3.0), np.full_like(back, np.pi)], axis=1)
    return np.concatenate([outbound, inbound])


def frames_along(poses: np.ndarray, seed: int) -> list[RadarFrame]:
    world = synthetic_world(WORLD_PX, seed=seed)
    frames = []
    for i, pose in enumerate(poses):
        polar, azimuths, res = render_polar(world, WORLD_CELL_M, tuple(pose), n_bins=900)
        noise = np.random.default_rng(i).integers(0, 12, polar.shape, dtype=np.uint8)
        frames.append(RadarFrame(i * 250_000_000, polar + noise, azimuths, res, "sim"))
    return frames


def test_reverse_route_detects_loops_and_excludes_recent() -> None:
    poses = route()
    frames = frames_along(poses, seed=5)
    exclusion = ExclusionConfig(recent_keyframes=8, recent_seconds=0.0)
    cfg = with_exclusion(RaPlaceConfig(), exclusion)
    runs = method_runs(["raplace", "scancontext"], cfg)
    results = match_intra_session(enumerate(frames), runs)
    counts = intra_session_candidate_counts(np.arange(len(frames)) * 0.25, exclusion)
    for matches in results.values():
        # Every match respects the window the truth uses (pr_curve would also refuse otherwise).
        found = matches.match_index != NO_MATCH
        assert np.all(matches.match_index[found] < counts[found])
        assert np.all((matches.match_index == NO_MATCH) == (counts == 0))
    curve = evaluate_matches(results["raplace"], poses[:, :2], poses[:, :2], counts, 20.0)
    assert curve.true_revisits > 30
    assert curve.max_f1 >= 0.9, curve
    assert curve.recall_at_1 >= 0.9


def test_multi_session_runs_see_the_whole_map() -> None:
    poses = route(step_m=8.0)[:20]
    map_frames = frames_along(poses, seed=9)
    query_poses = poses + np.array([1.5, 1.0, 0.3])
    query_frames = frames_along(query_poses, seed=9)
    cfg = with_exclusion(RaPlaceConfig(), ExclusionConfig(0, 0.0))
    runs = method_runs(["raplace"], cfg)
    build_map(enumerate(map_frames), runs)
    results = match_queries(enumerate(query_frames), runs)
    matches = results["raplace"]
    np.testing.assert_array_equal(matches.match_index, np.arange(20))  # the last too
    counts = np.full(20, 20)
    curve = evaluate_matches(matches, query_poses[:, :2], poses[:, :2], counts, 10.0)
    assert curve.max_f1 == pytest.approx(1.0)
    assert matches.seconds >= matches.descriptor_seconds > 0


def test_unknown_method() -> None:
    with pytest.raises(PlaceRecognitionError, match="unknown method"):
        method_runs(["netvlad"], RaPlaceConfig())


# A small simulated drive (radar_slam.sim): two blocks east, one north, back west, and the
# first block again in the opposite direction; 61 m range, about 130 scans.
SMALL_REVERSE_ROUTE = ((1, 1), (3, 1), (3, 2), (2, 2), (2, 1), (1, 1))
SMALL_BLOCKS_M = (45.0, 55.0)
SMALL_EXCLUDE = 40


@pytest.fixture(scope="module")
def small_reverse(tmp_path_factory: pytest.TempPathFactory) -> RadarSequence:
    tiny = SCENARIOS["tiny"]
    scenario = replace(
        tiny,
        name="pr_small_reverse",
        waypoints=SMALL_REVERSE_ROUTE,
        town_routes=(SMALL_REVERSE_ROUTE,),
        max_frames=None,
        town=replace(tiny.town, block_size_m=SMALL_BLOCKS_M),
    )
    folder = tmp_path_factory.mktemp("sim") / scenario.name
    generate_sequence(scenario, folder, workers=0)
    return open_synthetic(folder)


def test_simulated_reverse_revisits(small_reverse: RadarSequence) -> None:
    """RaPlace finds the opposite-direction revisits that Scan Context mostly misses."""
    exclusion = ExclusionConfig(SMALL_EXCLUDE, 0.0)
    runs = method_runs(["raplace", "scancontext"], with_exclusion(RaPlaceConfig(), exclusion))
    frames = ((i, small_reverse[i]) for i in range(len(small_reverse)))
    results = match_intra_session(frames, runs)
    xy = small_reverse.ground_truth[:, :2]
    times_s = small_reverse.timestamps_ns / NS_PER_S
    counts = intra_session_candidate_counts(times_s, exclusion)
    curves = {m: evaluate_matches(r, xy, xy, counts, 20.0) for m, r in results.items()}
    assert curves["raplace"].true_revisits >= 15
    assert curves["raplace"].max_f1 >= 0.85, curves["raplace"]
    assert curves["raplace"].recall_at_1 >= 0.85
    assert curves["raplace"].max_f1 > curves["scancontext"].max_f1 + 0.15


def stand_in_line() -> tuple[np.ndarray, np.ndarray]:
    """(times [s], (60, 2) positions [m]): 10 frames 5 m apart along x, 40 frames standing at
    x = 45 m, then 10 frames on, 5 m apart. A straight line: no true revisit of a place."""
    x = np.r_[np.arange(10) * 5.0, np.full(40, 45.0), 50.0 + np.arange(10) * 5.0]
    return np.arange(60) * 0.25, np.stack([x, np.zeros_like(x)], axis=1)


def test_a_stand_inflates_frame_based_revisits_not_distance_based_ones() -> None:
    times, xy = stand_in_line()
    travelled = path_length_m(xy)
    frames_only = ExclusionConfig(recent_keyframes=8, recent_seconds=0.0)
    by_frames = intra_session_candidate_counts(times, frames_only)
    by_metres = intra_session_candidate_counts(times, frames_only, travelled, recent_metres=12.0)
    # Frames: stand queries 16-49 reach frames 7-9 (x 35-45 m) and frames 50, 51 the stand.
    assert revisit_truth(xy, xy, by_frames, 10.0).sum() == 36
    assert revisit_truth(xy, xy, by_metres, 10.0).sum() == 0
    standing = standing_queries(times, frames_only, travelled, 10.0)
    np.testing.assert_array_equal(np.flatnonzero(standing), np.r_[np.arange(17, 50), 50])


def test_distance_counts_agree_with_held_back_insertion() -> None:
    times, xy = stand_in_line()
    travelled = path_length_m(xy)
    np.testing.assert_allclose(travelled[[0, 9, 49, 59]], [0.0, 45.0, 45.0, 95.0])
    counts = intra_session_candidate_counts(
        times, ExclusionConfig(2, 0.0), travelled, recent_metres=7.0
    )
    assert np.all(np.diff(counts) >= 0)
    for i, count in enumerate(counts):
        assert np.all(travelled[i] - travelled[:count] >= 7.0)
        assert count == 0 or count >= i - 2 or travelled[i] - travelled[count] < 7.0
    with pytest.raises(PlaceRecognitionError, match="distances travelled"):
        intra_session_candidate_counts(times, ExclusionConfig(0, 0.0), None, 5.0)
