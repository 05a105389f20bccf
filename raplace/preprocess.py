"""Polar scan clean-up and warping to a Cartesian disc image.

Pure functions on arrays (`resample_range`, `suppress_noise`, `radial_taper`) plus
`CartesianImager`, a thin class that caches the warping maps of raplace.warp.

Polar convention (as raplace.warp): `polar` is (n_azimuths, n_bins), azimuths counter-clockwise
from +x (forward) in a frame x-forward, y-left; bin k is centred at (k + 0.5) * range_resolution_m.
"""

from __future__ import annotations

from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from raplace import RaPlaceError
from raplace.config import ImageConfig, PreprocessConfig
from raplace.warp import CartesianGrid, CartesianWarper


def resample_range(
    polar: NDArray, range_resolution_m: float, cell_m: float, max_range_m: float
) -> tuple[NDArray[np.float32], float]:
    """Crop a polar scan to `max_range_m` and average groups of bins to about `cell_m`.

    Args:
        polar: (n_azimuths, n_bins) intensities (any real dtype).
        range_resolution_m: size of one input bin [m].
        cell_m: target bin size [m]; bins are averaged in groups of
            f = max(1, round(cell_m / range_resolution_m)) (an integer factor keeps OpenCV's fast
            area-averaging path, about 5x faster than a fractional one).
        max_range_m: bins whose far edge lies beyond this are dropped [m].

    Returns:
        (n_azimuths, n_out) float32 bin means, and the output bin size f * range_resolution_m [m].
        Output bin i averages input bins [i f, (i + 1) f), so it is centred at (i + 0.5) f res,
        keeping the bin-centre convention.
    """
    polar = np.asarray(polar)
    if polar.ndim != 2:
        raise RaPlaceError(f"polar must be (n_azimuths, n_bins), got shape {polar.shape}")
    if range_resolution_m <= 0 or cell_m <= 0 or max_range_m <= 0:
        raise RaPlaceError("range_resolution_m, cell_m and max_range_m must be positive")
    factor = max(1, int(round(cell_m / range_resolution_m)))
    n_keep = min(polar.shape[1], int(np.floor(max_range_m / range_resolution_m)))
    n_out = n_keep // factor
    if n_out < 1:
        raise RaPlaceError(f"max_range_m {max_range_m} is below one output bin")
    cropped = polar[:, : n_out * factor].astype(np.float32)
    if factor == 1:
        return cropped, float(range_resolution_m)
    resized = cv2.resize(cropped, (n_out, polar.shape[0]), interpolation=cv2.INTER_AREA)
    # OpenCV's stubs return a generic MatLike; resize keeps the float32 source dtype.
    return cast(NDArray[np.float32], resized), factor * float(range_resolution_m)


def suppress_noise(
    polar: NDArray[np.float32], range_resolution_m: float, cfg: PreprocessConfig
) -> NDArray[np.float32]:
    """Remove ring noise, the saturated near range and the noise floor; transform intensity.

    Args:
        polar: (n_azimuths, n_bins) float32 intensities (uint8 scale).
        range_resolution_m: bin size [m].
        cfg: which steps to apply.

    Returns:
        (n_azimuths, n_bins) float32, non-negative.
    """
    out = np.array(polar, dtype=np.float32, copy=True)
    if cfg.ring_noise_removal:
        out -= np.median(out, axis=0, keepdims=True)
    if cfg.spoke_removal:
        out -= np.median(out, axis=1, keepdims=True)
    if cfg.noise_floor > 0:
        out -= np.float32(cfg.noise_floor)
    np.maximum(out, 0.0, out=out)
    n_near = int(np.ceil(cfg.min_range_m / range_resolution_m))
    out[:, :n_near] = 0.0
    if cfg.intensity == "log1p":
        np.log1p(out, out=out)
    elif cfg.intensity == "square":
        np.square(out, out=out)
    elif cfg.intensity != "linear":
        raise RaPlaceError(f"unknown intensity transform {cfg.intensity!r}")
    return out


def radial_taper(
    grid: CartesianGrid, radius_m: float, taper_fraction: float
) -> NDArray[np.float32]:
    """Weights (size_px, size_px) in [0, 1]: 1 inside the disc, a cosine ramp to 0 at its rim.

    The ramp covers radii [(1 - taper_fraction) * radius_m, radius_m]; beyond it the weight is 0.
    """
    x, y = grid.pixel_centres()
    r = np.hypot(x, y)
    inner = (1.0 - taper_fraction) * radius_m
    ramp = np.clip((r - inner) / max(radius_m - inner, 1e-9), 0.0, 1.0)
    return (0.5 + 0.5 * np.cos(np.pi * ramp)).astype(np.float32)


def finish_disc(
    cart: NDArray[np.float32], taper: NDArray[np.float32], subtract_mean: bool
) -> NDArray[np.float32]:
    """Taper a Cartesian image to its disc, first removing the disc's weighted mean if asked.

    Args:
        cart: (n, n) image; modified in place and returned.
        taper: (n, n) weights from `radial_taper`.
        subtract_mean: remove sum(cart * taper) / sum(taper) before tapering.
    """
    if subtract_mean:
        cart -= np.float32(np.sum(cart * taper, dtype=np.float64) / max(float(taper.sum()), 1e-12))
    cart *= taper
    return cart


class CartesianImager:
    """Polar scan -> cleaned Cartesian disc image (size_px, size_px) float32.

    Caches the warping maps (per scan geometry) and the taper weights.
    """

    def __init__(self, preprocess: PreprocessConfig, image: ImageConfig) -> None:
        if image.cell_m <= 0 or image.max_range_m <= image.cell_m:
            raise RaPlaceError(f"bad image settings {image}")
        self.preprocess = preprocess
        self.image = image
        self.grid = CartesianGrid.covering(image.max_range_m, image.cell_m)
        self._warper = CartesianWarper(self.grid)
        self._taper = radial_taper(self.grid, image.max_range_m, image.taper_fraction)

    def __call__(
        self, polar: NDArray, azimuths_rad: NDArray[np.float64], range_resolution_m: float
    ) -> NDArray[np.float32]:
        """The cleaned, tapered Cartesian image of one polar scan (image convention of warp.py).

        Args:
            polar: (n_azimuths, n_bins) intensities, rows at `azimuths_rad` (CCW) [rad].
            range_resolution_m: bin size of `polar` [m].
        """
        coarse, res = resample_range(
            polar, range_resolution_m, self.image.cell_m, self.image.max_range_m
        )
        clean = suppress_noise(coarse, res, self.preprocess)
        cart = self._warper(clean, azimuths_rad, res)
        return finish_disc(cart, self._taper, self.image.subtract_mean)
