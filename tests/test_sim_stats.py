"""Intensity statistics of simulated full-resolution scans against the real Navtech scans.

Bands (pixel values of the uint8 polar scans; the real values are from ../shared/data: one
MulRan CIR204-H scan and the Oxford CTS350-X scans):

| statistic | real MulRan | real Oxford | band |
| --- | --- | --- | --- |
| fraction of pixels < 5 | 0.398 | 0.355 | 0.30 - 0.45 |
| median | 6 | 6 | 5 - 9 |
| 90th percentile | 25 | 28-29 | 20 - 34 |
| 99th percentile | 69 | 73-75 | 60 - 85 |
| 99.9th percentile | 102 | 106 | 92 - 115 |
| max | 136 | 136 | <= 136 |
| mean per range decile | 6-14 | 6-19 | 5 - 22 |
| mean of the last 3 deciles | 6.3 | 6.3 | 5 - 9 |
| near (first half) minus far (last 3 deciles) mean | 6 | 10 | >= 2 |
| lag-1 autocorrelation along range, far range | 0.96 | 0.97 | >= 0.9 |
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from radar_slam.datasets.navtech import OXFORD_HEADER_BYTES
from radar_slam.sim.generate import build_scene, make_renderer, render_frame
from radar_slam.sim.scenarios import get_scenario

N_SCANS = 6
BANDS = {
    "near_zero": (0.30, 0.45),
    "p50": (5, 9),
    "p90": (20, 34),
    "p99": (60, 85),
    "p99.9": (92, 115),
}
DECILE_MEAN_BAND = (5.0, 22.0)
FAR_MEAN_BAND = (5.0, 9.0)
NEAR_MINUS_FAR_MIN = 2.0
RANGE_AUTOCORR_MIN = 0.9
MAX_LEVEL = 136


def statistics(scans: np.ndarray) -> dict[str, float]:
    """The banded statistics of (n, n_azimuths, n_bins) scans."""
    a = scans.astype(np.float64)
    p50, p90, p99, p999 = np.percentile(a, [50, 90, 99, 99.9])
    return {"near_zero": float((a < 5).mean()), "p50": p50, "p90": p90, "p99": p99, "p99.9": p999}


def decile_means(scans: np.ndarray) -> np.ndarray:
    n_bins = scans.shape[-1]
    edges = np.linspace(0, n_bins, 11).astype(int)
    return np.array([scans[..., a:b].mean() for a, b in zip(edges[:-1], edges[1:], strict=True)])


def range_autocorrelation(scan: np.ndarray) -> float:
    """Lag-1 autocorrelation along range of the far tenth of a scan."""
    far = scan[:, -scan.shape[1] // 10 :].astype(np.float64)
    far -= far.mean()
    return float((far[:, 1:] * far[:, :-1]).mean() / (far * far).mean())


@pytest.fixture(scope="module")
def simulated() -> np.ndarray:
    scene = build_scene(get_scenario("loop"))
    renderer = make_renderer(scene)
    frames = np.linspace(10, scene.n_frames - 10, N_SCANS).astype(int)
    return np.stack([render_frame(scene, renderer, int(k)) for k in frames])


def check_bands(scans: np.ndarray) -> None:
    for name, value in statistics(scans).items():
        low, high = BANDS[name]
        assert low <= value <= high, f"{name} = {value} outside [{low}, {high}]"
    means = decile_means(scans)
    assert np.all((means >= DECILE_MEAN_BAND[0]) & (means <= DECILE_MEAN_BAND[1])), means
    far = means[-3:].mean()
    assert FAR_MEAN_BAND[0] <= far <= FAR_MEAN_BAND[1], means
    assert means[:5].mean() - far >= NEAR_MINUS_FAR_MIN, means
    assert range_autocorrelation(scans[0]) >= RANGE_AUTOCORR_MIN
    assert scans.max() <= MAX_LEVEL


def test_simulated_scans_are_in_the_real_bands(simulated: np.ndarray) -> None:
    assert simulated.shape == (N_SCANS, 400, 3360)
    check_bands(simulated)


@pytest.mark.realdata
def test_the_bands_hold_the_real_scans(mulran_raw_dir: Path, oxford_dir: Path) -> None:
    mulran = cv2.imread(str(next((mulran_raw_dir / "polar").glob("*.png"))), cv2.IMREAD_UNCHANGED).T
    check_bands(mulran[None])
    oxford = np.stack(
        [
            cv2.imread(str(p), cv2.IMREAD_UNCHANGED)[:, OXFORD_HEADER_BYTES:]
            for p in sorted((oxford_dir / "radar").glob("*.png"))
        ]
    )
    check_bands(oxford)


@pytest.mark.realdata
def test_simulated_statistics_are_close_to_the_real_ones(
    simulated: np.ndarray, mulran_raw_dir: Path
) -> None:
    real = cv2.imread(str(next((mulran_raw_dir / "polar").glob("*.png"))), cv2.IMREAD_UNCHANGED).T[
        None
    ]
    sim, ref = statistics(simulated), statistics(real)
    assert abs(sim["near_zero"] - ref["near_zero"]) < 0.06
    for name in ("p90", "p99", "p99.9"):
        assert abs(sim[name] - ref[name]) <= 0.15 * ref[name], (name, sim[name], ref[name])
    # The histogram of the lowest levels (the sensor's integer power counts) matches.
    for level in (0, 6, 9):
        assert abs((simulated == level).mean() - (real == level).mean()) < 0.05, level
