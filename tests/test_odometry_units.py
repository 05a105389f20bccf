"""Unit tests of the odometry building blocks on synthetic inputs (no dataset needed)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np
import pytest

from odometry import OdometryError
from odometry.config import OdometryConfig, PreprocessConfig
from odometry.phase_correlation import correlate, forward, locate_peak
from odometry.preprocess import (
    Scan,
    cartesian_level,
    motion_from_twist,
    preprocess_polar,
    render_cartesian,
    sampling_maps,
    twist_from_motion,
)
from raplace.se2 import compose
from raplace.warp import CartesianGrid, CartesianWarper

N_AZ = 400
N_BINS = 1000
RES_M = 0.1


@dataclass(frozen=True)
class FakeScan:
    timestamp_ns: int
    polar: np.ndarray
    azimuths_rad: np.ndarray
    range_resolution_m: float
    sensor: str = "test"
    azimuth_times_ns: np.ndarray | None = None


def clockwise_azimuths(n: int = N_AZ) -> np.ndarray:
    return -(np.arange(n) + 0.5) * (2.0 * np.pi / n)


def blob_image(size: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    image = np.zeros((size, size), np.float32)
    pts = rng.integers(size // 8, size - size // 8, (150, 2))
    image[pts[:, 0], pts[:, 1]] = rng.uniform(0.5, 1.0, len(pts))
    return cv2.GaussianBlur(image, (0, 0), 1.5)


def fourier_shift(image: np.ndarray, shift: tuple[float, float]) -> np.ndarray:
    """`image` moved by `shift` (rows, cols) pixels, exactly, in the Fourier domain."""
    fy = np.fft.fftfreq(image.shape[0])[:, None]
    fx = np.fft.fftfreq(image.shape[1])[None, :]
    ramp = np.exp(-2j * np.pi * (fy * shift[0] + fx * shift[1]))
    return np.real(np.fft.ifft2(np.fft.fft2(image) * ramp)).astype(np.float32)


@pytest.mark.parametrize("shift", [(3.3, -7.6), (-12.25, 0.5), (0.0, 20.9)])
def test_phase_correlation_recovers_subpixel_shift(shift: tuple[float, float]) -> None:
    image = blob_image(128)
    moved = fourier_shift(image, shift)
    surface = correlate(forward(image), forward(moved), image.shape, smoothing_px=1.0)
    peak = locate_peak(surface, smoothing_px=1.0)
    np.testing.assert_allclose(peak.shift_px, shift, atol=0.03)
    assert peak.quality > 20
    cov = peak.covariance_px()
    assert np.all(np.linalg.eigvalsh(cov) > 0)


def test_phase_correlation_search_window_and_flat_surface() -> None:
    image = blob_image(128, seed=3)
    moved = fourier_shift(image, (5.0, 5.0))
    surface = correlate(forward(image), forward(moved), image.shape, smoothing_px=1.0)
    peak = locate_peak(surface, 1.0, center_px=(4.0, 6.0), radius_px=3)
    np.testing.assert_allclose(peak.shift_px, (5.0, 5.0), atol=0.03)
    flat = locate_peak(np.zeros((64, 64), np.float32), 1.0)
    assert flat.quality == 0.0


def test_twist_round_trip() -> None:
    motion = np.array([2.1, -0.4, 0.3])
    twist = twist_from_motion(motion, 0.25)
    np.testing.assert_allclose(motion_from_twist(twist, 0.25), motion, atol=1e-12)
    # The exponential is the limit of many small constant steps.
    pose = np.zeros(3)
    for _ in range(2000):
        pose = compose(pose, twist * 0.25 / 2000)
    np.testing.assert_allclose(pose, motion, atol=1e-3)
    with pytest.raises(ValueError):
        twist_from_motion(motion, 0.0)


def test_rendering_matches_raplace_warper() -> None:
    """Without preprocessing and de-skew, rendering equals raplace's backward warp."""
    rng = np.random.default_rng(1)
    polar = rng.integers(0, 255, (N_AZ, N_BINS)).astype(np.uint8)
    scan = FakeScan(0, polar, clockwise_azimuths(), RES_M)
    bare = PreprocessConfig(
        bin_size_m=RES_M, min_range_m=0.0, ring_noise_removal=False, noise_floor_sigmas=-1.0
    )
    conditioned = preprocess_polar(scan, bare)
    np.testing.assert_array_equal(conditioned.image, polar.astype(np.float32))
    level = cartesian_level(0.5, 256)
    ours = render_cartesian(conditioned, level) / np.maximum(level.window, 1e-12)
    theirs = CartesianWarper(CartesianGrid(0.5, 256))(polar, scan.azimuths_rad, RES_M)
    inside = level.window > 0.5
    np.testing.assert_allclose(ours[inside], theirs[inside], atol=0.05)


def test_rotation_rendering_turns_the_image() -> None:
    """A return at bearing b lands at b + rotation in the rendered image."""
    polar = np.zeros((N_AZ, N_BINS), np.uint8)
    polar[100, 400:410] = 255  # one target at ~40 m
    scan = FakeScan(0, polar, clockwise_azimuths(), RES_M)
    cfg = PreprocessConfig(bin_size_m=RES_M, ring_noise_removal=False, noise_floor_sigmas=-1.0)
    conditioned = preprocess_polar(scan, cfg)
    level = cartesian_level(0.5, 256)
    for rotation in (0.0, 0.4):
        image = render_cartesian(conditioned, level, rotation)
        r, c = np.unravel_index(np.argmax(image), image.shape)
        bearing = float(level.bearing_rad[r, c])
        expected = scan.azimuths_rad[100] + rotation
        assert abs(np.angle(np.exp(1j * (bearing - expected)))) < np.deg2rad(1.0)


def test_deskew_maps_move_samples_by_the_sweep_motion() -> None:
    """A point seen late in the sweep (tau > 0) is sampled where the moved sensor saw it."""
    x = np.array([[20.0, 0.0]], np.float32)
    y = np.array([[0.0, 20.0]], np.float32)
    rng, bearing = np.hypot(x, y), np.arctan2(y, x)
    common = dict(
        first_azimuth_rad=0.0,
        azimuth_step_rad=2.0 * np.pi / N_AZ,
        n_azimuths=N_AZ,
        bin_size_m=RES_M,
    )
    bins0, rows0 = sampling_maps(x, y, rng, bearing, **common)
    timing = (0.1, 0.0)  # every row 0.1 s after the reference time
    twist = np.array([10.0, 0.0, 0.0])  # 1 m forward in 0.1 s
    bins, rows = sampling_maps(x, y, rng, bearing, **common, twist=twist, timing=timing)
    # Ahead: 1 m closer. Left: ~same range, bearing turned by atan(1/20) away from forward.
    assert bins[0, 0] == pytest.approx(bins0[0, 0] - 1.0 / RES_M, abs=1e-3)
    assert bins[0, 1] == pytest.approx(np.hypot(20.0, 1.0) / RES_M - 0.5, abs=1e-2)
    assert rows[0, 1] - rows0[0, 1] == pytest.approx(
        np.arctan(1.0 / 20.0) * N_AZ / (2 * np.pi), abs=0.02
    )


def test_preprocess_removes_ring_noise_and_near_range() -> None:
    rng = np.random.default_rng(2)
    polar = rng.integers(0, 10, (N_AZ, N_BINS)).astype(np.uint8)
    polar[:, 500:503] = 200  # a constant-range band: ring noise
    polar[:, :20] = 250  # saturated near range
    polar[37, 700:705] = 220  # a real target
    scan = FakeScan(0, polar, clockwise_azimuths(), RES_M)
    out = preprocess_polar(scan, PreprocessConfig(bin_size_m=RES_M, min_range_m=3.0))
    assert out.image[:, 500:503].max() < 20
    assert out.image[:, :30].max() == 0.0
    assert out.image[37, 700:705].min() > 150
    assert out.azimuth_step_rad < 0  # clockwise sweep kept


def test_preprocess_resamples_nonuniform_azimuths_and_times() -> None:
    az = clockwise_azimuths()
    jitter = az + np.deg2rad(0.3) * np.sin(np.arange(N_AZ))
    times = (np.arange(N_AZ) * 625_000).astype(np.int64)  # 250 ms sweep
    scan = FakeScan(
        125_000_000, np.zeros((N_AZ, N_BINS), np.uint8), jitter, RES_M, azimuth_times_ns=times
    )
    out = preprocess_polar(scan, PreprocessConfig())
    assert out.n_azimuths == N_AZ
    assert out.timing is not None
    assert out.timing.row_period_s == pytest.approx(625e-6, rel=1e-6)
    assert out.timing.first_row_s == pytest.approx(-0.125, abs=1e-3)


@pytest.mark.parametrize(
    "polar, azimuths",
    [
        (np.zeros((N_AZ, N_BINS), np.uint8), clockwise_azimuths(N_AZ - 1)),
        (np.zeros((4, N_BINS), np.uint8), clockwise_azimuths(4)),
        (np.zeros(N_BINS, np.uint8), clockwise_azimuths()),
        (np.zeros((N_AZ, N_BINS), np.float32), clockwise_azimuths()),
    ],
)
def test_preprocess_rejects_bad_geometry_or_dtype(polar: np.ndarray, azimuths: np.ndarray) -> None:
    with pytest.raises(OdometryError):
        preprocess_polar(FakeScan(0, polar, azimuths, RES_M), PreprocessConfig())


def test_config_is_hashable_and_strictly_mergeable() -> None:
    from radar_slam.config import merge
    from radar_slam.errors import ConfigError

    cfg = OdometryConfig()
    assert hash(cfg) == hash(OdometryConfig())
    merged = merge(
        OdometryConfig, cfg, {"fine": {"cell_m": 0.3}, "keyframe": {"max_frames": 3}}, "test"
    )
    assert merged.fine.cell_m == 0.3 and merged.keyframe.max_frames == 3
    assert merged.coarse == cfg.coarse
    with pytest.raises(ConfigError):
        merge(OdometryConfig, cfg, {"fine": {"cel_m": 0.3}}, "test")


def test_radar_frame_is_a_scan() -> None:
    from radar_slam.datasets.frame import RadarFrame

    frame = RadarFrame(0, np.zeros((8, 8), np.uint8), clockwise_azimuths(8), 0.1, "x")
    assert isinstance(frame, Scan)
    assert isinstance(dataclasses.replace(frame, timestamp_ns=5), Scan)
