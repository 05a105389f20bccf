"""The odometry's fast paths equal the straightforward computations they replace.

Bit for bit: the uint16 bin sums and the counting ring median against OpenCV's area resize and a
partition, the per-scan caches (wrapped polar image, refinement spectrum) against fresh
computations. To float32 precision (compiled float32 kernels against float64 numpy): the
sampling maps, the cross-power spectra of the 2-D and 1-D phase correlations, the packed spectra
and the Fourier-Mellin log magnitude. The peak statistics against known answers: Gaussian peaks,
whose log the fit describes exactly.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest
from test_odometry_units import FakeScan, clockwise_azimuths

from odometry.config import OdometryConfig, PreprocessConfig
from odometry.phase_correlation import (
    ROTATION,
    SPECTRUM_EPS,
    _centred_log_magnitude,
    _rotation_of_peak,
    correlate,
    correlate_1d,
    forward,
    forward_rows,
    inverse,
    locate_peak,
    pack,
    polar_grid,
    refine_rotation_against,
)
from odometry.preprocess import cartesian_level, preprocess_polar, render_cartesian, sampling_maps
from odometry.registration import PreparedScan, _residual_rotation, coarse_level
from raplace.warp import wrap_rows

N_AZ = 400
SWEEP_S = 0.25


def _random_map_arguments(rng: np.random.Generator, deskew: bool) -> dict:
    first_row_s = float(rng.uniform(-SWEEP_S, 0.0))
    return {
        "first_azimuth_rad": float(rng.uniform(-4.0, 4.0)),
        "azimuth_step_rad": float(rng.choice([-1.0, 1.0]) * 2.0 * np.pi / N_AZ),
        "n_azimuths": N_AZ,
        "bin_size_m": float(rng.uniform(0.05, 0.3)),
        "rotation_rad": float(rng.uniform(-3.5, 3.5)),
        "twist": rng.normal(0.0, [10.0, 1.0, 0.5]) if deskew else None,
        "timing": (first_row_s, SWEEP_S / N_AZ),
    }


def _maps_float64(
    x: np.ndarray,
    y: np.ndarray,
    rng: np.ndarray,
    bearing: np.ndarray,
    **kwargs: object,
) -> tuple[np.ndarray, np.ndarray]:
    """`sampling_maps` from its formulas in float64: the row of the bearing, the range of the
    point seen from the sensor at the row's time and its bearing to first order."""
    first, step, n = kwargs["first_azimuth_rad"], kwargs["azimuth_step_rad"], N_AZ
    rotation, twist, timing = kwargs["rotation_rad"], kwargs["twist"], kwargs["timing"]
    x, y, rng, bearing = (np.asarray(a, np.float64) for a in (x, y, rng, bearing))
    rows = np.mod((bearing - first - rotation) / step, n)
    if twist is None:
        return rng / kwargs["bin_size_m"] - 0.5, rows
    c, s = np.cos(rotation), np.sin(rotation)
    wx, wy = c * twist[0] - s * twist[1], s * twist[0] + c * twist[1]
    tau = timing[0] + rows * timing[1]
    bins = np.hypot(x - tau * wx, y - tau * wy) / kwargs["bin_size_m"] - 0.5
    turn = tau * ((x * wy - y * wx) / (rng**2 - tau * (x * wx + y * wy)) + twist[2])
    return bins, np.mod(rows - turn / step, n)


@pytest.mark.parametrize("deskew", [False, True])
def test_sampling_map_kernel_equals_float64_formulas(deskew: bool) -> None:
    rng = np.random.default_rng(11)
    level = cartesian_level(0.5, 96)
    grid = polar_grid(ROTATION)
    point_sets = [
        (level.x_m, level.y_m, level.range_m, level.bearing_rad),
        grid.shifted(3.2, -1.1),  # the refinement grid seen from a moved sensor
    ]
    for points in point_sets:
        far = points[2] > 5.0  # nearer, the bearing correction's denominator amplifies rounding
        for _ in range(6):
            kwargs = _random_map_arguments(rng, deskew)
            bins, rows = sampling_maps(*points, **kwargs)
            ref_bins, ref_rows = _maps_float64(*points, **kwargs)
            assert bins.dtype == rows.dtype == np.float32
            assert rows.min() >= 0.0 and rows.max() <= N_AZ
            np.testing.assert_allclose(bins[far], ref_bins[far], rtol=0, atol=2e-3)
            row_error = (rows - ref_rows + N_AZ / 2) % N_AZ - N_AZ / 2
            assert np.abs(row_error[far]).max() < 2e-3
            if deskew:  # the de-skew really moved the samples
                plain_bins, _ = sampling_maps(*points, **{**kwargs, "twist": None})
                assert np.abs(bins - plain_bins).max() > 0.1


@pytest.mark.parametrize("ring", [False, True])
@pytest.mark.parametrize("factor", [1, 2, 3, 5])
def test_bin_means_and_ring_median_equal_area_resize_and_partition(factor: int, ring: bool) -> None:
    rng = np.random.default_rng(factor)
    polar = rng.integers(0, 256, (N_AZ, 600), dtype=np.uint8)
    polar[:, 100:200] = rng.integers(0, 3, (N_AZ, 100))  # many ties, as in radar noise
    polar[:, :7] = 255  # saturated sums
    scan = FakeScan(0, polar, clockwise_azimuths(N_AZ), 0.05)
    cfg = PreprocessConfig(
        bin_size_m=0.05 * factor,
        min_range_m=0.0,
        max_range_m=100.0,
        ring_noise_removal=ring,
        noise_floor_sigmas=-1.0,
    )
    n_bins = polar.shape[1] // factor * factor
    expected = cv2.resize(
        polar[:, :n_bins].astype(np.float32),
        (n_bins // factor, N_AZ),
        interpolation=cv2.INTER_AREA,
    )
    if ring:
        median = np.partition(expected, N_AZ // 2, axis=0)[N_AZ // 2]
        expected = np.maximum(expected - median, 0.0)
    conditioned = preprocess_polar(scan, cfg)
    assert conditioned.image.dtype == np.float32
    np.testing.assert_array_equal(conditioned.image, expected)


def _blob_scan(seed: int, timestamp_ns: int = 0) -> FakeScan:
    rng = np.random.default_rng(seed)
    polar = rng.integers(0, 30, (N_AZ, 900), dtype=np.uint8)
    rows = rng.integers(0, N_AZ, 300)
    cols = rng.integers(60, 900, 300)
    polar[rows, cols] = rng.integers(120, 255, 300, dtype=np.uint8)
    times = timestamp_ns + ((np.arange(N_AZ) - N_AZ / 2) * (SWEEP_S / N_AZ * 1e9)).astype(np.int64)
    return FakeScan(
        timestamp_ns=timestamp_ns,
        polar=cv2.GaussianBlur(polar, (5, 3), 0),
        azimuths_rad=clockwise_azimuths(N_AZ),
        range_resolution_m=0.1,
        azimuth_times_ns=times,
    )


def test_wrapped_polar_image_repeats_row_0() -> None:
    polar = preprocess_polar(_blob_scan(1), PreprocessConfig(bin_size_m=0.2, max_range_m=80.0))
    np.testing.assert_array_equal(polar.wrapped_image, wrap_rows(polar.image))
    assert np.shares_memory(polar.wrapped_image, polar.image)  # one array, no copy


def test_prepared_scan_caches_equal_fresh_computations() -> None:
    cfg = OdometryConfig()
    polar = preprocess_polar(_blob_scan(3), cfg.preprocess)
    twist = np.array([7.0, 0.3, 0.2])
    scan = PreparedScan(polar, twist, cfg)
    coarse = render_cartesian(polar, coarse_level(cfg), 0.0, twist, scan.image_time_s)
    np.testing.assert_array_equal(scan.coarse_spectrum, forward(coarse))
    grid = polar_grid(ROTATION)
    np.testing.assert_array_equal(scan.refine_spectrum, forward_rows(scan.refine_image))
    # The cached reference spectrum gives the same residual rotation as the images.
    moving = PreparedScan(preprocess_polar(_blob_scan(3, 250_000_000), cfg.preprocess), twist, cfg)
    cached = _residual_rotation(scan, moving, np.array([1.5, 0.2]), 0.05)
    points = grid.shifted(1.5, 0.2)
    fresh = refine_rotation_against(
        forward_rows(scan.refine_image), moving._sample(points, 0.05), ROTATION
    )
    assert cached == fresh


def _correlate_numpy(
    ref: np.ndarray, moved: np.ndarray, smoothing_px: float, half_turn: bool
) -> np.ndarray:
    """`correlate` of two images in plain float64 numpy operations."""
    if half_turn:  # turned by pi about the centre, which lies between pixels
        moved = moved[::-1, ::-1]
    cross = np.fft.rfft2(moved) * np.conj(np.fft.rfft2(ref))
    cross /= np.abs(cross) + SPECTRUM_EPS
    fy = np.fft.fftfreq(ref.shape[0])[:, None]
    fx = np.fft.rfftfreq(ref.shape[1])[None, :]
    cross *= np.exp(-2.0 * (np.pi * smoothing_px) ** 2 * (fy * fy + fx * fx))
    return np.fft.irfft2(cross, s=ref.shape)


def _correlate_1d_numpy(ref: np.ndarray, moved: np.ndarray, smoothing: float) -> np.ndarray:
    """`correlate_1d` of two (rows, n) images in plain float64 numpy operations."""
    cross = np.fft.rfft(moved, axis=1) * np.conj(np.fft.rfft(ref, axis=1))
    cross /= np.abs(cross) + SPECTRUM_EPS
    summed = cross.sum(axis=0)
    summed[0] = 0.0
    summed *= np.exp(-2.0 * (np.pi * smoothing * np.fft.rfftfreq(ref.shape[1])) ** 2)
    return np.fft.irfft(summed, n=ref.shape[1]) / ref.shape[0]


def _relative_error(actual: np.ndarray, expected: np.ndarray) -> float:
    return float(np.abs(actual - expected).max() / np.abs(expected).max())


def _shifted_pair(size: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    image = cv2.GaussianBlur(rng.random((size, size), dtype=np.float32), (0, 0), 1.5)
    return image, np.roll(image, (int(rng.integers(-20, 20)), int(rng.integers(-20, 20))), (0, 1))


@pytest.mark.parametrize("half_turn", [False, True])
def test_cross_power_kernel_equals_numpy_reference(half_turn: bool) -> None:
    ref, moved = _shifted_pair(96, seed=int(half_turn))
    if half_turn:  # a turned image, which the half-turn correlation turns back
        moved = np.ascontiguousarray(moved[::-1, ::-1])
    surface = correlate(forward(ref), forward(moved), ref.shape, 1.3, half_turn)
    expected = _correlate_numpy(ref, moved, 1.3, half_turn)
    assert surface.dtype == np.float32 and surface.shape == ref.shape
    assert _relative_error(surface, expected) < 1e-6
    assert np.argmax(surface) == np.argmax(expected)


@pytest.mark.parametrize("n", [180, 179])
def test_summed_angular_correlation_equals_numpy_reference(n: int) -> None:
    rng = np.random.default_rng(4)
    polar = rng.random((40, n), dtype=np.float32)
    turned = np.roll(polar, 7, axis=1) + rng.normal(0, 0.1, polar.shape).astype(np.float32)
    curve = correlate_1d(forward_rows(polar), forward_rows(turned), n, 1.0)
    assert _relative_error(curve, _correlate_1d_numpy(polar, turned, 1.0)) < 1e-6
    assert int(np.argmax(curve)) == 7


PEAK_PRECISION = np.linalg.inv(np.array([[1.69, 0.4], [0.4, 1.0]]))
"""Inverse covariance [1/px^2] of the Gaussian peaks below (1.3 px along rows, 1 px along columns,
correlated)."""
BACKGROUND = 0.01
"""Amplitude of the +-checkerboard around them: its standard deviation."""


def _gaussian_peak_surface(
    centres: list[tuple[float, float]], heights: list[float], size: int = 64
) -> np.ndarray:
    """A periodic (size, size) float32 surface: Gaussian peaks (`PEAK_PRECISION`) at the
    sub-pixel `centres` (rows, cols) in the rows within 5 of each centre (the peak's noise band),
    a checkerboard of +-`BACKGROUND` (mean 0, standard deviation `BACKGROUND`) elsewhere."""
    i, j = np.mgrid[0:size, 0:size].astype(np.float64)
    surface = BACKGROUND * (1.0 - 2.0 * ((i + j) % 2))
    for (ci, cj), height in zip(centres, heights, strict=True):
        di = (i - ci + size / 2) % size - size / 2
        dj = (j - cj + size / 2) % size - size / 2
        a, b, c = PEAK_PRECISION[0, 0], PEAK_PRECISION[0, 1], PEAK_PRECISION[1, 1]
        band = np.abs(di) <= 5.0
        peak = height * np.exp(-0.5 * (a * di * di + 2 * b * di * dj + c * dj * dj))
        surface[band] = peak[band]
    return surface.astype(np.float32)


@pytest.mark.parametrize(
    ("centre", "wrapped"),
    [((20.3, 40.6), (20.3, -23.4)), ((63.7, 0.2), (-0.3, 0.2)), ((5.45, 31.9), (5.45, 31.9))],
)
def test_a_gaussian_peak_is_located_and_its_width_measured(
    centre: tuple[float, float], wrapped: tuple[float, float]
) -> None:
    """The log of a Gaussian is a quadratic, so the fit is exact: the sub-pixel centre (as a
    shift in [-size/2, size/2)), the curvature its inverse covariance, the quality the height at
    the top pixel over the background's standard deviation, the covariance the Gaussian's
    divided by the squared quality."""
    surface = _gaussian_peak_surface([centre], [1.0])
    peak = locate_peak(surface, 1.0)
    np.testing.assert_allclose(peak.shift_px, wrapped, atol=1e-4)
    np.testing.assert_allclose(peak.curvature, PEAK_PRECISION, atol=1e-4)
    top = np.round(centre) - np.array(centre)
    height = np.exp(-0.5 * top @ PEAK_PRECISION @ top)
    assert peak.quality == pytest.approx(height / BACKGROUND, rel=1e-4)
    covariance = np.linalg.inv(PEAK_PRECISION) / peak.quality**2
    np.testing.assert_allclose(peak.covariance_px(), covariance, rtol=1e-3)
    # A saddle instead of a peak: 10 px either way, not a covariance from the fit.
    flat = dataclasses.replace(peak, curvature=np.array([[1.0, 0.0], [0.0, -1.0]]))
    np.testing.assert_allclose(flat.covariance_px(), np.eye(2) * 1e2 / peak.quality**2)


def test_a_search_window_finds_the_weaker_peak_inside_it() -> None:
    """Two peaks, the stronger outside the window: the window's own peak is located, also when
    the window wraps round the surface's edges."""
    for weak, strong in (((10.2, -20.4 % 64), (40.0, 30.0)), ((63.6, 63.3), (30.0, 30.0))):
        surface = _gaussian_peak_surface([weak, strong], [0.5, 1.0])
        assert locate_peak(surface, 1.0).shift_px == pytest.approx(
            (np.array(strong) + 32) % 64 - 32, abs=1e-4
        )
        near = (weak[0] + 2.0, weak[1] - 3.0)
        found = locate_peak(surface, 1.0, near, 6.0).shift_px
        np.testing.assert_allclose(found, (np.array(weak) + 32) % 64 - 32, atol=1e-4)


def test_centred_log_magnitude_equals_numpy() -> None:
    ref, _ = _shifted_pair(64, seed=12)
    spectrum = np.fft.rfft2(ref.astype(np.float64))
    out = np.empty(spectrum.shape, np.float32)
    _centred_log_magnitude(forward(ref), out)
    expected = np.fft.fftshift(np.log1p(np.abs(spectrum)), axes=0)
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-4)  # float32 DFT


@pytest.mark.parametrize("shape", [(4, 6), (64, 64), (96, 40)])
def test_packed_spectra_hold_the_numpy_half_spectra(shape: tuple[int, int]) -> None:
    image = np.random.default_rng(shape[0]).random(shape, dtype=np.float32)
    packed = forward(image)
    assert packed.shape == shape and packed.dtype == np.float32
    assert _relative_error(packed, pack(np.fft.rfft2(image.astype(np.float64)))) < 1e-6
    np.testing.assert_allclose(inverse(packed) / image.size, image, atol=1e-5)
    with pytest.raises(ValueError, match="even"):
        forward(np.zeros((5, 8), np.float32))
    rows = np.fft.rfft(image.astype(np.float64), axis=1)  # per row: Re 0, (Re, Im) pairs, Re n/2
    expected = np.column_stack(
        [rows[:, 0].real, np.stack([rows.real, rows.imag], axis=2)[:, 1:-1].reshape(shape[0], -1)]
    )
    expected = np.column_stack([expected, rows[:, -1].real])
    assert _relative_error(forward_rows(image), expected) < 1e-6


def test_an_angular_gaussian_peak_gives_its_rotation_and_width() -> None:
    """A Gaussian of 1.5 samples at sample 277.3 of 360 (0.5 deg apart) over a +-0.01 alternating
    background: the rotation is minus the wrapped shift (82.7 samples, 41.35 deg), the quality
    the height over the background, the standard deviation the width over the quality."""
    step = np.deg2rad(0.5)
    samples = np.arange(360)
    distance = (samples - 277.3 + 180.0) % 360 - 180.0
    curve = np.where(
        np.abs(distance) <= 5.0,
        np.exp(-0.5 * (distance / 1.5) ** 2),
        BACKGROUND * (1.0 - 2.0 * (samples % 2)),
    )
    estimate = _rotation_of_peak(curve, 1.0, step)
    assert np.rad2deg(estimate.angle_rad) == pytest.approx(41.35, abs=1e-9)
    height = np.exp(-0.5 * (0.3 / 1.5) ** 2)
    assert estimate.quality == pytest.approx(height / BACKGROUND, rel=1e-4)
    assert estimate.sigma_rad == pytest.approx(1.5 * step / estimate.quality, rel=1e-9)
