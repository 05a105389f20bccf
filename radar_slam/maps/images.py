"""Keyframe images of a map: what loop verification needs, without the whole polar scan.

A map keeps, per keyframe, one de-skewed Cartesian image of the conditioned scan (the odometry's
`preprocess_polar`: range bins averaged, ring noise removed), quantised to uint8 with a
per-image scale and PNG-compressed (lossless, deterministic). For verification the image is
sampled back onto a polar grid (`pseudo_scan`): a `RadarFrame` without azimuth times (the image
is already at the scan's reference time), which the loop verifier (`radar_slam.loops`) takes
like any scan. Image convention as `raplace.warp`: sensor at the centre, +x (forward) up, +y
(left) to the left.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numba
import numpy as np
from numpy.typing import NDArray

from odometry import OdometryConfig, PolarScan, RadarFrame, sample_scan
from radar_slam.errors import RadarSlamError
from raplace import CartesianGrid, checks

PIXEL_MAX = 255
"""uint8 full scale of a re-made polar scan."""
SCALE_PERCENTILE = 99.9
"""The image intensity at this percentile is the top level (brighter pixels saturate)."""
TOP_SAMPLE_STRIDE = 16
"""`top_level` finds a threshold below the top level from every this-many-th pixel ..."""
TOP_SAMPLE_PERCENTILE = 99.0
"""... at this percentile of them, and sorts only the pixels above it (a tenth of the cost of
`np.percentile` of the whole image; the same value)."""
PNG_COMPRESSION = 6
"""zlib level of the PNG encoder (deterministic for a given image)."""
PNG_STRATEGY = cv2.IMWRITE_PNG_STRATEGY_RLE
"""zlib strategy of the PNG encoder: run lengths only. The images are mostly zeros in runs, so
it compresses them as well as the default strategy at level 9 in a tenth of the time."""
PNG_FILTER = cv2.IMWRITE_PNG_FILTER_NONE
"""PNG row filter: none. libpng's adaptive choice among all five filters took most of the encoding
time, and the unfiltered runs of zeros compress better still; lossless like any PNG."""
PSEUDO_SENSOR = "map-keyframe"
"""`RadarFrame.sensor` of a scan re-made from a map image."""


@dataclass(frozen=True)
class ImageGeometry:
    """The stored keyframe images and the polar grid they are sampled back onto.

    Attributes:
        cell_m: pixel size [m].
        size_px: image side [pixels] (the image spans +-size_px * cell_m / 2).
        n_azimuths: azimuths of the re-made polar scan (a full turn, CCW from +x).
        range_resolution_m: range bin of the re-made polar scan [m].
        levels: quantisation levels above zero; the square root of the intensity is quantised
            (more levels for the weak returns, fewer bytes).
        floor_fraction: intensities below this fraction of the top level are stored as 0 (the
            residual clutter that the conditioning leaves costs most of the bytes).
    """

    cell_m: float = 0.4
    size_px: int = 400
    n_azimuths: int = 400
    range_resolution_m: float = 0.2
    levels: int = 15
    floor_fraction: float = 0.1

    def __post_init__(self) -> None:
        checks.positive("cell_m", self.cell_m)
        checks.at_least("size_px", self.size_px, 2)
        checks.at_least("n_azimuths", self.n_azimuths, 2)
        checks.positive("range_resolution_m", self.range_resolution_m)
        checks.in_range("levels", self.levels, 1, 255)
        checks.in_range("floor_fraction", self.floor_fraction, 0.0, 1.0, open_high=True)

    @property
    def max_range_m(self) -> float:
        """Range covered in every direction [m] (the image's inscribed radius)."""
        return 0.5 * self.size_px * self.cell_m

    @property
    def n_bins(self) -> int:
        return int(self.max_range_m / self.range_resolution_m)


KEYFRAME_IMAGE = ImageGeometry()
"""The image geometry of the maps a run makes (a map records its own, which its users read):
the defaults of `ImageGeometry`, the verifier's reach at a few bytes per pixel."""


def top_level(image: NDArray[np.floating]) -> float:
    """`np.percentile(image, SCALE_PERCENTILE)` (linear interpolation, NaN when the image holds
    one), computed from the brightest pixels only: the same value, bit for bit."""
    flat = image.reshape(-1)
    n = flat.size
    virtual = (n - 1) * np.true_divide(SCALE_PERCENTILE, 100)  # as np.percentile computes it
    previous = int(np.floor(virtual))
    needed = n - previous  # the pixels at or above the order statistic `previous`
    if needed < 2 or np.isnan(flat.max()):
        return float(np.percentile(image, SCALE_PERCENTILE))
    sample = flat[::TOP_SAMPLE_STRIDE]
    k = int(len(sample) * TOP_SAMPLE_PERCENTILE / 100)
    threshold = np.partition(sample, k)[k]
    top = flat[flat >= threshold]  # every pixel ranked above all the others
    if len(top) < needed:
        return float(np.percentile(image, SCALE_PERCENTILE))
    top.sort()
    first = previous - (n - len(top))
    low, high = top[first], top[first + 1]
    gamma = float(virtual - previous)
    step = high - low  # np.percentile's interpolation, in the image's precision
    return float(high - step * (1 - gamma) if gamma >= 0.5 else low + step * gamma)


def quantise(
    image: NDArray[np.floating], scale: float, floor_fraction: float, levels: int
) -> NDArray[np.uint8]:
    """The stored uint8 image: rint(sqrt(clip(image / scale, 0, 1)) * levels), relative values
    below `floor_fraction` stored as 0 (one pass for a finite float32 image; NumPy's
    operations otherwise, with the same result)."""
    if image.dtype == np.float32 and image.ndim == 2 and np.isfinite(scale):
        if np.isfinite(image.max()):
            return _quantise_kernel(
                image, np.float32(scale), np.float32(floor_fraction), np.float32(levels)
            )
    relative = np.clip(image / scale, 0.0, 1.0)
    relative[relative < floor_fraction] = 0.0
    return np.rint(np.sqrt(relative) * levels).astype(np.uint8)


@numba.njit(nogil=True, cache=True)
def _quantise_kernel(
    image: NDArray[np.float32], scale: np.float32, floor: np.float32, levels: np.float32
) -> NDArray[np.uint8]:
    """`quantise` of a finite float32 image, every step in float32 as NumPy computes it."""
    out = np.empty(image.shape, dtype=np.uint8)
    zero, one = np.float32(0.0), np.float32(1.0)
    for i in range(image.shape[0]):
        for j in range(image.shape[1]):
            relative = image[i, j] / scale
            relative = min(max(relative, zero), one)
            if relative < floor:
                relative = zero
            out[i, j] = np.uint8(np.rint(np.sqrt(relative) * levels))
    return out


class KeyframeImager:
    """Scan -> (PNG bytes, scale) and back to a polar `RadarFrame`; caches the sampling grids."""

    def __init__(self, geometry: ImageGeometry, odometry: OdometryConfig) -> None:
        self.geometry = geometry
        self.odometry = odometry
        grid = CartesianGrid(geometry.cell_m, geometry.size_px)
        x, y = grid.pixel_centres()
        self._xy = (x.astype(np.float32), y.astype(np.float32))
        self._range = np.hypot(x, y).astype(np.float32)
        self._bearing = np.arctan2(y, x).astype(np.float32)
        self.azimuths_rad: NDArray[np.float64] = np.arange(
            geometry.n_azimuths, dtype=np.float64
        ) * (2.0 * np.pi / geometry.n_azimuths)
        ranges = (np.arange(geometry.n_bins) + 0.5) * geometry.range_resolution_m
        # Polar sample (azimuth a, range r) -> fractional image (column, row).
        px = ranges[None, :] * np.cos(self.azimuths_rad)[:, None]
        py = ranges[None, :] * np.sin(self.azimuths_rad)[:, None]
        half = 0.5 * geometry.size_px
        self._cols = (half - py / geometry.cell_m - 0.5).astype(np.float32)
        self._rows = (half - px / geometry.cell_m - 0.5).astype(np.float32)

    def render(self, polar: PolarScan, twist: NDArray[np.float64] | None) -> NDArray[np.float32]:
        """(size_px, size_px) float32 image of a conditioned scan (`preprocess_polar` with this
        imager's odometry settings), de-skewed with `twist` (3,) (vx, vy [m/s], yaw rate
        [rad/s]) or not (None)."""
        x, y = self._xy
        return sample_scan(polar, x, y, self._range, self._bearing, twist=twist)

    def encode(self, image: NDArray[np.float32]) -> tuple[bytes, float]:
        """(PNG bytes of the uint8 image, scale): pixel value v stands for
        scale * (v / levels)^2."""
        geo = self.geometry
        top = top_level(image)
        scale = top if top > 0 else 1.0
        quantised = quantise(image, scale, geo.floor_fraction, geo.levels)
        options = [
            cv2.IMWRITE_PNG_COMPRESSION,
            PNG_COMPRESSION,
            cv2.IMWRITE_PNG_STRATEGY,
            PNG_STRATEGY,
            cv2.IMWRITE_PNG_FILTER,
            PNG_FILTER,
        ]
        ok, png = cv2.imencode(".png", quantised, options)
        if not ok:
            raise RadarSlamError("could not PNG-encode a keyframe image")
        return png.tobytes(), float(np.float32(scale))

    def decode(self, png: bytes) -> NDArray[np.uint8]:
        """The stored uint8 image of PNG bytes."""
        image = cv2.imdecode(np.frombuffer(png, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
        size = self.geometry.size_px
        if image is None or image.shape != (size, size) or image.dtype != np.uint8:
            raise RadarSlamError(f"a keyframe image is not a {size} x {size} 8-bit PNG")
        return np.asarray(image, dtype=np.uint8)

    def pseudo_scan(self, png: bytes, timestamp_ns: int) -> RadarFrame:
        """The keyframe image sampled onto a polar grid: a scan the loop verifier accepts.

        Intensities are relative to the image's top level, 0..PIXEL_MAX (the scale only
        matters across images, and the verifier normalises its images). No azimuth times: the
        image is already de-skewed.
        """
        levels = self.decode(png).astype(np.float32) / self.geometry.levels
        image = levels * levels * PIXEL_MAX
        polar = cv2.remap(
            image,
            self._cols,
            self._rows,
            interpolation=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=0.0,
        )
        return RadarFrame(
            timestamp_ns=int(timestamp_ns),
            polar=np.clip(np.rint(polar), 0, PIXEL_MAX).astype(np.uint8),
            azimuths_rad=self.azimuths_rad,
            range_resolution_m=self.geometry.range_resolution_m,
            sensor=PSEUDO_SENSOR,
        )
