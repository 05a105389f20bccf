"""The loop-closing bar the SLAM tests on synthetic/tiny_loop share."""

from __future__ import annotations

MAX_ATE_RATIO = 0.4
"""SLAM / odometry ATE on synthetic/tiny_loop, unless SLAM is within MAX_SLAM_ATE_M (the SLAM
bar "<= 0.3 x odometry or <= 1 m", scaled to a drive this short)."""
MAX_SLAM_ATE_M = 0.085
"""Absolute SLAM ATE bar [m] on synthetic/tiny_loop: its odometry alone is at 0.133 m, so a graph
whose loops did little stays above it."""


def loops_corrected(slam_ate_m: float, odometry_ate_m: float) -> bool:
    """The loops cut the odometry's ATE by the ratio, or to the absolute bar, and never raise it."""
    small = slam_ate_m <= MAX_ATE_RATIO * odometry_ate_m or slam_ate_m <= MAX_SLAM_ATE_M
    return small and slam_ate_m < odometry_ate_m
