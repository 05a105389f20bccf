"""Exception hierarchy of radar-slam.

Every error a user can cause (a missing dataset, a corrupt file, a bad config) is a
`RadarSlamError`; the CLI prints it as one line and exits with code 1. Anything else is a bug.
"""

from __future__ import annotations


class RadarSlamError(Exception):
    """Base class of every user-facing radar-slam error."""


class DatasetNotFoundError(RadarSlamError):
    """A sequence could not be located under the data root."""


class DatasetFormatError(RadarSlamError):
    """A dataset file exists but its content is not what the format requires."""


class ConfigError(RadarSlamError):
    """A configuration file is unreadable, or has unknown keys or values of the wrong type."""


class TrajectoryError(RadarSlamError):
    """A trajectory file is malformed, or two trajectories cannot be associated."""


class ResultsError(RadarSlamError):
    """A results folder cannot be created without overwriting something."""


class GraphError(RadarSlamError):
    """A pose-graph operation is inconsistent: unknown or duplicate keyframe, a covariance that
    is not symmetric positive definite, keyframes not connected to the anchored part, ..."""


class GraphFormatError(GraphError):
    """A pose-graph file (g2o) is malformed; the message names the file and line."""
