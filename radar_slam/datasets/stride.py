"""A strided view of a sequence: every K-th scan, with its timestamps and ground truth.

What users do to go faster (or to test a lower frame rate): `strided(sequence, 4)` turns a 4 Hz
sequence into a 1 Hz one without copying or reading anything (frames stay lazy).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from radar_slam.datasets.frame import RadarFrame, RadarSequence
from radar_slam.errors import RadarSlamError


class StridedSequence:
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
        self.base = base
        self.stride = int(stride)
        self.family = base.family
        self.name = base.name if stride == 1 else f"{base.name}_stride{stride}"

    def __len__(self) -> int:
        return (len(self.base) + self.stride - 1) // self.stride

    def __getitem__(self, index: int) -> RadarFrame:
        if not -len(self) <= index < len(self):
            raise IndexError(f"scan {index} out of range (0..{len(self) - 1})")
        return self.base[(index % len(self)) * self.stride]

    @property
    def timestamps_ns(self) -> NDArray[np.int64]:
        """(len,) reference times of the kept scans [ns]."""
        return np.asarray(self.base.timestamps_ns[:: self.stride], dtype=np.int64)

    @property
    def ground_truth(self) -> NDArray[np.float64] | None:
        """(len, 3) ground truth of the kept scans, or None."""
        gt = self.base.ground_truth
        return None if gt is None else np.asarray(gt[:: self.stride], dtype=np.float64)

    def __repr__(self) -> str:
        return f"StridedSequence({self.base!r}, stride={self.stride})"


def strided(sequence: RadarSequence, stride: int) -> RadarSequence:
    """`sequence` itself for stride 1, else its strided view (see `StridedSequence`)."""
    return sequence if stride == 1 else StridedSequence(sequence, stride)
