"""Orchestration: the SLAM runner, the odometry-only runner, loops on another odometry's graph.

    config.py         PipelineConfig and how it is loaded (defaults, family YAML, user file)
    records.py        Progress, Results, SlamMetrics, OdometryRun, GraphLoopsRun
    steps.py          steps shared by the runners (ground truth, accuracy, loop review, ...)
    slam.py           Pipeline: odometry -> pose graph <- verified loops
    odometry_only.py  run_odometry
    graph_loops.py    close_loops_on_graph

Library code: no printing, no files (see `radar_slam.outputs` and `radar_slam.commands`).
"""

from radar_slam.pipeline.config import (
    PipelineConfig,
    family_config_path,
    load_config,
    open_configurations,
    open_configured,
)
from radar_slam.pipeline.graph_loops import close_loops_on_graph
from radar_slam.pipeline.odometry_only import run_odometry
from radar_slam.pipeline.records import (
    GraphLoopsRun,
    OdometryRun,
    Progress,
    ProgressCallback,
    Results,
    SlamMetrics,
)
from radar_slam.pipeline.slam import MEMORY_BUDGET_BYTES, MEMORY_BUDGET_SCANS, Pipeline
from radar_slam.pipeline.steps import (
    BACKEND_REJECT_WEIGHT,
    StepTimer,
    accuracy,
    frame_count,
    ground_truth_of,
    odometry_factor,
    review_loops,
    sequence_label,
    summarise,
)

__all__ = [
    "BACKEND_REJECT_WEIGHT",
    "MEMORY_BUDGET_BYTES",
    "MEMORY_BUDGET_SCANS",
    "GraphLoopsRun",
    "OdometryRun",
    "Pipeline",
    "PipelineConfig",
    "Progress",
    "ProgressCallback",
    "Results",
    "SlamMetrics",
    "StepTimer",
    "accuracy",
    "close_loops_on_graph",
    "family_config_path",
    "frame_count",
    "ground_truth_of",
    "load_config",
    "odometry_factor",
    "open_configured",
    "open_configurations",
    "review_loops",
    "run_odometry",
    "sequence_label",
    "summarise",
]
