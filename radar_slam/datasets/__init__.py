"""Radar datasets: the frame record, the sequence protocol, loaders and `open_sequence`.

Importing this package registers the families `mulran` and `oxford`; plug-in families (the
simulator's `synthetic`) register through the `radar_slam.datasets` entry point on first lookup.
Address a sequence as `family/sequence` or by its folder path.
"""

from __future__ import annotations

from radar_slam.datasets.frame import RadarFrame, RadarSequence, Sequence
from radar_slam.datasets.mulran import MulRanSequence
from radar_slam.datasets.open import open_sequence
from radar_slam.datasets.oxford import OxfordSequence
from radar_slam.datasets.registry import DatasetConfig, data_root, families

__all__ = [
    "DatasetConfig",
    "MulRanSequence",
    "OxfordSequence",
    "RadarFrame",
    "RadarSequence",
    "Sequence",
    "data_root",
    "families",
    "open_sequence",
]
