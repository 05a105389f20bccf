"""Radar datasets: the frame record, the sequence protocol, loaders and `open_sequence`.

Importing this package registers the families `mulran`, `oxford`, `boreas`, `radiate` and
`rosbag` (ROS 1 bag files and ROS 2 bag folders); plug-in families (the simulator's `synthetic`)
register through the `radar_slam.datasets` entry point on first lookup.
Address a sequence as `family/sequence` or by its folder path.
"""

from __future__ import annotations

from radar_slam.datasets.boreas import BoreasSequence
from radar_slam.datasets.frame import RadarFrame, RadarSequence, Sequence
from radar_slam.datasets.mulran import MulRanSequence
from radar_slam.datasets.open import locate_sequence, open_located, open_sequence
from radar_slam.datasets.oxford import OxfordSequence
from radar_slam.datasets.radiate import RadiateSequence
from radar_slam.datasets.registry import DatasetConfig, data_root, families
from radar_slam.datasets.rosbag import BagSequence

__all__ = [
    "BagSequence",
    "BoreasSequence",
    "DatasetConfig",
    "MulRanSequence",
    "OxfordSequence",
    "RadiateSequence",
    "RadarFrame",
    "RadarSequence",
    "Sequence",
    "data_root",
    "families",
    "locate_sequence",
    "open_located",
    "open_sequence",
]
