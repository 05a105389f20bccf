"""The SLAM pipeline (being split into a package)."""

from radar_slam.pipeline.slam import *  # noqa: F403
