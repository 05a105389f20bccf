"""The pipeline's observer hook: something that watches a SLAM run scan by scan (the live viewer).

An observer is optional and passive: it reads the pipeline's public state (its sequence, loop
detector and graph) and must not change it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from odometry import OdometryResult
    from radar_slam.datasets.frame import RadarFrame
    from radar_slam.pipeline import Pipeline, Results


class PipelineObserver(Protocol):
    """Called by `Pipeline.run` after each scan and once with the final results."""

    def on_scan(self, pipeline: Pipeline, frame: RadarFrame, result: OdometryResult) -> None:
        """A scan was tracked (`result`: its prompt result); the scan before it has now been
        revised (`pipeline.odometry.result`), added to the graph and offered to the loop
        detector."""

    def on_finish(self, results: Results) -> None:
        """The run finished (final optimisation and evaluation done)."""
