"""The loop throttle (`radar_slam.loops.throttle`): along a stretch closed by consecutive accepted
loops, verifications are bounded to one per `closed_spacing_m` of travel; off the stretch, after
a failed verification or a rejected loop, every query is verified again."""

from __future__ import annotations

import numpy as np
import pytest

from radar_slam.loops import StretchThrottle, ThrottleConfig
from radar_slam.loops.throttle import CLOSED_AFTER, direction_of

SPACING_M = 4.0  # database / query spacing along the path [m]
FIRST_DRIVE_M = 400.0  # the revisited road, driven first from path 0 to here
REVISIT_START_M = 1000.0  # the revisit starts at this path length [m]
SCALE = 1.01  # the second drive's odometry path grows 1 % faster than the first's


class Simulation:
    """Queries every `SPACING_M`, the candidate given by `match_of`, verified by an oracle that
    passes a candidate within 6 m of the true match; the gate accepts every verified loop."""

    def __init__(self, cfg: ThrottleConfig) -> None:
        self.throttle = StretchThrottle(cfg)
        self.verified: list[float] = []  # query paths of the verifications run
        self.decisions = 0

    def query(self, q: float, match: float, truth: float | None, yaw: float = 0.0) -> None:
        if not self.throttle.due(q, [match]):
            return
        ok = truth is not None and abs(match - truth) < 6.0
        decision = self.decisions
        self.decisions += 1
        self.verified.append(q)
        self.throttle.verified(decision, q, match, yaw, ok)
        if ok:
            self.throttle.resolved({decision: "accepted"})


def revisit(sim: Simulation, length_m: float, reverse: bool = False) -> None:
    """Drive `length_m` along the first drive's road (the same way or the opposite way)."""
    for n in range(int(length_m / SPACING_M)):
        q = REVISIT_START_M + n * SPACING_M
        along = n * SPACING_M / SCALE
        truth = FIRST_DRIVE_M - along if reverse else along
        sim.query(q, truth, truth, np.pi if reverse else 0.0)


@pytest.mark.parametrize("reverse", [False, True])
def test_verifications_along_a_closed_stretch_are_bounded(reverse: bool) -> None:
    cfg = ThrottleConfig(closed_spacing_m=20.0)
    sim = Simulation(cfg)
    revisit(sim, 360.0, reverse)
    queries = int(360.0 / SPACING_M)
    # Three loops close the stretch, then one verification per 20 m (the query spacing rounds
    # 20 m up to 20 or 24 m).
    assert CLOSED_AFTER + 360.0 / 20.0 >= len(sim.verified) >= 360.0 / 24.0
    assert sim.throttle.skipped == queries - len(sim.verified)
    gaps = np.diff(sim.verified[CLOSED_AFTER:])
    assert np.all(gaps >= cfg.closed_spacing_m) and np.all(gaps <= cfg.closed_spacing_m + SPACING_M)
    (stretch,) = sim.throttle.stretches
    assert stretch.direction == (-1 if reverse else 1)


def test_no_throttling_when_disabled() -> None:
    sim = Simulation(ThrottleConfig(closed_spacing_m=0.0))
    revisit(sim, 200.0)
    assert len(sim.verified) == 50 and sim.throttle.skipped == 0


def test_candidates_off_the_stretch_and_failures_return_to_full_rate() -> None:
    cfg = ThrottleConfig(closed_spacing_m=20.0)
    sim = Simulation(cfg)
    revisit(sim, 100.0)
    assert sim.throttle.skipped > 0
    # A query whose candidate lies elsewhere (not where the stretch predicts) is verified.
    before = len(sim.verified)
    sim.query(1100.0, 300.0, None)
    assert len(sim.verified) == before + 1
    # A failed verification on the stretch ends it: the next queries are all verified.
    q = 1104.0
    while sim.throttle.due(q, [104.0 / SCALE]):
        q += SPACING_M
        assert q < 1200.0
    sim.throttle.verified(sim.decisions, q + 20.0, (104.0 + 20.0) / SCALE, 0.0, ok=False)
    assert not sim.throttle.stretches
    for n in range(5):
        assert sim.throttle.due(q + 24.0 + n * SPACING_M, [(128.0 + n * SPACING_M) / SCALE])


def test_a_rejected_loop_on_the_stretch_ends_it() -> None:
    sim = Simulation(ThrottleConfig(closed_spacing_m=20.0))
    revisit(sim, 100.0)
    throttle = sim.throttle
    q = REVISIT_START_M + 120.0
    throttle.verified(99, q, 120.0 / SCALE, 0.0, ok=True)
    throttle.resolved({99: "pending"})
    assert throttle.stretches  # pending changes nothing
    throttle.resolved({99: "rejected"})
    assert not throttle.stretches
    assert throttle.due(q + SPACING_M, [(120.0 + SPACING_M) / SCALE])


def test_a_stretch_is_forgotten_after_max_gap() -> None:
    cfg = ThrottleConfig(closed_spacing_m=20.0)
    sim = Simulation(cfg)
    revisit(sim, 100.0)
    last = sim.throttle.stretches[0].query_path_m
    # Far beyond the gap the stretch's prediction is not trusted any more.
    q = last + 150.0
    assert sim.throttle.due(q, [(q - REVISIT_START_M) / SCALE])
    assert not sim.throttle.stretches


def test_a_third_drive_keeps_a_stretch_per_earlier_drive() -> None:
    """Best candidates alternating between two earlier drives of the road still throttle."""
    cfg = ThrottleConfig(closed_spacing_m=20.0)
    sim = Simulation(cfg)
    second_drive_offset = 500.0  # the road's second drive started at path 500 m
    for n in range(100):
        q = 2000.0 + n * SPACING_M
        along = n * SPACING_M / SCALE
        match = along + (second_drive_offset if n % 2 else 0.0)
        sim.query(q, match, match)
    assert len(sim.throttle.stretches) == 2
    assert len(sim.verified) <= 2 * CLOSED_AFTER + 400.0 / 20.0


def test_direction_from_the_loop_yaw() -> None:
    assert direction_of(0.3) == 1 and direction_of(-0.3) == 1
    assert direction_of(np.pi - 0.2) == -1 and direction_of(-np.pi + 0.2) == -1


def test_anchor_is_the_latest_loop_of_the_closed_stretch_the_match_lies_on() -> None:
    cfg = ThrottleConfig(closed_spacing_m=20.0)
    sim = Simulation(cfg)
    throttle = sim.throttle
    revisit(sim, 8.0)  # two loops: the stretch is not closed yet
    assert throttle.stretches and throttle.anchor(1012.0, 12.0 / SCALE) is None
    revisit(sim, 100.0)
    (stretch,) = throttle.stretches
    assert stretch.decision == sim.decisions - 1  # every verification passed
    q = stretch.query_path_m + 20.0
    on = stretch.match_path_m + 20.0 / SCALE
    assert throttle.anchor(q, on) == stretch.decision
    assert throttle.anchor(q, on + 50.0) is None  # off the stretch
    assert throttle.anchor(q, stretch.match_path_m - 20.0) is None  # the other way along it
