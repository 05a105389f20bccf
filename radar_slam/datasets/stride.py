"""Views of a sequence: every K-th scan (`strided`), or any chosen scans (`ScanSelection`),
with their timestamps and ground truth.

What users do to go faster (or to test a lower frame rate): `strided(sequence, 4)` turns a 4 Hz
sequence into a 1 Hz one without copying or reading anything (frames stay lazy).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from radar_slam.datasets.frame import GroundTruthSource, RadarFrame, RadarSequence
from radar_slam.errors import RadarSlamError


class ScanSelection:
    """Some scans of a sequence, in order (a `RadarSequence` itself; frames stay lazy).

    Args:
        base: the full sequence.
        indices: (n,) increasing indices of the kept scans in `base`.
        name: the view's name (result folders use it).

    Attributes:
        family: the base family (its shipped configuration still applies).
    """

    def __init__(self, base: RadarSequence, indices: NDArray[np.int64], name: str) -> None:
        self.base = base
        self.indices = np.asarray(indices, dtype=np.int64)
        self.family = base.family
        self.name = name

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, index: int) -> RadarFrame:
        if not -len(self) <= index < len(self):
            raise IndexError(f"scan {index} out of range (0..{len(self) - 1})")
        return self.base[int(self.indices[index])]

    @property
    def timestamps_ns(self) -> NDArray[np.int64]:
        """(len,) reference times of the kept scans [ns]."""
        return np.asarray(self.base.timestamps_ns, dtype=np.int64)[self.indices]

    @property
    def ground_truth(self) -> NDArray[np.float64] | None:
        """(len, 3) ground truth of the kept scans, or None."""
        gt = self.base.ground_truth
        return None if gt is None else np.asarray(gt, dtype=np.float64)[self.indices]

    @property
    def ground_truth_source(self) -> GroundTruthSource | None:
        """The base sequence's."""
        return self.base.ground_truth_source

    def __repr__(self) -> str:
        return f"ScanSelection({self.base!r}, {len(self)} scans)"


class StridedSequence(ScanSelection):
    """Scans 0, K, 2K, ... of a sequence (a `RadarSequence` itself).

    Args:
        base: the full sequence.
        stride: K >= 1 (1 returns the same scans).

    Attributes:
        name: the base name with `_strideK` appended (K > 1), so result folders differ.
        family: the base family (its shipped configuration still applies).
    """

    def __init__(self, base: RadarSequence, stride: int) -> None:
        if stride < 1:
            raise RadarSlamError(f"--stride must be at least 1, got {stride}")
        self.stride = int(stride)
        name = base.name if stride == 1 else f"{base.name}_stride{stride}"
        super().__init__(base, np.arange(0, len(base), self.stride), name)

    def __repr__(self) -> str:
        return f"StridedSequence({self.base!r}, stride={self.stride})"


def strided(sequence: RadarSequence, stride: int) -> RadarSequence:
    """`sequence` itself for stride 1, else its strided view (see `StridedSequence`)."""
    return sequence if stride == 1 else StridedSequence(sequence, stride)
