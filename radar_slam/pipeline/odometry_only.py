"""Odometry alone over a sequence (`radar-slam odometry`)."""

from __future__ import annotations

import time

import numpy as np

from odometry import Odometry
from radar_slam.datasets.frame import RadarSequence
from radar_slam.pipeline.concurrency import ScanReader
from radar_slam.pipeline.config import PipelineConfig
from radar_slam.pipeline.records import (
    OdometryRun,
    Progress,
    ProgressCallback,
)
from radar_slam.pipeline.steps import (
    accuracy,
    frame_count,
    ground_truth_of,
    gt_accuracy_m,
    gt_report_of,
    sequence_label,
)
from radar_slam.trajectory import Trajectory


def run_odometry(
    sequence: RadarSequence,
    config: PipelineConfig | None = None,
    max_frames: int | None = None,
    progress: ProgressCallback | None = None,
) -> OdometryRun:
    """Odometry alone over a sequence: read -> register per scan, then evaluate.

    Scans are read ahead on a thread (`config.concurrency.read_ahead_scans`; a reading error is
    raised at the scan where it happened)."""
    config = PipelineConfig() if config is None else config
    frames = frame_count(sequence, max_frames)
    odometry = Odometry(config.odometry)
    start = time.perf_counter()
    depth = config.concurrency.read_ahead_scans
    with ScanReader(sequence.__getitem__, frames, depth) as reader:
        for index in range(frames):
            odometry.register(reader.next())
            if progress is not None:
                progress(Progress(index + 1, frames, 0, 0, time.perf_counter() - start))
    seconds = time.perf_counter() - start
    results = odometry.results  # each pose revised once the next scan registered
    stamps = np.array([r.timestamp_ns for r in results], dtype=np.int64)
    trajectory = Trajectory(stamps, np.array([r.pose for r in results]).reshape(-1, 3))
    _, gt = ground_truth_of(sequence, frames)
    return OdometryRun(
        sequence=sequence_label(sequence),
        config=config,
        trajectory=trajectory,
        ground_truth=gt,
        results=results,
        seconds=seconds,
        metrics=accuracy(trajectory, gt, gt_accuracy_m(sequence)),
        gt_report=gt_report_of(sequence, gt, {"odometry": trajectory}),
    )
