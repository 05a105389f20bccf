"""The long-drive scenario `long_city` is city-length with revisits (checked on its lattice route,
without laying out the town: that takes seconds)."""

from __future__ import annotations

from collections import Counter

from radar_slam.sim.route import expand_waypoints
from radar_slam.sim.scenarios import get_scenario

MIN_ROUTE_M = 20_000.0


def test_long_city_is_city_length_with_revisits_both_ways() -> None:
    scenario = get_scenario("long_city")
    assert scenario.max_frames == 10_000
    nodes = expand_waypoints(list(scenario.waypoints))
    steps = list(zip(nodes[:-1], nodes[1:], strict=True))
    assert all(abs(a[0] - b[0]) + abs(a[1] - b[1]) == 1 for a, b in steps)  # lattice moves
    block_x, block_y = scenario.town.block_size_m
    length = sum(block_x if a[1] == b[1] else block_y for a, b in steps)
    assert length >= MIN_ROUTE_M
    # Driven at 8-12 m/s cruise (slower in turns) it lasts about 11,000 scans; 10,000 are kept.
    edges = Counter(frozenset(step) for step in steps)
    revisited = sum(n for n in edges.values() if n > 1) / len(steps)
    assert revisited > 0.6
    directions = Counter(steps)
    reversed_ = sum(1 for a, b in directions if (b, a) in directions)
    assert reversed_ >= 40  # many streets driven both ways
