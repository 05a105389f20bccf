"""The compiled kernels of the sinogram pose: against their plain numpy formulations, and known
answers."""

from __future__ import annotations

import numpy as np
import pytest

from raplace.descriptor import image_spectrum, radial_spectrum
from raplace.pose import (
    aligned_correlation,
    fit_translation,
    per_angle_shifts,
    pose_angles,
    pose_freqs,
    radial_rows,
)

N_THETA = 32
SIDE = 64
CELL_M = 0.5


def random_rows(rng: np.random.Generator) -> np.ndarray:
    shape = (N_THETA, SIDE + 1)
    return (rng.normal(size=shape) + 1j * rng.normal(size=shape)).astype(np.complex64)


def test_radial_rows_sample_like_radial_spectrum() -> None:
    rng = np.random.default_rng(0)
    fft = image_spectrum(rng.random((SIDE, SIDE)).astype(np.float32), CELL_M, 2)
    thetas = pose_angles(N_THETA) - 0.37
    expected = radial_spectrum(fft, thetas, pose_freqs(fft))
    got = radial_rows(fft, thetas, fft.size // 2 + 1)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-4 * np.abs(expected).max())


def test_per_angle_shifts_find_known_row_shifts() -> None:
    """Rows displaced by b_i along l (phase e^(-2 pi i k b)) give back b_i."""
    rng = np.random.default_rng(1)
    period_m = 2 * SIDE * CELL_M
    freqs = np.arange(SIDE + 1) / period_m
    shifts = rng.uniform(-10.0, 10.0, N_THETA)
    map_rows = random_rows(rng)
    query = (map_rows * np.exp(-2j * np.pi * freqs[None, :] * shifts[:, None])).astype(np.complex64)
    found = per_angle_shifts(query, map_rows, period_m, whitening=0.5, upsample=2)
    np.testing.assert_allclose(found, shifts, atol=0.05)


def test_fit_translation_matches_least_squares_on_the_inliers() -> None:
    rng = np.random.default_rng(2)
    thetas = pose_angles(N_THETA)
    xy = np.array([3.2, -1.7])
    shifts = xy[0] * np.cos(thetas) + xy[1] * np.sin(thetas) + rng.normal(0, 0.05, N_THETA)
    outliers = rng.choice(N_THETA, 6, replace=False)
    shifts[outliers] += rng.uniform(4.0, 8.0, 6)
    got, truncated, inliers = fit_translation(thetas, shifts, threshold_m=1.0)
    assert not inliers[outliers].any() and inliers.sum() == N_THETA - 6
    design = np.stack([np.cos(thetas), np.sin(thetas)], axis=1)
    expected = np.linalg.lstsq(design[inliers], shifts[inliers], rcond=None)[0]
    np.testing.assert_allclose(got, expected, atol=1e-9)
    # Without noise: the translation exactly, and a truncated RMS of the 6 outliers of 32 each
    # counted at the 1 m bound, sqrt(6 / 32).
    exact = xy[0] * np.cos(thetas) + xy[1] * np.sin(thetas)
    exact[outliers] += rng.uniform(4.0, 8.0, 6)
    got, truncated, inliers = fit_translation(thetas, exact, threshold_m=1.0)
    np.testing.assert_allclose(got, xy, atol=1e-9)
    assert truncated == pytest.approx(np.sqrt(6 / 32), rel=1e-9)
    assert not inliers[outliers].any() and inliers.sum() == N_THETA - 6


def test_aligned_correlation_is_one_at_the_true_translation_and_near_zero_elsewhere() -> None:
    """Rows moved by their own translation correlate perfectly, whatever their scale; unrelated
    rows and the right rows at a translation 2 m off hardly correlate."""
    rng = np.random.default_rng(3)
    thetas = pose_angles(N_THETA)
    freqs = np.arange(SIDE + 1, dtype=np.float64) * 0.01
    q, m = random_rows(rng), random_rows(rng)
    xy = np.array([1.5, -0.5])
    shift = (xy[0] * np.cos(thetas) + xy[1] * np.sin(thetas))[:, None]
    moved = (m * np.exp(-2j * np.pi * freqs[None, :] * shift)).astype(np.complex64)
    assert aligned_correlation(moved, m, thetas, freqs, xy) == pytest.approx(1.0, abs=1e-5)
    assert aligned_correlation(3 * moved, m, thetas, freqs, xy) == pytest.approx(1.0, abs=1e-5)
    assert abs(aligned_correlation(q, m, thetas, freqs, xy)) < 0.05
    off = xy + np.array([2.0, 0.0])
    assert abs(aligned_correlation(moved, m, thetas, freqs, off)) < 0.2


def test_aligned_correlation_weighs_each_frequency_by_its_ring() -> None:
    """Polar Parseval: the ring at frequency k covers an area proportional to k. Rows of unit
    magnitude against the same rows cut to their lower half (k = 1..32 of 64, DC excluded)
    correlate sqrt(528 / 2080) = 0.504 (0.707 were every frequency weighed alike)."""
    rng = np.random.default_rng(5)
    thetas = pose_angles(N_THETA)
    freqs = np.arange(SIDE + 1, dtype=np.float64) * 0.01
    rows = np.exp(2j * np.pi * rng.random((N_THETA, SIDE + 1))).astype(np.complex64)
    low = rows.copy()
    low[:, SIDE // 2 + 1 :] = 0.0
    correlation = aligned_correlation(low, rows, thetas, freqs, np.zeros(2))
    assert correlation == pytest.approx(np.sqrt(528 / 2080), abs=1e-5)


def test_image_spectrum_equals_the_shifted_padded_fft2() -> None:
    """The spectrum made from the image's non-zero rows is fftshift(fft2(ifftshift(padded)))."""
    rng = np.random.default_rng(4)
    for side, pad in ((SIDE, 2), (SIDE, 1), (10, 3)):
        cart = rng.random((side, side)).astype(np.float32)
        size = pad * side
        padded = np.zeros((size, size))
        start = size // 2 - side // 2
        padded[start : start + side, start : start + side] = cart[::-1, ::-1]
        expected = np.fft.fftshift(np.fft.fft2(np.fft.ifftshift(padded)))
        grid = image_spectrum(cart, CELL_M, pad).grid
        got = grid[..., 0] + 1j * grid[..., 1]
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-5 * np.abs(expected).max())
