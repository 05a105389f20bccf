"""Radar datasets: the frame record, the sequence protocol, loaders and `open_sequence`.

Importing this package registers the dataset families `mulran`, `oxford`, `boreas`, `radiate`,
`synthetic` and `rosbag` (ROS 1 bag files and ROS 2 bag folders).
Address a sequence as `family/sequence` or by its folder path.
"""

from __future__ import annotations

from radar_slam.datasets.boreas import BoreasSequence
from radar_slam.datasets.frame import RadarFrame, Sequence
from radar_slam.datasets.mulran import MulRanSequence
from radar_slam.datasets.open import open_sequence
from radar_slam.datasets.oxford import OxfordSequence
from radar_slam.datasets.radiate import RadiateSequence
from radar_slam.datasets.registry import DatasetConfig, data_root, families
from radar_slam.datasets.rosbag import BagSequence
from radar_slam.datasets.synthetic import SYNTHETIC  # noqa: F401  (importing registers the family)

__all__ = [
    "BagSequence",
    "BoreasSequence",
    "DatasetConfig",
    "MulRanSequence",
    "OxfordSequence",
    "RadiateSequence",
    "RadarFrame",
    "Sequence",
    "data_root",
    "families",
    "open_sequence",
]
