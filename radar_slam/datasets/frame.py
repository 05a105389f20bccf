"""The radar frame record and the sequence protocol every loader implements."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class RadarFrame:
    """One radar sweep in the project-wide convention.

    Attributes:
        timestamp_ns: reference time of the scan [ns]; the time its pose refers to.
        polar: (n_azimuths, n_bins) uint8 intensities, one row per azimuth.
        azimuths_rad: (n_azimuths,) azimuth of each row [rad], counter-clockwise from +x
            (forward) in a frame x-forward, y-left. Bin k of azimuth a lies at
            ((k + 0.5) * res * cos a, (k + 0.5) * res * sin a).
        range_resolution_m: size of one range bin [m].
        sensor: sensor / dataset name, e.g. "navtech-cir204h".
        azimuth_times_ns: (n_azimuths,) acquisition time of each row [ns], when known.
    """

    timestamp_ns: int
    polar: NDArray[np.uint8]
    azimuths_rad: NDArray[np.float64]
    range_resolution_m: float
    sensor: str
    azimuth_times_ns: NDArray[np.int64] | None = None

    @property
    def n_azimuths(self) -> int:
        return int(self.polar.shape[0])

    @property
    def n_bins(self) -> int:
        return int(self.polar.shape[1])

    @property
    def max_range_m(self) -> float:
        return self.n_bins * self.range_resolution_m


@runtime_checkable
class Sequence(Protocol):
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
