"""radar-slam: radar pose-graph SLAM with phase-correlation odometry and RaPlace loop closure.

The public API, importable from here (each name loads only its own module, so
`from radar_slam import LoopDetector` loads no GTSAM):

    open_sequence, RadarSequence        datasets (`family/sequence` or a folder)
    Pipeline, PipelineConfig, load_config, Results
    LoopDetector, LoopClosureConfig, LoopConstraint, LoopDecision
    PoseGraph, GraphConfig, add_loop_factors
    Trajectory, evaluate                trajectories and their accuracy against ground truth
    RadarSlamError                      base of every user-facing error
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from radar_slam.lazy import lazy_exports

__version__ = "0.1.0"

logging.getLogger(__name__).addHandler(logging.NullHandler())

_EXPORTS = {
    "open_sequence": "radar_slam.datasets",
    "RadarSequence": "radar_slam.datasets",
    "Pipeline": "radar_slam.pipeline",
    "PipelineConfig": "radar_slam.pipeline",
    "load_config": "radar_slam.pipeline",
    "Results": "radar_slam.pipeline",
    "LoopDetector": "radar_slam.loops",
    "LoopClosureConfig": "radar_slam.loops",
    "LoopConstraint": "radar_slam.loops",
    "LoopDecision": "radar_slam.loops",
    "PoseGraph": "radar_slam.graph",
    "GraphConfig": "radar_slam.graph",
    "add_loop_factors": "radar_slam.factors",
    "Trajectory": "radar_slam.trajectory",
    "evaluate": "radar_slam.evaluation.metrics",
    "RadarSlamError": "radar_slam.errors",
}

__all__ = [
    "GraphConfig",
    "LoopClosureConfig",
    "LoopConstraint",
    "LoopDecision",
    "LoopDetector",
    "Pipeline",
    "PipelineConfig",
    "PoseGraph",
    "RadarSequence",
    "RadarSlamError",
    "Results",
    "Trajectory",
    "add_loop_factors",
    "evaluate",
    "load_config",
    "open_sequence",
]

if TYPE_CHECKING:
    from radar_slam.datasets import RadarSequence, open_sequence
    from radar_slam.errors import RadarSlamError
    from radar_slam.evaluation.metrics import evaluate
    from radar_slam.factors import add_loop_factors
    from radar_slam.graph import GraphConfig, PoseGraph
    from radar_slam.loops import LoopClosureConfig, LoopConstraint, LoopDecision, LoopDetector
    from radar_slam.pipeline import Pipeline, PipelineConfig, Results, load_config
    from radar_slam.trajectory import Trajectory


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
