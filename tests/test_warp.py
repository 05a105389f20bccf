"""Polar -> Cartesian backward warping: geometry and seams."""

from __future__ import annotations

import numpy as np
import pytest

from raplace import RaPlaceError
from raplace.warp import CartesianGrid, CartesianWarper

N_AZ = 400
RES = 0.05


@pytest.mark.parametrize("row", [0, 50, 150, 399])
@pytest.mark.parametrize("direction", [1.0, -1.0])
def test_point_lands_at_its_polar_position(row: int, direction: float) -> None:
    azimuths = direction * np.arange(N_AZ) / N_AZ * 2 * np.pi + 0.01
    polar = np.zeros((N_AZ, 1200), np.uint8)
    polar[row, 990:1011] = 255  # a short radial segment centred on bin 1000
    warper = CartesianWarper(CartesianGrid.covering(60.0, 0.1))
    cart = warper(polar, azimuths, RES).astype(np.float64)
    x, y = warper.grid.pixel_centres()
    cx, cy = (cart * x).sum() / cart.sum(), (cart * y).sum() / cart.sum()
    rng = 1000.5 * RES
    assert cx == pytest.approx(rng * np.cos(azimuths[row]), abs=0.1)
    assert cy == pytest.approx(rng * np.sin(azimuths[row]), abs=0.1)


def test_forward_is_up_and_left_is_left() -> None:
    azimuths = np.arange(N_AZ) / N_AZ * 2 * np.pi
    polar = np.zeros((N_AZ, 400), np.uint8)
    polar[0, 300] = 255  # straight ahead
    polar[100, 300] = 255  # 90 deg CCW: to the left
    warper = CartesianWarper(CartesianGrid.covering(20.0, 0.1))
    cart = warper(polar, azimuths, RES)
    centre = warper.grid.size_px / 2
    ahead = cart[: int(centre), int(centre) - 2 : int(centre) + 2]
    left = cart[int(centre) - 2 : int(centre) + 2, : int(centre)]
    assert ahead.max() > 100 and left.max() > 100
    assert cart[int(centre) + 2 :, :].max() < 1  # nothing behind


def test_seam_between_last_and_first_azimuth_is_filled() -> None:
    azimuths = np.arange(N_AZ) / N_AZ * 2 * np.pi
    polar = np.full((N_AZ, 300), 100, np.uint8)
    cart = CartesianWarper(CartesianGrid.covering(14.0, 0.05))(polar, azimuths, RES)
    grid_x, grid_y = CartesianGrid.covering(14.0, 0.05).pixel_centres()
    ring = (np.hypot(grid_x, grid_y) > 1) & (np.hypot(grid_x, grid_y) < 14)
    assert cart[ring].min() == pytest.approx(100.0, abs=1e-3)  # no holes, incl. the seam


def test_shape_mismatch_is_clear_error() -> None:
    warper = CartesianWarper(CartesianGrid(0.5, 64))
    with pytest.raises(RaPlaceError, match="n_azimuths"):
        warper(np.zeros((10, 20)), np.linspace(0, 6, 12), 0.1)
