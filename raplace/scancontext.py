"""Radar Scan Context baseline (Kim and Kim, IROS 2018; the radar version of the MulRan paper).

A scan becomes a polar context (n_rings, n_sectors) holding the maximum intensity of each
range-ring x azimuth-sector bin. Retrieval: the nearest entries by ring key (the mean of each
ring over sectors, rotation invariant), then the column-shift distance

    d(q, m) = min_s  mean_j (1 - cos(q[:, j], m[:, j - s]))    (over columns non-empty in both)

whose best shift gives the yaw. `ScanContextRecognizer` has the interface of
raplace.retrieval.PlaceRecognizer (add / query / save / load), so evaluations run both.

Sector j covers CCW azimuths [j, j + 1) * 2 pi / n_sectors from +x (forward); ring i covers
ranges [i, i + 1) * max_range_m / n_rings.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from raplace import RaPlaceError
from raplace.config import ScanContextConfig
from raplace.preprocess import resample_range, suppress_noise
from raplace.retrieval import (
    Candidate,
    GrowingArray,
    KeyframeIndex,
    entry_times,
    load_database,
    save_database,
)

log = logging.getLogger(__name__)

COLUMN_NORM_EPS = 1e-9
"""Columns with a smaller norm are empty (ignored by the distance)."""
TWO_PI = 2.0 * np.pi


def scan_context(
    polar: NDArray,
    azimuths_rad: NDArray[np.float64],
    range_resolution_m: float,
    cfg: ScanContextConfig,
) -> NDArray[np.float32]:
    """Polar context (n_rings, n_sectors) float32 of one scan: max cleaned intensity per bin.

    Args:
        polar: (n_azimuths, n_bins) intensities, rows at `azimuths_rad` (CCW) [rad].
        range_resolution_m: bin size [m].
        cfg: context settings (bins are first averaged to `range_cell_m`, then cleaned with
            `preprocess`).
    """
    azimuths = np.asarray(azimuths_rad, dtype=np.float64)
    if np.ndim(polar) != 2 or np.shape(polar)[0] != len(azimuths):
        raise RaPlaceError(
            f"polar must be (n_azimuths, n_bins) with n_azimuths = {len(azimuths)}, "
            f"got {np.shape(polar)}"
        )
    coarse, res = resample_range(polar, range_resolution_m, cfg.range_cell_m, cfg.max_range_m)
    clean = suppress_noise(coarse, res, cfg.preprocess)
    centres = (np.arange(clean.shape[1]) + 0.5) * res
    ring = np.minimum((centres * (cfg.n_rings / cfg.max_range_m)).astype(np.int64), cfg.n_rings)
    # Max over the bins of each ring (bins are sorted by range, so rings are contiguous runs).
    ring_max = np.zeros((clean.shape[0], cfg.n_rings), dtype=np.float32)
    present = np.unique(ring[ring < cfg.n_rings])
    starts = np.searchsorted(ring, present)
    ring_max[:, present] = np.maximum.reduceat(clean, starts, axis=1)[:, : len(present)]
    sector = (np.mod(azimuths, TWO_PI) * (cfg.n_sectors / TWO_PI)).astype(np.int64)
    sector = np.minimum(sector, cfg.n_sectors - 1)
    context = np.zeros((cfg.n_sectors, cfg.n_rings), dtype=np.float32)
    np.maximum.at(context, sector, ring_max)
    return np.ascontiguousarray(context.T)


def ring_key(context: NDArray) -> NDArray[np.float32]:
    """(..., n_rings) mean of each ring over sectors (rotation invariant)."""
    return np.asarray(context, dtype=np.float32).mean(axis=-1)


def column_shift_distance(
    query: NDArray, candidates: NDArray
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Scan Context distance of a query context to many, minimised over column shifts.

    Args:
        query: (n_rings, n_sectors) context.
        candidates: (n, n_rings, n_sectors) contexts.

    Returns:
        (distance (n,) in [0, 1] (1 when no column pair is comparable), yaw (n,) [rad] in
        (-pi, pi]: the candidate scan's yaw in the query frame at the best shift).
    """
    query = np.asarray(query, dtype=np.float64)
    candidates = np.asarray(candidates, dtype=np.float64)
    n_sectors = query.shape[1]
    q_norm = np.linalg.norm(query, axis=0)
    c_norm = np.linalg.norm(candidates, axis=1)  # (n, n_sectors)
    q_valid = q_norm > COLUMN_NORM_EPS
    c_valid = c_norm > COLUMN_NORM_EPS
    q_unit = query / np.where(q_valid, q_norm, 1.0)
    c_unit = candidates / np.where(c_valid, c_norm, 1.0)[:, None, :]
    # Row s of the stack is the query rolled so that column j' + s meets candidate column j'.
    shifts = np.arange(n_sectors)
    columns = (shifts[:, None] + shifts[None, :]) % n_sectors  # (shift, j')
    q_shifted = q_unit[:, columns]  # (n_rings, shift, j')
    similarity = np.einsum("rsj,crj->cs", q_shifted, c_unit)
    overlap = q_valid[columns].astype(np.float64) @ c_valid.T.astype(np.float64)  # (shift, n)
    overlap = overlap.T
    distance = np.where(overlap > 0, 1.0 - similarity / np.maximum(overlap, 1.0), 1.0)
    best = np.argmin(distance, axis=1)
    yaw = best * (TWO_PI / n_sectors)
    yaw = np.where(yaw > np.pi, yaw - TWO_PI, yaw)
    return distance[np.arange(len(best)), best], yaw


class ScanContextExtractor:
    """Polar scan -> Scan Context (n_rings, n_sectors) float32; called like DescriptorExtractor."""

    def __init__(self, cfg: ScanContextConfig) -> None:
        self.cfg = cfg

    @property
    def shape(self) -> tuple[int, int]:
        return (self.cfg.n_rings, self.cfg.n_sectors)

    def __call__(
        self, polar: NDArray, azimuths_rad: NDArray[np.float64], range_resolution_m: float
    ) -> NDArray[np.float32]:
        return scan_context(polar, azimuths_rad, range_resolution_m, self.cfg)


class ScanContextRecognizer:
    """Scan Context keyframe database with the PlaceRecognizer interface."""

    method = "scancontext"

    def __init__(self, cfg: ScanContextConfig) -> None:
        self.cfg = cfg
        shape = (cfg.n_rings, cfg.n_sectors)
        self._contexts = GrowingArray(shape, np.float32)
        self._ring_keys = GrowingArray((cfg.n_rings,), np.float32)
        self._index = KeyframeIndex()

    def __len__(self) -> int:
        return len(self._index)

    @property
    def keys(self) -> NDArray[np.int64]:
        """(n_entries,) keys in insertion order."""
        return self._index.keys.copy()

    @property
    def descriptor_shape(self) -> tuple[int, int]:
        return (self.cfg.n_rings, self.cfg.n_sectors)

    def add(self, descriptor: NDArray, key: int, time_s: float | None = None) -> None:
        """Store one context (n_rings, n_sectors) with its key and optional time [s]."""
        times = None if time_s is None else np.array([time_s], dtype=np.float64)
        self.add_batch(np.asarray(descriptor)[None], np.array([key]), times)

    def add_batch(
        self, descriptors: NDArray, keys: NDArray, times_s: NDArray[np.float64] | None = None
    ) -> None:
        """Store (n, n_rings, n_sectors) contexts with (n,) keys and optional (n,) times [s]."""
        descriptors = np.asarray(descriptors, dtype=np.float32)
        keys = np.asarray(keys, dtype=np.int64)
        if descriptors.shape[1:] != self.descriptor_shape or len(keys) != len(descriptors):
            raise RaPlaceError(
                f"need (n, {self.cfg.n_rings}, {self.cfg.n_sectors}) contexts and n keys, got "
                f"{descriptors.shape} and {keys.shape}"
            )
        times = entry_times(times_s, keys)
        self._contexts.extend(descriptors)
        self._ring_keys.extend(ring_key(descriptors))
        self._index.extend(keys, times)

    def query(
        self, descriptor: NDArray, k: int = 1, time_s: float | None = None
    ) -> list[Candidate]:
        """The k best candidates (ring-key shortlist, then column-shift distance), best first."""
        descriptor = np.asarray(descriptor, dtype=np.float32)
        if descriptor.shape != self.descriptor_shape:
            raise RaPlaceError(f"query shape {descriptor.shape} != {self.descriptor_shape}")
        allowed = self._index.allowed(time_s, self.cfg.exclusion)
        if len(allowed) == 0:
            return []
        gaps = np.sum((self._ring_keys.values[allowed] - ring_key(descriptor)) ** 2, axis=1)
        n_short = min(len(allowed), max(self.cfg.n_candidates, k))
        shortlist = allowed[np.argpartition(gaps, n_short - 1)[:n_short]]
        distance, yaw = column_shift_distance(descriptor, self._contexts.values[shortlist])
        return self._index.ranked(shortlist, distance, yaw, k, yaw_period_rad=TWO_PI)

    def is_loop(self, candidate: Candidate) -> bool:
        """True when the candidate's distance is below the configured loop threshold."""
        return candidate.distance < self.cfg.loop_threshold

    def save(self, path: Path) -> None:
        """Write the database (contexts, keys, times, config) to an .npz file."""
        save_database(path, self.method, self.cfg, self._contexts.values, self._index)

    @classmethod
    def load(cls, path: Path, cfg: ScanContextConfig | None = None) -> ScanContextRecognizer:
        """Read a database written by `save`; `cfg` overrides the stored settings."""
        recognizer = load_database(path, cls.method, cls, ScanContextConfig, cfg)
        log.debug("loaded %d Scan Context keyframes from %s", len(recognizer), path)
        return recognizer
