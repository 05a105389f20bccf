"""Backward warping of polar radar scans to Cartesian images.

Cartesian image convention (used by raplace and odometry alike): a square image of `size_px`
pixels of `cell_m` metres, sensor at the centre, +x (forward) up, +y (left) to the left. Pixel
(r, c) has its centre at x = (size/2 - r - 0.5) * cell, y = (size/2 - c - 0.5) * cell.

Polar convention: rows are azimuths given by `azimuths_rad` (counter-clockwise from +x, any
monotonic order), columns are range bins; bin k is centred at (k + 0.5) * range_resolution_m.
Backward warping gives every Cartesian pixel the bilinear value of its polar sample: no holes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from raplace import RaPlaceError

TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class CartesianGrid:
    """A square Cartesian grid centred on the sensor.

    Attributes:
        cell_m: pixel size [m].
        size_px: image side [pixels]; the image spans +-size_px * cell_m / 2 metres.
    """

    cell_m: float
    size_px: int

    @property
    def half_extent_m(self) -> float:
        return 0.5 * self.size_px * self.cell_m

    def pixel_centres(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(x, y) [m] of every pixel centre, each (size_px, size_px)."""
        offsets = (0.5 * self.size_px - np.arange(self.size_px) - 0.5) * self.cell_m
        x = np.repeat(offsets[:, None], self.size_px, axis=1)
        y = np.repeat(offsets[None, :], self.size_px, axis=0)
        return x, y

    @classmethod
    def covering(cls, max_range_m: float, cell_m: float) -> CartesianGrid:
        """The smallest even-sized grid of `cell_m` pixels reaching `max_range_m` on each side."""
        half = int(np.ceil(max_range_m / cell_m))
        return cls(cell_m=cell_m, size_px=2 * half)


def polar_sample_coords(
    x_m: NDArray[np.float64],
    y_m: NDArray[np.float64],
    azimuths_rad: NDArray[np.float64],
    range_resolution_m: float,
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Fractional (bin, row) polar coordinates of sensor-frame points (x_m, y_m).

    The row coordinate indexes a polar array with its first row repeated at the end (see
    `wrap_rows`), so interpolation across the seam between the last and first azimuth works.
    Returns float32 maps of the input shape, ready for cv2.remap.
    """
    az = np.asarray(azimuths_rad, dtype=np.float64)
    if az.ndim != 1 or len(az) < 2:
        raise RaPlaceError(f"azimuths_rad must be 1-D with >= 2 entries, got shape {az.shape}")
    if range_resolution_m <= 0:
        raise RaPlaceError(f"range_resolution_m must be positive, got {range_resolution_m}")
    steps = np.diff(np.unwrap(az))
    direction = 1.0 if steps.mean() > 0 else -1.0
    # Offsets of each row from the first, along the sweep direction, in [0, 2 pi); then the seam.
    offsets = np.mod(direction * (az - az[0]), TWO_PI)
    offsets = np.maximum.accumulate(offsets)  # guard against tiny jitter making it non-monotonic
    offsets = np.append(offsets, TWO_PI)
    angle = np.mod(direction * (np.arctan2(y_m, x_m) - az[0]), TWO_PI)
    rows = np.interp(angle, offsets, np.arange(len(offsets), dtype=np.float64))
    bins = np.hypot(x_m, y_m) / range_resolution_m - 0.5
    return bins.astype(np.float32), rows.astype(np.float32)


def wrap_rows(polar: NDArray) -> NDArray[np.float32]:
    """The polar array as float32 with its first row appended (for seam interpolation)."""
    return np.vstack([polar, polar[:1]]).astype(np.float32, copy=False)


def remap(
    polar: NDArray, bins: NDArray[np.float32], rows: NDArray[np.float32]
) -> NDArray[np.float32]:
    """Sample `polar` (n_azimuths, n_bins) bilinearly at fractional (bins, rows); 0 outside."""
    return remap_wrapped(wrap_rows(polar), bins, rows)


def remap_wrapped(
    wrapped: NDArray[np.float32], bins: NDArray[np.float32], rows: NDArray[np.float32]
) -> NDArray[np.float32]:
    """`remap` of a polar array already made by `wrap_rows` (n_azimuths + 1, n_bins) float32:
    for a scan sampled many times, wrap it once."""
    sampled = cv2.remap(
        wrapped,
        bins,
        rows,
        interpolation=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=0.0,
    )
    # OpenCV's stubs return a generic MatLike; remap keeps the float32 source dtype.
    return cast(NDArray[np.float32], sampled)


class CartesianWarper:
    """Polar -> Cartesian warping with the sampling maps cached per scan geometry."""

    def __init__(self, grid: CartesianGrid) -> None:
        self.grid = grid
        self._key: tuple[int, int, float, bytes] | None = None
        self._maps: tuple[NDArray[np.float32], NDArray[np.float32]] | None = None

    def maps(
        self, azimuths_rad: NDArray[np.float64], n_bins: int, range_resolution_m: float
    ) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """(bins, rows) sampling maps for this geometry, rebuilt only when it changes."""
        az = np.asarray(azimuths_rad, dtype=np.float64)
        # Azimuths jitter by encoder ticks between scans; rounding to 1e-4 rad keeps the cache.
        key = (len(az), int(n_bins), float(range_resolution_m), np.round(az, 4).tobytes())
        if key != self._key or self._maps is None:
            x, y = self.grid.pixel_centres()
            self._maps = polar_sample_coords(x, y, az, range_resolution_m)
            self._key = key
        return self._maps

    def __call__(
        self, polar: NDArray, azimuths_rad: NDArray[np.float64], range_resolution_m: float
    ) -> NDArray[np.float32]:
        """Cartesian image (size_px, size_px) float32 of `polar` (n_azimuths, n_bins)."""
        polar = np.asarray(polar)
        if polar.ndim != 2 or polar.shape[0] != len(azimuths_rad):
            raise RaPlaceError(
                f"polar must be (n_azimuths, n_bins) with n_azimuths = {len(azimuths_rad)}, "
                f"got {polar.shape}"
            )
        bins, rows = self.maps(azimuths_rad, polar.shape[1], range_resolution_m)
        return remap(polar, bins, rows)
