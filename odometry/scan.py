"""The radar scan every stage consumes: the structural `Scan` protocol and `RadarFrame`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray


@runtime_checkable
class Scan(Protocol):
    """One radar sweep (any object with these attributes).

    Attributes:
        timestamp_ns: reference time of the scan [ns]: the time its pose refers to.
        polar: (n_azimuths, n_bins) uint8 intensities, one row per azimuth.
        azimuths_rad: (n_azimuths,) azimuth of each row [rad], counter-clockwise from +x
            (forward) in the sensor frame x-forward, y-left; bin k of row i lies at range
            (k + 0.5) * range_resolution_m along azimuths_rad[i].
        range_resolution_m: size of one range bin [m].
        sensor: sensor / dataset name (informational).
        azimuth_times_ns: (n_azimuths,) acquisition time of each row [ns], or None when unknown
            (then the scan cannot be de-skewed).
    """

    # Read-only properties so that frozen dataclasses (RadarFrame) match under mypy too.
    @property
    def timestamp_ns(self) -> int: ...

    @property
    def polar(self) -> NDArray[np.uint8]: ...

    @property
    def azimuths_rad(self) -> NDArray[np.float64]: ...

    @property
    def range_resolution_m(self) -> float: ...

    @property
    def sensor(self) -> str: ...

    @property
    def azimuth_times_ns(self) -> NDArray[np.int64] | None: ...


@dataclass(frozen=True)
class RadarFrame:
    """One radar sweep: the concrete `Scan` (see `Scan` for the attributes)."""

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
