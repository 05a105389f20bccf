"""Scanning radar geometry and timing of the simulated sensor (Navtech CIR204-H by default).

Conventions (identical to the real MulRan data):
- The sensor sweeps clockwise seen from above. Column j of a scan is fired at encoder count
  `first_encoder + encoder_step * j` of `encoder_ticks_per_rev`, i.e. at a clockwise angle
  `2 pi * encoder / ticks` from the sensor's +x (forward) axis. In the project frame (x-forward,
  y-left, angles counter-clockwise) that azimuth is the negative of the clockwise angle.
- Range bin k is centred at `(k + 0.5) * range_resolution_m`.
- A scan lasts `1 / scan_rate_hz`; column j is acquired at `scan_end - (n_azimuths - 1 - j) *
  azimuth_period`, so the last column is at the scan's end time, which names the file.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from radar_slam.datasets.navtech import (
    ENCODER_TICKS_PER_REV,
    MULRAN_ENCODER_STEP,
    MULRAN_FIRST_ENCODER,
    MULRAN_N_AZIMUTHS,
    MULRAN_N_BINS,
    MULRAN_RANGE_RESOLUTION_M,
    SCAN_RATE_HZ,
)
from raplace import NS_PER_S

TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class SensorConfig:
    """Geometry and timing of a scanning FMCW radar.

    Attributes:
        n_azimuths: columns per scan.
        n_bins: range bins per column (tests may use fewer; the bin size stays the same).
        range_resolution_m: size of one range bin [m].
        scan_rate_hz: rotations per second.
        encoder_ticks_per_rev: encoder counts per revolution.
        first_encoder: encoder count of column 0.
        encoder_step: encoder counts between consecutive columns.
        beamwidth_deg: two-way azimuth beamwidth at -3 dB [deg].
        name: sensor name written into world.json.
    """

    n_azimuths: int = MULRAN_N_AZIMUTHS
    n_bins: int = MULRAN_N_BINS
    range_resolution_m: float = MULRAN_RANGE_RESOLUTION_M
    scan_rate_hz: float = SCAN_RATE_HZ
    encoder_ticks_per_rev: int = ENCODER_TICKS_PER_REV
    first_encoder: int = MULRAN_FIRST_ENCODER
    encoder_step: int = MULRAN_ENCODER_STEP
    beamwidth_deg: float = 1.8
    name: str = "navtech-cir204h-sim"

    @property
    def max_range_m(self) -> float:
        """Far edge of the last range bin [m]."""
        return self.n_bins * self.range_resolution_m

    @property
    def scan_period_ns(self) -> int:
        """Duration of one sweep [ns]."""
        return round(NS_PER_S / self.scan_rate_hz)

    @property
    def azimuth_step_rad(self) -> float:
        """Angle between consecutive columns [rad] (positive: clockwise)."""
        return TWO_PI * self.encoder_step / self.encoder_ticks_per_rev

    @property
    def first_azimuth_cw_rad(self) -> float:
        """Clockwise angle of column 0 from +x [rad]."""
        return TWO_PI * self.first_encoder / self.encoder_ticks_per_rev

    def encoders(self) -> NDArray[np.int64]:
        """(n_azimuths,) encoder count of every column."""
        return self.first_encoder + self.encoder_step * np.arange(self.n_azimuths, dtype=np.int64)

    def azimuths_ccw_rad(self) -> NDArray[np.float64]:
        """(n_azimuths,) azimuth of every column [rad], CCW from +x (project frame)."""
        return -self.encoders().astype(np.float64) * (TWO_PI / self.encoder_ticks_per_rev)

    def azimuth_offsets_ns(self) -> NDArray[np.int64]:
        """(n_azimuths,) acquisition time of every column relative to the scan end [ns] (<= 0)."""
        period = self.scan_period_ns
        j = np.arange(self.n_azimuths, dtype=np.int64)
        return -((self.n_azimuths - 1 - j) * period) // self.n_azimuths

    def column_of_angle(self, angle_ccw_rad: NDArray[np.floating]) -> NDArray[np.float32]:
        """Fractional column index of sensor-frame angles (CCW from +x) [rad], in [0, n_az)."""
        cw = -np.asarray(angle_ccw_rad, dtype=np.float32) - np.float32(self.first_azimuth_cw_rad)
        col = cw * np.float32(1.0 / self.azimuth_step_rad)
        return np.mod(col, np.float32(self.n_azimuths))
