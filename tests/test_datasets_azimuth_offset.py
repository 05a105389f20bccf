"""The `dataset.azimuth_offset_rad` setting reaches every loader (Oxford, MulRan, synthetic)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from radar_slam.datasets import DatasetConfig, OxfordSequence, open_sequence
from radar_slam.datasets.frame import Sequence

OFFSET_RAD = -0.024


@pytest.mark.realdata
def test_oxford_azimuths_are_offset(oxford_dir: Path) -> None:
    plain = OxfordSequence(oxford_dir)[0]
    moved = OxfordSequence(oxford_dir, azimuth_offset_rad=OFFSET_RAD)[0]
    np.testing.assert_allclose(moved.azimuths_rad - plain.azimuths_rad, OFFSET_RAD)
    np.testing.assert_array_equal(moved.polar, plain.polar)


def test_config_offset_reaches_the_synthetic_loader(tiny: Sequence, synthetic_root: Path) -> None:
    assert DatasetConfig().loader_options() == {}  # unset: no loader sees the key
    options = DatasetConfig(azimuth_offset_rad=OFFSET_RAD)
    moved = open_sequence("synthetic/tiny", synthetic_root, options)[3]
    np.testing.assert_allclose(moved.azimuths_rad - tiny[3].azimuths_rad, OFFSET_RAD)
