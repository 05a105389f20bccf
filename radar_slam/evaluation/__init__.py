"""Evaluation against ground truth: trajectory metrics, loop judging, false-loop injection.

    metrics.py      ATE / RPE / KITTI drift (evo), association, alignment
    truth.py        whether a loop closure is true (`is_true_loop`)
    false_loops.py  false-loop injection for robustness experiments (tests, benchmarks)
    nees.py         NEES of pose-graph between-factors against the ground truth

The library core (raplace, odometry, loops, graph, datasets, sim) never imports this package.
"""

from radar_slam.evaluation.metrics import TrajectoryMetrics, evaluate
from radar_slam.evaluation.truth import is_true_loop

__all__ = ["TrajectoryMetrics", "evaluate", "is_true_loop"]
