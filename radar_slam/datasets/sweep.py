"""Azimuth times for scans whose files carry none (MulRan polar PNGs, RADIATE, plain bags).

A scanning radar sees its azimuths one after another over one revolution, so a scan taken while
driving is skewed; the odometry de-skews it from per-azimuth times. Where a format stores none,
they are spread uniformly over one sweep in acquisition order (row 0 first: the sensor's own
azimuth direction, whatever its sense), with the scan's stamp at the END of the sweep, the last
azimuth. The sweep's duration is the gap to the previous radar stamp when that is within
`SCAN_PERIOD_TOLERANCE` of one nominal revolution, else the nominal revolution (the first scan,
or a dropped or skipped sweep: stamps alone cannot tell a slower radar from sweeps left out).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from raplace import NS_PER_S, checks

SCAN_PERIOD_TOLERANCE = 0.2
"""A gap between radar stamps counts as one sweep if within +-20 % of the nominal one."""


def nominal_period_ns(scan_rate_hz: float) -> int:
    """One revolution [ns] of a radar turning `scan_rate_hz` times a second."""
    checks.positive("scan_rate_hz", scan_rate_hz)
    return int(round(NS_PER_S / scan_rate_hz))


def scan_periods_ns(
    scan_stamps_ns: NDArray[np.int64],
    radar_stamps_ns: NDArray[np.int64],
    nominal_ns: int,
) -> NDArray[np.int64]:
    """Duration of the sweep ending at each scan stamp [ns].

    Args:
        scan_stamps_ns: (N,) end-of-sweep times of the scans.
        radar_stamps_ns: (M,) sorted end-of-sweep times of every sweep the radar recorded (a
            stamp list such as MulRan's navtech_top_stamp.csv, or the scan stamps themselves).
        nominal_ns: one revolution of the radar [ns].

    Returns:
        (N,) int64: the gap to the previous radar stamp when it is within the tolerance of one
        revolution, otherwise the nominal revolution.
    """
    previous_index = np.searchsorted(radar_stamps_ns, scan_stamps_ns, side="left") - 1
    has_previous = previous_index >= 0
    gaps = np.where(
        has_previous,
        scan_stamps_ns - radar_stamps_ns[np.maximum(previous_index, 0)],
        nominal_ns,
    )
    plausible = np.abs(gaps - nominal_ns) <= SCAN_PERIOD_TOLERANCE * nominal_ns
    return np.where(plausible, gaps, nominal_ns).astype(np.int64)


def uniform_azimuth_times_ns(end_ns: int, period_ns: int, n_azimuths: int) -> NDArray[np.int64]:
    """(n_azimuths,) times spread uniformly over one sweep, the last azimuth at `end_ns`.

    Azimuth j is at end - (n - 1 - j) * period / n, so consecutive sweeps tile time evenly.
    """
    steps_back = np.arange(n_azimuths - 1, -1, -1, dtype=np.float64)
    return end_ns - np.round(steps_back * (period_ns / n_azimuths)).astype(np.int64)


class SweepTimes:
    """Azimuth times of the scans of one sequence whose files carry none.

    Args:
        scan_stamps_ns: (N,) end-of-sweep times of the scans, increasing.
        scan_rate_hz: revolutions per second of the radar.
        radar_stamps_ns: every sweep the radar recorded, when a stamp list has more than the
            scans (None: the scan stamps).
    """

    def __init__(
        self,
        scan_stamps_ns: NDArray[np.int64],
        scan_rate_hz: float,
        radar_stamps_ns: NDArray[np.int64] | None = None,
    ) -> None:
        self.scan_rate_hz = float(scan_rate_hz)
        stamps = scan_stamps_ns if radar_stamps_ns is None else radar_stamps_ns
        self._stamps = scan_stamps_ns
        self._periods_ns = scan_periods_ns(
            scan_stamps_ns, stamps, nominal_period_ns(self.scan_rate_hz)
        )

    def __call__(self, index: int, n_azimuths: int) -> NDArray[np.int64]:
        """(n_azimuths,) azimuth times [ns] of scan `index`, row 0 first."""
        return uniform_azimuth_times_ns(
            int(self._stamps[index]), int(self._periods_ns[index]), n_azimuths
        )
