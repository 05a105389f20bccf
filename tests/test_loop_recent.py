"""What a loop query may match (radar_slam.loops.recent): the stretch just driven is held back by
path length, so the revisit right after a turn-around is found at any frame rate; candidates the
odometry places out of the verifier's reach are not verified."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from radar_slam.datasets import open_sequence
from radar_slam.datasets.stride import strided
from radar_slam.loops import LoopDetector
from radar_slam.loops.config import LoopClosureConfig
from radar_slam.loops.recent import HeldBackDatabase, held_back_retrieval, within_reach
from raplace import se2
from raplace.config import ExclusionConfig, RetrievalConfig

TRUE_LOOP_M = 1.0  # an accepted loop's translation error on the ground truth [m] ...
TRUE_LOOP_DEG = 2.0  # ... and rotation error [deg]
MIN_LOOPS = 3  # accepted on the way back after the three-point turn (7 at 4 Hz and at 1 Hz)


class _Store:
    """A database that only records what it receives."""

    def __init__(self) -> None:
        self.keys: list[int] = []

    def __len__(self) -> int:
        return len(self.keys)

    def add(self, descriptor: object, key: int, time_s: float | None = None) -> None:
        self.keys.append(key)

    def query(self, descriptor: object, k: int = 1, time_s: float | None = None) -> list:
        return []


def test_held_back_by_path_then_by_count_and_seconds() -> None:
    store = _Store()
    held = HeldBackDatabase(store, 50.0, ExclusionConfig(recent_keyframes=2, recent_seconds=1.0))
    for k, path in enumerate([0.0, 20.0, 49.0, 60.0]):
        held.release(float(k), path)
        held.hold(None, k, float(k), path)
    assert store.keys == [0]  # at 60 m only the scan at 0 m is 50 m back
    held.release(4.0, 99.9)
    assert store.keys == [0, 1, 2]  # the one at 60 m is 39.9 m back
    held.flush()
    assert store.keys == [0, 1, 2, 3] and len(held) == 0
    # without a path length: after 2 newer scans and 1 s
    store = _Store()
    held = HeldBackDatabase(store, 50.0, ExclusionConfig(recent_keyframes=2, recent_seconds=1.0))
    for k in range(4):
        held.release(0.25 * k, None)
        held.hold(None, k, 0.25 * k, None)
    held.release(1.0, None)
    assert store.keys == [0]  # scan 1 (0.25 s) has 2 newer scans but is only 0.75 s old


def test_within_reach_allows_the_odometry_its_drift() -> None:
    query = np.array([0.0, 0.0, 0.0])
    matches = np.array([[14.0, 0.0, 0.0], [30.0, 0.0, 3.0], [30.0, 0.0, 0.0], [0.0, 16.0, 1.0]])
    gaps = np.array([100.0, 100.0, 400.0, 10.0])
    # reach 15 m + 5 % of the path: 20, 20, 35, 15.5 m
    assert within_reach(query, matches, gaps, 15.0, 0.05).tolist() == [True, False, True, False]
    assert within_reach(query, matches, gaps, 15.0, np.inf).all()


def test_own_database_excludes_nothing_itself_when_held_back() -> None:
    retrieval = RetrievalConfig()
    assert retrieval.exclusion.recent_keyframes > 0
    assert held_back_retrieval(retrieval, 50.0).exclusion == ExclusionConfig(0, 0.0)
    assert held_back_retrieval(retrieval, 0.0) == retrieval


def _loops_on_ground_truth(
    synthetic_root: Path, scenario: str, stride: int, config: LoopClosureConfig
) -> tuple[list, np.ndarray, np.ndarray]:
    """The accepted loops of a `LoopDetector` fed the ground-truth poses, and the scans' times
    and poses."""
    sequence = strided(open_sequence(f"synthetic/{scenario}", synthetic_root), stride)
    truth = sequence.ground_truth
    assert truth is not None
    detector = LoopDetector(config, scan_loader=lambda k: sequence[k])
    loops = []
    for k in range(len(sequence)):
        loops += detector.add(sequence[k], truth[k], key=k)
    loops += detector.finish()
    assert len(detector.recognizer) == len(detector)  # every scan in the database at the end
    return loops, np.asarray(sequence.timestamps_ns), truth


@pytest.mark.parametrize("stride", [1, 4])
def test_the_way_back_after_a_three_point_turn_closes_loops(
    synthetic_root: Path, stride: int
) -> None:
    """tiny_three_point_turn drives a street, turns in three moves and drives back along it:
    the loops between the two directions are found at 4 Hz and at 1 Hz, and all are true.
    Counting database entries instead (RaPlace's own exclusion) hides the whole way out."""
    config = LoopClosureConfig()
    loops, _, truth = _loops_on_ground_truth(
        synthetic_root, "tiny_three_point_turn", stride, config
    )
    assert len(loops) >= MIN_LOOPS
    for loop in loops:
        expected = se2.between(truth[loop.i], truth[loop.j])
        error = se2.compose(se2.inverse(expected), loop.measurement)
        assert np.hypot(error[0], error[1]) < TRUE_LOOP_M
        assert abs(np.rad2deg(error[2])) < TRUE_LOOP_DEG
        assert abs(se2.wrap_angle(expected[2])) > np.pi / 2  # the other direction
    by_count = dataclasses.replace(config, recent_path_m=0.0)
    assert (
        _loops_on_ground_truth(synthetic_root, "tiny_three_point_turn", stride, by_count)[0] == []
    )
