"""Dropped scans: a real recording loses scans now and then. A second of scans (four at 4 Hz)
goes missing just as the car turns into a corner: the next scan lands 7.6 m and 35 deg from the
last one, where the constant-velocity prediction (straight on, 10 m) is metres and tens of
degrees off. Rendered by the simulator in the `tiny` town, so every pose is known."""

from __future__ import annotations

import numpy as np
from test_odometry_recovery import (  # noqa: F401
    FINE_CELL_M,
    LARGE_ERROR_DEG,
    LARGE_ERROR_M,
    MAX_STEP_HEADING_DEG,
    START_S,
    drive,
    errors,
    run,
    tiny_scene,
)

from radar_slam.sim.generate import Scene
from radar_slam.sim.render import RenderTables
from raplace import se2

PERIOD_S = 0.25
STRAIGHT_S = 1.5
DROPPED = range(6, 10)
"""The scans lost: the second from the end of the straight (1 s at 4 Hz)."""


def test_scans_dropped_at_a_turn_register_without_gaps(
    tiny_scene: tuple[Scene, RenderTables],  # noqa: F811
) -> None:
    """The scan after the drop registers against a scan before it (no gap), within
    `LARGE_ERROR_M` of its true position; its heading is off by the de-skew of a turn the
    velocity did not know yet (`MAX_STEP_HEADING_DEG`), and the scans after it are back within
    `LARGE_ERROR_DEG` and one fine pixel."""
    legs = [
        (STRAIGHT_S, np.array([8.0, 0.0, 0.0])),
        (2.5, np.array([6.0, 0.0, np.deg2rad(35.0)])),
    ]
    frames, truth = drive(*tiny_scene, START_S[0], legs, period_s=PERIOD_S)
    kept = [k for k in range(len(frames)) if k not in DROPPED]
    jump = se2.between(truth[DROPPED[0] - 1], truth[DROPPED[-1] + 1])
    assert np.hypot(jump[0], jump[1]) > 7.0 and np.rad2deg(jump[2]) > 30.0

    odometry = run([frames[k] for k in kept])
    assert odometry.gaps == []
    after = odometry.results[DROPPED[0]]
    assert after.ok and after.keyframe_index < DROPPED[0]
    error_m, error_deg = errors(after.pose, truth[DROPPED[-1] + 1])
    assert error_m <= LARGE_ERROR_M and error_deg <= MAX_STEP_HEADING_DEG, (error_m, error_deg)
    later = np.array(
        [errors(odometry.poses[n], truth[k]) for n, k in enumerate(kept) if n > DROPPED[0]]
    )
    assert later[:, 0].max() <= FINE_CELL_M and later[:, 1].max() <= LARGE_ERROR_DEG, later
