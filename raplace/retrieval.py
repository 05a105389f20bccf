"""Keyframe database and place queries: `PlaceRecognizer` (RaPlace).

A query scores database entries with the mutable-threshold distance of raplace.scoring. With
`hierarchical` on, a query runs three stages, none with a Python loop over the database:
1. rank the allowed entries by a rotation-invariant bound of their low-resolution correlation
   (raplace.index: one matrix-vector product per kept harmonic) and keep the best
   `coarse_shortlist`;
2. score those on low-resolution descriptors (`coarse_descriptor`) with the rotation search;
3. re-score the best `coarse_candidates` and their `neighbour_radius` neighbours by insertion
   index at full resolution.
`coarse_shortlist` 0 skips stage 1 (every allowed entry is scored at low resolution).

The pieces shared with the Scan Context baseline (`Candidate`, `GrowingArray`,
`candidate_mask`, `KeyframeIndex`, the .npz layout with `save_database` / `load_database`) live
here too. The invariant index is derived from the descriptors when they are added, so it is not
stored: files keep format version 1.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, TypeVar

import numpy as np
import scipy.fft
from numpy.typing import NDArray

from raplace import RaPlaceError
from raplace.config import ExclusionConfig, RetrievalConfig
from raplace.config_io import from_dict, to_dict
from raplace.descriptor import coarse_descriptor
from raplace.growing import GrowingArray  # re-exported: its home before raplace.growing
from raplace.index import InvariantIndex
from raplace.scoring import score, theta_spectrum

log = logging.getLogger(__name__)

ConfigT = TypeVar("ConfigT")
DatabaseT = TypeVar("DatabaseT", bound="BatchDatabase")

FILE_FORMAT_VERSION = 1


@dataclass(frozen=True)
class Candidate:
    """One ranked answer of a place query.

    Attributes:
        key: the key the entry was added with (e.g. its timestamp [ns] or frame index).
        index: insertion index of the entry in the database.
        distance: dissimilarity (lower is more similar); a loop is declared below the
            recognizer's `loop_threshold`.
        yaw_rad: estimated yaw of the entry's scan in the query scan's frame (CCW) [rad].
        yaw_period_rad: the yaw is known modulo this (pi for RaPlace, whose descriptor repeats
            every pi: yaw_rad + pi is the other hypothesis; 2 pi for Scan Context).
    """

    key: int
    index: int
    distance: float
    yaw_rad: float
    yaw_period_rad: float


def candidate_mask(
    times_s: NDArray[np.float64], query_time_s: float | None, exclusion: ExclusionConfig
) -> NDArray[np.bool_]:
    """Which database entries a query may match.

    Args:
        times_s: (n_entries,) time of each entry [s], NaN when unknown.
        query_time_s: the query's time [s]; None means the most recent known entry time.
        exclusion: the most recent `recent_keyframes` entries are excluded, and entries newer
            than query_time_s - recent_seconds (when recent_seconds > 0).

    Returns:
        (n_entries,) bool, True where the entry is a valid candidate.
    """
    n = len(times_s)
    allowed = np.arange(n) < n - max(0, exclusion.recent_keyframes)
    if exclusion.recent_seconds > 0 and n:
        known = np.isfinite(times_s)
        if query_time_s is None and known.any():
            query_time_s = float(np.max(times_s[known]))
        if query_time_s is not None:
            recent = known & (times_s > query_time_s - exclusion.recent_seconds)
            allowed &= ~recent
    return allowed


def neighbourhood(indices: NDArray[np.int64], radius: int, n_entries: int) -> NDArray[np.int64]:
    """Sorted unique indices within `radius` of any of `indices`, clipped to [0, n_entries)."""
    offsets = np.arange(-radius, radius + 1)
    around = (np.asarray(indices)[:, None] + offsets[None, :]).ravel()
    return np.unique(np.clip(around, 0, n_entries - 1))


def save_npz(path: Path, method: str, config: object, arrays: dict[str, NDArray]) -> None:
    """Write a recognizer database: its arrays plus method name, config and format version."""
    meta = {"method": method, "version": FILE_FORMAT_VERSION, "config": to_dict(config)}
    np.savez(Path(path), allow_pickle=False, meta=np.array(json.dumps(meta)), **arrays)


def load_npz(path: Path, method: str) -> tuple[dict, dict[str, NDArray]]:
    """Read a file written by `save_npz` for `method`: (config dict, arrays)."""
    try:
        with np.load(Path(path), allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
    except (OSError, ValueError) as exc:
        raise RaPlaceError(f"{path}: cannot read the place database ({exc})") from None
    if "meta" not in arrays:
        raise RaPlaceError(f"{path}: not a place database (no meta record)")
    meta = json.loads(str(arrays.pop("meta")))
    if meta.get("method") != method or meta.get("version") != FILE_FORMAT_VERSION:
        raise RaPlaceError(
            f"{path}: holds a {meta.get('method')!r} database version {meta.get('version')}, "
            f"expected {method!r} version {FILE_FORMAT_VERSION}"
        )
    return meta["config"], arrays


class Recognizer(Protocol):
    """A place database: `PlaceRecognizer`, `ScanContextRecognizer`, or your own.

    Keys are the caller's (scan indices); `time_s` [s] lets the database exclude recent entries.
    """

    def __len__(self) -> int: ...

    def add(self, descriptor: NDArray, key: int, time_s: float | None = None) -> None: ...

    def query(
        self, descriptor: NDArray, k: int = 1, time_s: float | None = None
    ) -> list[Candidate]: ...


class BatchDatabase(Protocol):
    """What `load_database` needs of a recognizer: batch insertion."""

    def add_batch(
        self, descriptors: NDArray, keys: NDArray, times_s: NDArray[np.float64] | None = None
    ) -> None: ...


def entry_times(times_s: NDArray[np.float64] | None, keys: NDArray[np.int64]) -> NDArray:
    """(n,) float64 times [s] of n new entries with (n,) `keys`: NaN (unknown) when None."""
    times = np.full(len(keys), np.nan) if times_s is None else np.asarray(times_s, float)
    if times.shape != keys.shape:
        raise RaPlaceError(f"times shape {times.shape} != keys shape {keys.shape}")
    return times


class KeyframeIndex:
    """Keys and times [s] of a place database's entries, in insertion order.

    The bookkeeping both recognizers share: the exclusion window over the stored times and the
    ranking of scored entries into `Candidate`s.
    """

    def __init__(self) -> None:
        self._keys = GrowingArray((), np.int64)
        self._times = GrowingArray((), np.float64)

    def __len__(self) -> int:
        return len(self._keys)

    @property
    def keys(self) -> NDArray[np.int64]:
        """(n_entries,) keys (a view, invalidated by the next `extend`)."""
        return self._keys.values

    @property
    def times_s(self) -> NDArray[np.float64]:
        """(n_entries,) times [s], NaN when unknown (a view, invalidated by the next `extend`)."""
        return self._times.values

    def extend(self, keys: NDArray[np.int64], times_s: NDArray[np.float64]) -> None:
        """Append (n,) keys and their (n,) times [s] (see `entry_times`)."""
        self._keys.extend(keys)
        self._times.extend(times_s)

    def allowed(self, time_s: float | None, exclusion: ExclusionConfig) -> NDArray[np.int64]:
        """Sorted indices of the entries a query at `time_s` may match (see `candidate_mask`)."""
        return np.flatnonzero(self.allowed_mask(time_s, exclusion))

    def allowed_mask(self, time_s: float | None, exclusion: ExclusionConfig) -> NDArray[np.bool_]:
        """(n_entries,) True where a query at `time_s` may match the entry (`candidate_mask`)."""
        return candidate_mask(self._times.values, time_s, exclusion)

    def ranked(
        self,
        indices: NDArray[np.int64],
        distance: NDArray[np.float64],
        yaw_rad: NDArray[np.float64],
        k: int,
        yaw_period_rad: float,
    ) -> list[Candidate]:
        """The k scored entries of least distance, best first (ties keep the given order).

        Args:
            indices: (m,) insertion indices of the scored entries.
            distance: (m,) their distances; yaw_rad: (m,) their yaws in the query frame [rad].
            yaw_period_rad: the period the yaws are known modulo [rad].
        """
        order = np.argsort(distance, kind="stable")[: max(0, k)]
        keys = self._keys.values
        return [
            Candidate(
                key=int(keys[indices[i]]),
                index=int(indices[i]),
                distance=float(distance[i]),
                yaw_rad=float(yaw_rad[i]),
                yaw_period_rad=float(yaw_period_rad),
            )
            for i in order
        ]


def save_database(
    path: Path, method: str, config: object, descriptors: NDArray, index: KeyframeIndex
) -> None:
    """Write a recognizer's (n, ...) descriptors with the keys and times of `index`."""
    arrays = {"descriptors": descriptors, "keys": index.keys, "times_s": index.times_s}
    save_npz(path, method, config, arrays)


def load_database(
    path: Path,
    method: str,
    factory: Callable[[ConfigT], DatabaseT],
    config_type: type[ConfigT],
    cfg: ConfigT | None,
) -> DatabaseT:
    """Read a file written by `save_database` into `factory(cfg or the stored config)`."""
    stored, arrays = load_npz(path, method)
    database = factory(cfg if cfg is not None else from_dict(config_type, stored))
    if len(arrays["keys"]):
        database.add_batch(arrays["descriptors"], arrays["keys"], arrays["times_s"])
    return database


class PlaceRecognizer:
    """RaPlace keyframe database: add descriptors, query the best matching places.

    Descriptors come from raplace.descriptor (`DescriptorExtractor`), all of one shape
    (n_theta, n_freq), fixed by the first `add`.
    """

    method = "raplace"

    def __init__(self, cfg: RetrievalConfig) -> None:
        self.cfg = cfg
        self._index = KeyframeIndex()
        self._full: GrowingArray | None = None  # (n, n_theta // 2 + 1, n_freq) complex64
        self._coarse: GrowingArray | None = None  # same for the coarse descriptors
        self._invariant: InvariantIndex | None = None  # of the coarse descriptors
        self._shape: tuple[int, int] | None = None

    def __len__(self) -> int:
        return len(self._index)

    @property
    def keys(self) -> NDArray[np.int64]:
        """(n_entries,) keys in insertion order."""
        return self._index.keys.copy()

    @property
    def descriptor_shape(self) -> tuple[int, int] | None:
        """(n_theta, n_freq) of the stored descriptors, None while empty."""
        return self._shape

    def add(self, descriptor: NDArray, key: int, time_s: float | None = None) -> None:
        """Store one keyframe descriptor.

        Args:
            descriptor: (n_theta, n_freq) z-normalised RaPlace descriptor.
            key: identifier returned by queries (e.g. the scan timestamp [ns]).
            time_s: the keyframe's time [s] for the seconds-based exclusion window.
        """
        self.add_batch(
            np.asarray(descriptor)[None],
            np.array([key]),
            None if time_s is None else np.array([time_s], dtype=np.float64),
        )

    def add_batch(
        self, descriptors: NDArray, keys: NDArray, times_s: NDArray[np.float64] | None = None
    ) -> None:
        """Store (n, n_theta, n_freq) descriptors with (n,) keys and optional (n,) times [s]."""
        descriptors = np.asarray(descriptors, dtype=np.float32)
        keys = np.asarray(keys, dtype=np.int64)
        if descriptors.ndim != 3 or len(keys) != len(descriptors):
            raise RaPlaceError(
                f"need (n, n_theta, n_freq) descriptors and n keys, got {descriptors.shape} "
                f"and {keys.shape}"
            )
        if not np.all(np.isfinite(descriptors)):
            raise RaPlaceError("descriptors contain NaN or infinity")
        shape = (int(descriptors.shape[1]), int(descriptors.shape[2]))
        if self._shape is None:
            self._init_storage(shape)
        elif shape != self._shape:
            raise RaPlaceError(f"descriptor shape {shape} != database shape {self._shape}")
        times = entry_times(times_s, keys)
        assert self._full is not None and self._coarse is not None and self._invariant is not None
        self._full.extend(theta_spectrum(descriptors))
        coarse_spectra = theta_spectrum(self._coarse_of(descriptors))
        self._coarse.extend(coarse_spectra)
        self._invariant.extend(coarse_spectra)
        self._index.extend(keys, times)

    def _init_storage(self, shape: tuple[int, int]) -> None:
        n_theta, n_freq = shape
        pool = self.cfg.coarse_theta_pool
        if n_theta % pool or not 1 <= self.cfg.coarse_n_freq <= n_freq:
            raise RaPlaceError(
                f"coarse settings (theta_pool {pool}, n_freq {self.cfg.coarse_n_freq}) do not fit "
                f"descriptors of shape {shape}"
            )
        self._shape = shape
        self._full = GrowingArray((n_theta // 2 + 1, n_freq), np.complex64)
        n_coarse = n_theta // pool
        self._coarse = GrowingArray((n_coarse // 2 + 1, self.cfg.coarse_n_freq), np.complex64)
        self._invariant = InvariantIndex(
            n_coarse, self.cfg.coarse_n_freq, self.cfg.coarse_index_harmonics
        )

    def _coarse_of(self, descriptors: NDArray) -> NDArray[np.float32]:
        return coarse_descriptor(descriptors, self.cfg.coarse_theta_pool, self.cfg.coarse_n_freq)

    def query(
        self, descriptor: NDArray, k: int = 1, time_s: float | None = None
    ) -> list[Candidate]:
        """The k best candidates for a query descriptor, most similar first.

        Args:
            descriptor: (n_theta, n_freq) z-normalised descriptor of the query scan.
            k: number of candidates wanted (fewer when fewer are allowed).
            time_s: the query's time [s] for the seconds-based exclusion (None: the most recent
                entry's time).

        Returns:
            Candidates with the mutable-threshold distance and the entry's yaw in the query
            frame modulo pi.
        """
        if self._shape is None or len(self) == 0:
            return []
        descriptor = np.asarray(descriptor, dtype=np.float32)
        if descriptor.shape != self._shape:
            raise RaPlaceError(f"query shape {descriptor.shape} != database shape {self._shape}")
        allowed = self._index.allowed_mask(time_s, self.cfg.exclusion)
        if not allowed.any():
            return []
        subset = self._shortlist(descriptor, allowed)
        assert self._full is not None
        distance, yaw = score(descriptor, self._full.values[subset])
        return self._index.ranked(subset, distance, yaw, k, yaw_period_rad=np.pi)

    def _shortlist(self, descriptor: NDArray[np.float32], allowed: NDArray[np.bool_]) -> NDArray:
        """Entries scored at full resolution: all allowed, or the coarse winners' neighbours.

        Args:
            descriptor: (n_theta, n_freq) query descriptor.
            allowed: (n_entries,) True where the entry may match.
        """
        cfg = self.cfg
        budget = cfg.coarse_candidates * (2 * cfg.neighbour_radius + 1)
        n_allowed = int(np.count_nonzero(allowed))
        if not cfg.hierarchical or n_allowed <= budget:
            return np.flatnonzero(allowed)
        assert self._coarse is not None and self._invariant is not None
        coarse_query = self._coarse_of(descriptor)
        query_spectrum = theta_spectrum(coarse_query)
        if cfg.coarse_shortlist:
            listed = self._invariant.shortlist(query_spectrum, allowed, cfg.coarse_shortlist)
        else:
            listed = np.flatnonzero(allowed)
        coarse_distance, _ = score(coarse_query, self._coarse.values[listed])
        n_best = min(cfg.coarse_candidates, len(listed))
        best = listed[np.argpartition(coarse_distance, n_best - 1)[:n_best]]
        around = neighbourhood(best, cfg.neighbour_radius, len(self))
        return around[allowed[around]]

    def is_loop(self, candidate: Candidate) -> bool:
        """True when the candidate's distance is below the configured loop threshold."""
        return candidate.distance < self.cfg.loop_threshold

    def descriptors(self) -> NDArray[np.float32]:
        """(n_entries, n_theta, n_freq) stored descriptors (rebuilt from their theta-spectra)."""
        if self._shape is None or self._full is None:
            return np.zeros((0, 0, 0), dtype=np.float32)
        return scipy.fft.irfft(self._full.values, n=self._shape[0], axis=1).astype(np.float32)

    def save(self, path: Path) -> None:
        """Write the database (descriptors, keys, times, config) to an .npz file."""
        save_database(path, self.method, self.cfg, self.descriptors(), self._index)

    @classmethod
    def load(cls, path: Path, cfg: RetrievalConfig | None = None) -> PlaceRecognizer:
        """Read a database written by `save`; `cfg` overrides the stored retrieval settings."""
        recognizer = load_database(path, cls.method, cls, RetrievalConfig, cfg)
        log.debug("loaded %d RaPlace keyframes from %s", len(recognizer), path)
        return recognizer
