"""The radar scan the odometry consumes, as a structural protocol.

`radar_slam.datasets.frame.RadarFrame` satisfies it without the odometry importing radar_slam;
any object with these attributes does (tests build small dataclasses).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray


@runtime_checkable
class Scan(Protocol):
    """One radar sweep.

    Attributes:
        timestamp_ns: reference time of the scan [ns]: the time its pose refers to. De-skewing
            moves every return to where it would have been seen from the pose at this time.
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
