"""The sequence protocol every loader implements (frames are `odometry.RadarFrame`s)."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from odometry.scan import RadarFrame


@runtime_checkable
class RadarSequence(Protocol):
    """A radar sequence: lazily loaded frames plus optional ground truth.

    `ground_truth` is (len, 3) SE(2) poses (x, y, yaw) of the radar at each scan's
    `timestamps_ns`, in the dataset's own world frame, or None when there is none.
    """

    name: str
    family: str

    def __len__(self) -> int: ...

    def __getitem__(self, index: int) -> RadarFrame: ...

    @property
    def timestamps_ns(self) -> NDArray[np.int64]: ...

    @property
    def ground_truth(self) -> NDArray[np.float64] | None: ...


Sequence = RadarSequence
"""The old name of `RadarSequence` (it clashed with `collections.abc.Sequence`)."""

__all__ = ["RadarFrame", "RadarSequence", "Sequence"]
