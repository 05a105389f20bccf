"""The sequence protocol every loader implements (frames are `odometry.RadarFrame`s)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from odometry import RadarFrame


@dataclass(frozen=True)
class GroundTruthSource:
    """Where a sequence's ground truth comes from and how far to trust it.

    Attributes:
        description: what the GT is (e.g. "GNSS/INS without RTK").
        accuracy_m: the stated accuracy of one GT position [m] (0 for a simulation). Metrics
            that compare short stretches (KITTI drift) use only segments long enough for it.
        notes: facts found in this sequence's GT (outages, heading bias, ...), JSON-ready.
    """

    description: str
    accuracy_m: float
    notes: dict[str, float | int | str] = field(default_factory=dict)


@runtime_checkable
class RadarSequence(Protocol):
    """A radar sequence: lazily loaded frames plus optional ground truth.

    `ground_truth` is (len, 3) SE(2) poses (x, y, yaw) of the radar at each scan's
    `timestamps_ns`, in the dataset's own world frame, or None when there is none;
    `ground_truth_source` says what it is and how accurate (None without GT).
    """

    name: str
    family: str

    def __len__(self) -> int: ...

    def __getitem__(self, index: int) -> RadarFrame: ...

    @property
    def timestamps_ns(self) -> NDArray[np.int64]: ...

    @property
    def ground_truth(self) -> NDArray[np.float64] | None: ...

    @property
    def ground_truth_source(self) -> GroundTruthSource | None: ...


Sequence = RadarSequence
"""The old name of `RadarSequence` (it clashed with `collections.abc.Sequence`)."""

__all__ = ["GroundTruthSource", "RadarFrame", "RadarSequence", "Sequence"]
