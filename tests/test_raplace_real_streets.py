"""RaPlace on real street scans: the RADIATE Edinburgh drive and its GNSS.

One drive has no revisit of its own, but scans a few metres apart see the same place, and turning
one of them by pi is what a pass the other way sees (scripts/pr_real.py measures the whole drive).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from radar_slam.datasets import DatasetConfig, open_sequence
from radar_slam.placerec import pr_curve
from raplace import DescriptorExtractor, RaPlaceConfig
from raplace.config import PreprocessConfig
from raplace.scoring import score, theta_spectrum

EDINBURGH = "radiate/edinburgh_2019-02-12-15-33"
GNSS_OFFSET_S = 1.84
"""The drive's GNSS clock offset as scripts/pr_real.py estimates it from the odometry [s]."""
STRIDE = 4
"""Every fourth scan (one a second): a quarter of the work, pairs still 5-10 m apart."""
BAND_M = (5.0, 10.0)
FAR_M = 50.0
NEIGHBOUR_M = 20.0


@pytest.fixture(scope="module")
def drive(shared_data: Path) -> tuple[list, NDArray[np.float64]]:
    """(frames, (n, 2) GNSS positions [m]) of every `STRIDE`-th scan with a GNSS fix."""
    if not (shared_data / EDINBURGH).exists():
        pytest.skip(f"{shared_data / EDINBURGH} not found")
    sequence = open_sequence(EDINBURGH, shared_data, DatasetConfig(gt_time_offset_s=GNSS_OFFSET_S))
    assert sequence.ground_truth is not None
    xy = sequence.ground_truth[:, :2]
    kept = [i for i in range(0, len(sequence), STRIDE) if np.isfinite(xy[i, 0])]
    return [sequence[i] for i in kept], xy[kept]


def _describe(frames: list, cfg: RaPlaceConfig, turn_rad: float = 0.0) -> NDArray[np.float32]:
    extract = DescriptorExtractor(cfg.descriptor)
    return np.stack(
        [extract(f.polar, f.azimuths_rad + turn_rad, f.range_resolution_m) for f in frames]
    )


def _distances(queries: NDArray[np.float32], database: NDArray[np.float32]) -> NDArray:
    spectra = theta_spectrum(database)
    return np.array([score(q, spectra)[0] for q in queries])


def _gaps(xy: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))


def _pairs_auc(distances: NDArray, gap: NDArray) -> float:
    """AUC of one distance threshold telling pairs in `BAND_M` from pairs beyond `FAR_M`."""
    positive = (gap >= BAND_M[0]) & (gap <= BAND_M[1])
    pairs = positive | (gap > FAR_M)
    return pr_curve(distances[pairs], positive[pairs], positive[pairs]).auc


@pytest.mark.realdata
def test_azimuth_median_removal_tells_real_neighbours_from_other_places(drive) -> None:
    frames, xy = drive
    gap = _gaps(xy)
    cfg = RaPlaceConfig()
    plain = dataclasses.replace(
        cfg, descriptor=dataclasses.replace(cfg.descriptor, preprocess=PreprocessConfig())
    )
    described = _describe(frames, cfg)
    auc = _pairs_auc(_distances(described, described), gap)
    plain_described = _describe(frames, plain)
    plain_auc = _pairs_auc(_distances(plain_described, plain_described), gap)
    assert auc > 0.95  # 0.96
    assert auc > plain_auc + 0.02  # 0.93 without


@pytest.mark.realdata
def test_a_real_scan_turned_by_pi_finds_its_neighbour(drive) -> None:
    frames, xy = drive
    gap = _gaps(xy)
    database = _describe(frames, RaPlaceConfig())
    queries = np.arange(0, len(frames), 5)
    turned = _describe([frames[i] for i in queries], RaPlaceConfig(), turn_rad=np.pi)
    distances = _distances(turned, database)
    distances[np.arange(len(queries)), queries] = np.inf  # not itself
    found = gap[queries, np.argmin(distances, axis=1)]
    gap[queries, queries] = np.inf
    # Its match is one of its two nearest scans (those just before and after it on the drive,
    # 0-17 m away at this stride), never a scan farther along the road.
    neighbours = np.sort(gap[queries], axis=1)[:, :2]
    has_neighbours = neighbours[:, 0] < NEIGHBOUR_M  # all but a query inside a GNSS outage
    assert has_neighbours.sum() > 25
    assert np.all(found[has_neighbours] <= neighbours[has_neighbours, 1] + 0.5)
