"""The scenarios' routes: lattice waypoints (node indices of the town's street lattice, see
route.py), each scenario's drive from its first node to its last."""

from __future__ import annotations

Waypoints = tuple[tuple[int, int], ...]
"""A route: lattice nodes (i, j) in driving order, consecutive ones joined by one street."""

TINY_ROUTE: Waypoints = ((1, 1), (2, 1), (2, 2), (1, 2))
LOOP_ROUTE: Waypoints = (
    (2, 2),
    (4, 2),
    (4, 3),
    (2, 3),
    (2, 2),
    (4, 2),
    (4, 3),
    (2, 3),
    (2, 2),
    (3, 2),
)
TINY_LOOP_ROUTE: Waypoints = ((1, 1), (2, 1), (2, 2), (1, 2), (1, 1), (2, 1), (2, 2))
"""Around one block of the tiny town and on along one and a half of its streets again."""
_REVERSE_CROSSING = (5, 2)
"""Where the figure-eight of `reverse` crosses itself (lattice node)."""
REVERSE_ROUTE: Waypoints = (
    # Lap 1: the block on the crossing's (+i, +j) side anticlockwise, straight over the
    # crossing, the block on its (-i, -j) side clockwise.
    _REVERSE_CROSSING,
    (6, 2),
    (6, 3),
    (5, 3),
    (5, 1),
    (4, 1),
    (4, 2),
    _REVERSE_CROSSING,
    # Lap 2 (a left turn at the crossing): the same figure-eight in the opposite direction.
    (5, 3),
    (6, 3),
    (6, 2),
    (4, 2),
    (4, 1),
    (5, 1),
    _REVERSE_CROSSING,
)
"""A closed circuit (a figure-eight over two diagonal blocks) driven once, then again in the
opposite direction: every street of it is revisited the other way, in the other lane. The
crossing turns the route around with an ordinary turn (no U-turn), and every corner is driven
once as a left and once as a right turn."""
MULTI_A: Waypoints = ((1, 1), (3, 1), (3, 3), (1, 3), (1, 1), (3, 1))
"""A loop around blocks of the town and its first street again, so that the map session closes
its loop (a route starts and ends in the middle of a street)."""
MULTI_B: Waypoints = (
    (4, 4),
    (4, 2),
    (3, 2),
    (3, 3),
    (1, 3),
    (1, 2),
    (2, 2),
    (2, 4),
    (4, 4),
    (4, 3),
)
REVERSE_SESSION_A: Waypoints = MULTI_A
"""A loop around blocks of the town, driven anticlockwise, its first two blocks again so that
the map session closes its loop."""
REVERSE_SESSION_B: Waypoints = tuple(reversed(REVERSE_SESSION_A))
"""The same streets clockwise: every street the other way, in the other lane."""
TINY_BLOCK: Waypoints = ((1, 1), (2, 1), (2, 2), (1, 2), (1, 1))
"""Once around one block of the tiny town (the map tests)."""
LONG_ROUTE: Waypoints = (
    (1, 1),
    (4, 1),
    (4, 3),
    (1, 3),
    (1, 1),
    (4, 1),
    (7, 1),
    (7, 4),
    (4, 4),
    (4, 1),
    (1, 1),
    (1, 3),
    (4, 3),
    (4, 5),
    (1, 5),
    (1, 3),
    (2, 3),
)

_CITY_RING: Waypoints = ((1, 1), (11, 1), (11, 9), (1, 9), (1, 1))
"""The outer ring of the `long_city` town (12 x 10 blocks), anticlockwise: 3.9 km."""
LONG_CITY_ROUTE: Waypoints = (
    *_CITY_RING,
    # A serpentine across the town along x, ending in the far corner.
    (1, 3),
    (11, 3),
    (11, 5),
    (1, 5),
    (1, 7),
    (11, 7),
    (11, 9),
    # The ring again, clockwise (every ring street revisited the other way).
    (11, 1),
    (1, 1),
    (1, 9),
    (11, 9),
    # A serpentine along y, crossing the first one at every street.
    (9, 9),
    (9, 1),
    (7, 1),
    (7, 9),
    (5, 9),
    (5, 1),
    (3, 1),
    (3, 9),
    (1, 9),
    # The x serpentine back the other way, then the ring anticlockwise once more.
    (1, 7),
    (11, 7),
    (11, 5),
    (1, 5),
    (1, 3),
    (11, 3),
    (11, 1),
    *_CITY_RING,
)
"""About 26 km of streets through a 12 x 10 block town (the first 10,000 scans, ~24 km, are
driven at 8-12 m/s): three laps of the ring (two directions) and two
serpentines crossing each other and the ring, so most streets are revisited, some in reverse."""

TURN_AROUND_ROUTE: Waypoints = ((1, 1), (2, 1), (3, 1), (3, 2), (2, 2), (2, 1), (1, 1), (0, 1))
U_TURN_ROUTE: Waypoints = ((0, 1), (1, 1), (2, 1), (3, 1), (2, 1), (1, 1))
THREE_POINT_ROUTE: Waypoints = ((1, 0), (1, 1), (1, 2), (1, 1), (1, 0))
ROUNDABOUT_ROUTE: Waypoints = ((0, 1), (1, 1), (2, 1), (2, 2), (2, 3))
STOP_AND_GO_ROUTE: Waypoints = ((0, 1), (1, 1), (2, 1), (2, 2), (3, 2))
JUNCTION_ROUTE: Waypoints = ((0, 0), (1, 0), (1, 1), (2, 1), (2, 2), (3, 2), (3, 3))
REVERSE_GEAR_ROUTE: Waypoints = ((0, 1), (1, 1), (2, 1), (2, 2))
ROUNDABOUTS_ROUTE: Waypoints = ((0, 1), (3, 1), (3, 2), (1, 2), (1, 3))
"""Six roundabouts in a row (straight on, straight on, left, left, straight on, right)."""
HELD_OUT_TOWN_ROUTE: Waypoints = (
    (1, 1),
    (3, 1),
    (3, 3),
    (4, 3),
    (4, 4),
    (3, 4),
    (3, 3),
    (2, 3),
    (2, 2),
    (0, 2),
    (1, 2),
)
"""Out, round a block and back along the street it came (as the 25 % drift town drive), on, and
back again after a U-turn."""
HELD_OUT_JUNCTIONS_ROUTE: Waypoints = (
    (0, 0),
    (1, 0),
    (1, 1),
    (2, 1),
    (2, 2),
    (3, 2),
    (3, 3),
    (4, 3),
    (3, 3),
    (3, 4),
    (2, 4),
    (1, 4),
    (1, 3),
    (0, 3),
)
"""A staircase of junction turns on small blocks, a U-turn short of a node and back, then a
reversing stretch and more turns (a held-out drive)."""
HELD_OUT_MIXED_ROUTE: Waypoints = (
    (0, 1),
    (1, 1),
    (2, 1),
    (2, 2),
    (3, 2),
    (4, 2),
    (3, 2),
    (3, 3),
    (2, 3),
    (1, 3),
    (1, 2),
)
HELD_OUT_REVISITS_ROUTE: Waypoints = (
    (0, 1),
    (2, 1),
    (2, 3),
    (0, 3),
    (0, 1),
    (2, 1),
    (3, 1),
    (2, 1),
    (0, 1),
    (0, 3),
    (2, 3),
)
"""Round a ring of blocks, on past its start, a U-turn, and back round the ring the other way
(a held-out drive with revisits in both directions)."""
