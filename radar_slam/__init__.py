"""radar-slam: radar pose-graph SLAM with phase-correlation odometry and RaPlace loop closure."""

__version__ = "0.1.0"
