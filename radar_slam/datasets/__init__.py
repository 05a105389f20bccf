"""Radar datasets: the frame record, the sequence protocol, loaders and `open_sequence`.

Importing this package registers the dataset families: `mulran`, `oxford`, and `synthetic`
when its module is present. Address a sequence as `family/sequence` or by its folder path.
"""

from __future__ import annotations

import importlib
from pathlib import Path

from radar_slam.datasets.frame import RadarFrame, Sequence
from radar_slam.datasets.mulran import MulRanSequence
from radar_slam.datasets.open import open_sequence
from radar_slam.datasets.oxford import OxfordSequence
from radar_slam.datasets.registry import data_root, families

_PACKAGE_DIR = Path(__file__).resolve().parent
_OPTIONAL_FAMILY_MODULES = ("synthetic",)
"""Loader modules other work may add; each is imported (and registers itself) if present."""

for _module in _OPTIONAL_FAMILY_MODULES:
    if (_PACKAGE_DIR / f"{_module}.py").is_file() or (_PACKAGE_DIR / _module).is_dir():
        importlib.import_module(f"{__name__}.{_module}")

__all__ = [
    "MulRanSequence",
    "OxfordSequence",
    "RadarFrame",
    "Sequence",
    "data_root",
    "families",
    "open_sequence",
]
