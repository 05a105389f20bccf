"""Place-recognition evaluation: revisit truth from ground truth, precision-recall sweeps.

Pure arrays in, arrays out; no files, no printing. `radar_slam.commands.placerec` (the `pr`
command) feeds it frames and writes the results.

Protocol (the one of the radar place-recognition papers: Scan Context, MulRan, RaPlace)
--------------------------------------------------------------------------------------------
Every evaluated frame is a query. Its *candidates* are

- intra-session: the earlier frames of the same sequence, except the `recent_keyframes` most
  recent ones, those less than `recent_seconds` older (when > 0) and those less than
  `recent_metres` of travel behind (ground-truth path length, when > 0): a prefix of the frames
  (`intra_session_candidate_counts`). `match_intra_session` inserts each frame into the
  recognizers' databases just before the first query allowed to match it, so what they can
  return and what the truth counts are one rule;
- multi-session: every frame of the map sequence (no exclusion).

A query is a *true revisit* when at least one candidate lies within `criterion_m` of it (ground
truth positions, metres). The recognizer returns the query's best candidate, at distance d
(d = +inf when it has no candidate). At a threshold t:

- the query is a *positive* when d < t;
- a positive is a *true positive* (TP) when its best candidate lies within `criterion_m` of the
  query, a *false positive* (FP) otherwise;
- a true revisit that is not a TP is a *false negative* (FN) (so FN = true revisits - TP);

    precision(t) = TP / (TP + FP)   (1 by convention when there is no positive),
    recall(t)    = TP / true revisits.

A vehicle standing still (at a junction, at the start) keeps seeing the frames a frame or time
window lets through from the same spot: each of its queries is a trivial revisit. A query is
*standing* when it has candidates under the frame and time rules alone and the newest of them is
less than `criterion_m` of travel behind it (`standing_queries`); excluding by distance
travelled (`recent_metres` >= `criterion_m`) leaves no such revisit.

The curve is swept over every threshold at which a query changes state (just above each
distinct finite d, plus one threshold below all of them); the sweep is one sort and two
cumulative sums. AUC is the trapezoidal area under precision(recall) in that order, max F1 the
maximum of 2 P R / (P + R) over the sweep, and recall@1 the fraction of true revisits whose best
candidate lies within the criterion whatever its distance (the recall at t = +inf).
"""

from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import Literal, Protocol

import numpy as np
from numpy.typing import NDArray

from radar_slam.datasets.frame import RadarFrame
from radar_slam.errors import RadarSlamError
from raplace import (
    NS_PER_S,
    DescriptorExtractor,
    ExclusionConfig,
    PlaceRecognizer,
    RaPlaceConfig,
    Recognizer,
    ScanContextExtractor,
    ScanContextRecognizer,
)

log = logging.getLogger(__name__)

REVISIT_CRITERIA_M = (10.0, 20.0, 50.0)
"""Revisit criteria of the radar PR literature [m]; 20 m is the default."""
DEFAULT_CRITERION_M = 20.0
DEFAULT_EXCLUDE_RECENT = 50
"""Most recent frames a query may not match (RaPlace's evaluation protocol)."""
METHODS = ("raplace", "scancontext")
NO_MATCH = -1
"""match_index of a query without any candidate."""
TRUTH_BLOCK_ELEMENTS = 4_000_000
"""Query x map pairs handled per block of the revisit search (bounds memory, ~32 MB)."""

Mode = Literal["intra", "multi"]


class PlaceRecognitionError(RadarSlamError):
    """The evaluation cannot run: no ground truth, inconsistent inputs."""


# --------------------------------------------------------------------------------------------
# Ground truth


def path_length_m(xy: NDArray[np.float64]) -> NDArray[np.float64]:
    """(n,) distance travelled [m] from the first of (n, 2) positions [m] to each (0 first)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    steps = np.hypot(*np.diff(xy, axis=0).T) if len(xy) > 1 else np.zeros(0)
    return np.concatenate([[0.0], np.cumsum(steps)])[: len(xy)]


def intra_session_candidate_counts(
    times_s: NDArray[np.float64],
    exclusion: ExclusionConfig,
    travelled_m: NDArray[np.float64] | None = None,
    recent_metres: float = 0.0,
) -> NDArray[np.int64]:
    """How many leading frames each query may match in intra-session evaluation.

    Query i sees frames 0..i-1 minus the most recent `recent_keyframes`, minus those newer
    than t_i - recent_seconds when recent_seconds > 0, and minus those travelled less than
    `recent_metres` before it (s_i - s_j < recent_metres) when recent_metres > 0. With
    increasing times and non-decreasing path lengths this is always a prefix 0..count_i - 1, and
    count_i never decreases with i.

    Args:
        times_s: (n,) frame times [s], strictly increasing.
        exclusion: the frame and time window.
        travelled_m: (n,) distance travelled at each frame [m] (`path_length_m`); needed when
            recent_metres > 0.
        recent_metres: travel [m] a candidate must lie behind the query (0 disables).

    Returns:
        (n,) int64 counts, count_i <= max(0, i - recent_keyframes).
    """
    times = np.asarray(times_s, dtype=np.float64)
    if len(times) > 1 and not np.all(np.diff(times) > 0):
        raise PlaceRecognitionError("frame times must be strictly increasing")
    counts = np.maximum(np.arange(len(times)) - max(0, exclusion.recent_keyframes), 0)
    if exclusion.recent_seconds > 0:
        older = np.searchsorted(times, times - exclusion.recent_seconds, side="right")
        counts = np.minimum(counts, older)
    if recent_metres > 0:
        if travelled_m is None or np.shape(travelled_m) != times.shape:
            raise PlaceRecognitionError("excluding by distance needs (n,) distances travelled")
        travelled = np.asarray(travelled_m, dtype=np.float64)
        if np.any(np.diff(travelled) < 0):
            raise PlaceRecognitionError("distances travelled must not decrease")
        behind = np.searchsorted(travelled, travelled - recent_metres, side="right")
        counts = np.minimum(counts, behind)
    return counts.astype(np.int64)


def standing_queries(
    times_s: NDArray[np.float64],
    exclusion: ExclusionConfig,
    travelled_m: NDArray[np.float64],
    criterion_m: float,
) -> NDArray[np.bool_]:
    """(n,) True where a query is standing: the frame and time rules of `exclusion` leave it
    candidates, and the newest of them is less than `criterion_m` of travel behind it, so that
    it is a revisit whatever the place recognition does.

    Args:
        times_s: (n,) frame times [s], strictly increasing.
        exclusion: the frame and time window (its distance rule, if any, is not applied).
        travelled_m: (n,) distance travelled at each frame [m] (`path_length_m`).
        criterion_m: revisit radius [m].
    """
    travelled = np.asarray(travelled_m, dtype=np.float64)
    counts = intra_session_candidate_counts(times_s, exclusion)
    newest = travelled[np.maximum(counts - 1, 0)] if len(travelled) else travelled
    return (counts > 0) & (travelled - newest < criterion_m)


def revisit_truth(
    query_xy: NDArray[np.float64],
    map_xy: NDArray[np.float64],
    candidate_counts: NDArray[np.int64],
    criterion_m: float,
) -> NDArray[np.bool_]:
    """Which queries are true revisits: some allowed map frame lies within the criterion.

    Args:
        query_xy: (n_q, 2) query positions [m] (ground truth).
        map_xy: (n_m, 2) map positions [m], same world frame.
        candidate_counts: (n_q,) query i may match map frames 0..candidate_counts[i] - 1.
        criterion_m: revisit radius [m]; a distance equal to it counts.

    Returns:
        (n_q,) bool.
    """
    query_xy = np.asarray(query_xy, dtype=np.float64).reshape(-1, 2)
    map_xy = np.asarray(map_xy, dtype=np.float64).reshape(-1, 2)
    counts = np.asarray(candidate_counts, dtype=np.int64)
    if counts.shape != (len(query_xy),):
        raise PlaceRecognitionError(
            f"candidate_counts shape {counts.shape} != ({len(query_xy)},) queries"
        )
    revisit = np.zeros(len(query_xy), dtype=bool)
    if len(map_xy) == 0:
        return revisit
    radius2 = float(criterion_m) ** 2
    map_index = np.arange(len(map_xy))
    block = max(1, TRUTH_BLOCK_ELEMENTS // len(map_xy))
    for start in range(0, len(query_xy), block):
        stop = start + block
        gaps = query_xy[start:stop, None, :] - map_xy[None, :, :]
        within = np.einsum("qmc,qmc->qm", gaps, gaps) <= radius2
        allowed = map_index[None, :] < counts[start:stop, None]
        revisit[start:stop] = np.any(within & allowed, axis=1)
    return revisit


def match_within_criterion(
    query_xy: NDArray[np.float64],
    map_xy: NDArray[np.float64],
    match_index: NDArray[np.int64],
    criterion_m: float,
) -> NDArray[np.bool_]:
    """(n_q,) bool: the query's best candidate lies within `criterion_m` of it (False for none).

    Args:
        query_xy: (n_q, 2) query positions [m].
        map_xy: (n_m, 2) map positions [m].
        match_index: (n_q,) index into map_xy of each query's best candidate, NO_MATCH for none.
    """
    query_xy = np.asarray(query_xy, dtype=np.float64).reshape(-1, 2)
    map_xy = np.asarray(map_xy, dtype=np.float64).reshape(-1, 2)
    match_index = np.asarray(match_index, dtype=np.int64)
    has_match = match_index != NO_MATCH
    if np.any(match_index[has_match] >= len(map_xy)) or np.any(match_index < NO_MATCH):
        raise PlaceRecognitionError("match index out of the map's range")
    matched_xy = map_xy[np.where(has_match, match_index, 0)] if len(map_xy) else query_xy
    gap = np.linalg.norm(query_xy - matched_xy, axis=1)
    return has_match & (gap <= criterion_m)


# --------------------------------------------------------------------------------------------
# Precision-recall sweep


@dataclass(frozen=True)
class PRCurve:
    """A precision-recall curve and its summary numbers (see the module docstring).

    Attributes:
        thresholds: (n_t,) increasing distance thresholds t (a query is positive when d < t).
        precision: (n_t,) TP / (TP + FP), 1 where there is no positive.
        recall: (n_t,) TP / true revisits (0 when there are none).
        true_positives: (n_t,) TP counts.
        false_positives: (n_t,) FP counts.
        queries: number of queries evaluated.
        true_revisits: number of queries that are true revisits.
        auc: trapezoidal area under precision(recall).
        max_f1: the best F1 over the thresholds.
        threshold_at_max_f1: the threshold reaching it (+inf when there is no positive).
        recall_at_1: fraction of true revisits whose best candidate is within the criterion.
    """

    thresholds: NDArray[np.float64]
    precision: NDArray[np.float64]
    recall: NDArray[np.float64]
    true_positives: NDArray[np.int64]
    false_positives: NDArray[np.int64]
    queries: int
    true_revisits: int
    auc: float
    max_f1: float
    threshold_at_max_f1: float
    recall_at_1: float

    @property
    def f1(self) -> NDArray[np.float64]:
        """(n_t,) F1 score at each threshold."""
        return f1_score(self.precision, self.recall)


def f1_score(precision: NDArray[np.float64], recall: NDArray[np.float64]) -> NDArray[np.float64]:
    """F1 = 2 P R / (P + R), 0 where P + R = 0 (element-wise)."""
    precision = np.asarray(precision, dtype=np.float64)
    recall = np.asarray(recall, dtype=np.float64)
    total = precision + recall
    return np.where(total > 0, 2.0 * precision * recall / np.where(total > 0, total, 1.0), 0.0)


def sweep_thresholds(distances: NDArray[np.float64]) -> NDArray[np.float64]:
    """Thresholds at which the PR state changes: below every finite distance, then just above
    each distinct one (so that with `d < t` each distance becomes positive in turn).

    Returns an empty array when no distance is finite.
    """
    d = np.asarray(distances, dtype=np.float64)
    distinct = np.unique(d[np.isfinite(d)])
    if len(distinct) == 0:
        return np.zeros(0)
    return np.concatenate([distinct[:1], np.nextafter(distinct, np.inf)])


def pr_curve(
    distances: NDArray[np.float64],
    correct: NDArray[np.bool_],
    revisit: NDArray[np.bool_],
    thresholds: NDArray[np.float64] | None = None,
) -> PRCurve:
    """Precision and recall of a set of queries over distance thresholds (vectorised).

    Args:
        distances: (n_q,) distance of each query's best candidate (+inf or NaN: no candidate).
        correct: (n_q,) the best candidate is within the revisit criterion.
        revisit: (n_q,) the query is a true revisit.
        thresholds: increasing thresholds; default `sweep_thresholds(distances)`.

    Returns:
        The curve with AUC, max F1 and recall@1.
    """
    d = np.asarray(distances, dtype=np.float64)
    correct = np.asarray(correct, dtype=bool)
    revisit = np.asarray(revisit, dtype=bool)
    if not d.shape == correct.shape == revisit.shape or d.ndim != 1:
        raise PlaceRecognitionError(
            f"distances, correct and revisit must be (n,) arrays of one length, got {d.shape}, "
            f"{correct.shape}, {revisit.shape}"
        )
    if np.any(correct & ~revisit):
        raise PlaceRecognitionError(
            "a query's best candidate is within the criterion but the query is not a revisit: "
            "the recognizer's exclusion window differs from the revisit truth's"
        )
    d = np.where(np.isnan(d), np.inf, d)
    t = sweep_thresholds(d) if thresholds is None else np.asarray(thresholds, dtype=np.float64)
    if t.ndim != 1 or np.any(np.diff(t) < 0):
        raise PlaceRecognitionError("thresholds must be a 1-D increasing array")
    order = np.argsort(d, kind="stable")
    sorted_d = d[order]
    tp_cum = np.concatenate([[0], np.cumsum(correct[order])])
    positives = np.searchsorted(sorted_d, t, side="left")  # count of d < t
    tp = tp_cum[positives].astype(np.int64)
    fp = (positives - tp).astype(np.int64)
    n_revisits = int(revisit.sum())
    precision = np.where(positives > 0, tp / np.maximum(positives, 1), 1.0)
    recall = tp / n_revisits if n_revisits else np.zeros(len(t))
    f1 = f1_score(precision, recall)
    best = int(np.argmax(f1)) if len(t) else 0
    max_f1 = float(f1[best]) if len(t) else 0.0
    if len(t) > 1:
        auc = float(np.sum(np.diff(recall) * 0.5 * (precision[1:] + precision[:-1])))
    else:
        auc = 0.0
    return PRCurve(
        thresholds=t,
        precision=precision.astype(np.float64),
        recall=np.asarray(recall, dtype=np.float64),
        true_positives=tp,
        false_positives=fp,
        queries=len(d),
        true_revisits=n_revisits,
        auc=auc,
        max_f1=max_f1,
        threshold_at_max_f1=float(t[best]) if max_f1 > 0 else float("inf"),
        recall_at_1=float(correct.sum() / n_revisits) if n_revisits else 0.0,
    )


@dataclass(frozen=True)
class BestMatches:
    """Each query's best candidate under one method.

    Attributes:
        method: "raplace" or "scancontext".
        query_index: (n_q,) index of each query frame in the evaluated frame list.
        match_index: (n_q,) index of its best candidate in the map frame list, NO_MATCH for none.
        distance: (n_q,) that candidate's distance, +inf for none.
        yaw_rad: (n_q,) the candidate's yaw in the query frame (modulo the method's period), NaN
            for none [rad].
        seconds: wall time of the method (descriptors, insertions and queries) [s].
        descriptor_seconds: the part spent computing descriptors [s].
        frames: scans whose descriptor was computed (queries, plus the map in multi-session).
    """

    method: str
    query_index: NDArray[np.int64]
    match_index: NDArray[np.int64]
    distance: NDArray[np.float64]
    yaw_rad: NDArray[np.float64]
    seconds: float
    descriptor_seconds: float
    frames: int = 0


def evaluate_matches(
    matches: BestMatches,
    query_xy: NDArray[np.float64],
    map_xy: NDArray[np.float64],
    candidate_counts: NDArray[np.int64],
    criterion_m: float,
) -> PRCurve:
    """The PR curve of one method's best matches against ground-truth positions.

    Args:
        matches: the method's best candidate per query.
        query_xy: (n_frames, 2) positions of the frames `matches.query_index` indexes [m].
        map_xy: (n_map, 2) positions of the frames `matches.match_index` indexes [m].
        candidate_counts: (n_frames,) map frames each query frame may match (a prefix).
        criterion_m: revisit radius [m].
    """
    q_xy = np.asarray(query_xy, dtype=np.float64)[matches.query_index]
    counts = np.asarray(candidate_counts, dtype=np.int64)[matches.query_index]
    revisit = revisit_truth(q_xy, map_xy, counts, criterion_m)
    correct = match_within_criterion(q_xy, map_xy, matches.match_index, criterion_m)
    return pr_curve(matches.distance, correct, revisit)


# --------------------------------------------------------------------------------------------
# Running the recognizers over frames


class Extractor(Protocol):
    def __call__(
        self, polar: NDArray, azimuths_rad: NDArray[np.float64], range_resolution_m: float
    ) -> NDArray[np.float32]: ...


@dataclass
class MethodRun:
    """One method's extractor and database, and the matches recorded so far (mutable).

    Database keys are frame indices (of the map sequence in multi-session mode).
    """

    method: str
    extractor: Extractor
    recognizer: Recognizer
    query_index: list[int] = field(default_factory=list)
    match_index: list[int] = field(default_factory=list)
    distance: list[float] = field(default_factory=list)
    yaw_rad: list[float] = field(default_factory=list)
    seconds: float = 0.0
    descriptor_seconds: float = 0.0
    frames: int = 0

    def describe(self, frame: RadarFrame) -> NDArray[np.float32]:
        start = time.perf_counter()
        desc = self.extractor(frame.polar, frame.azimuths_rad, frame.range_resolution_m)
        elapsed = time.perf_counter() - start
        self.frames += 1
        self.descriptor_seconds += elapsed
        self.seconds += elapsed
        return desc

    def add(self, index: int, frame: RadarFrame, desc: NDArray | None = None) -> None:
        """Insert a frame into the database (computing its descriptor unless given)."""
        desc = self.describe(frame) if desc is None else desc
        self.insert(index, frame.timestamp_ns / NS_PER_S, desc)

    def insert(self, index: int, time_s: float, desc: NDArray) -> None:
        """Insert a described frame (time [s]) into the database."""
        start = time.perf_counter()
        self.recognizer.add(desc, index, time_s)
        self.seconds += time.perf_counter() - start

    def query(self, index: int, frame: RadarFrame) -> NDArray[np.float32]:
        """Record the best candidate of a frame; returns its descriptor."""
        desc = self.describe(frame)
        start = time.perf_counter()
        found = self.recognizer.query(desc, 1, frame.timestamp_ns / NS_PER_S)
        self.seconds += time.perf_counter() - start
        self.query_index.append(index)
        if found:
            self.match_index.append(found[0].key)
            self.distance.append(found[0].distance)
            self.yaw_rad.append(found[0].yaw_rad)
        else:
            self.match_index.append(NO_MATCH)
            self.distance.append(float("inf"))
            self.yaw_rad.append(float("nan"))
        return desc

    def result(self) -> BestMatches:
        return BestMatches(
            method=self.method,
            query_index=np.asarray(self.query_index, dtype=np.int64),
            match_index=np.asarray(self.match_index, dtype=np.int64),
            distance=np.asarray(self.distance, dtype=np.float64),
            yaw_rad=np.asarray(self.yaw_rad, dtype=np.float64),
            seconds=self.seconds,
            descriptor_seconds=self.descriptor_seconds,
            frames=self.frames,
        )


def with_exclusion(cfg: RaPlaceConfig, exclusion: ExclusionConfig) -> RaPlaceConfig:
    """`cfg` with the exclusion window of both recognizers replaced by `exclusion`."""
    return replace(
        cfg,
        retrieval=replace(cfg.retrieval, exclusion=exclusion),
        scancontext=replace(cfg.scancontext, exclusion=exclusion),
    )


def method_runs(methods: Iterable[str], cfg: RaPlaceConfig) -> list[MethodRun]:
    """Fresh extractor + database per method, from the config's sections."""
    runs: list[MethodRun] = []
    for method in methods:
        if method == "raplace":
            runs.append(
                MethodRun(
                    method, DescriptorExtractor(cfg.descriptor), PlaceRecognizer(cfg.retrieval)
                )
            )
        elif method == "scancontext":
            runs.append(
                MethodRun(
                    method,
                    ScanContextExtractor(cfg.scancontext),
                    ScanContextRecognizer(cfg.scancontext),
                )
            )
        else:
            raise PlaceRecognitionError(f"unknown method {method!r} (known: {', '.join(METHODS)})")
    return runs


def match_intra_session(
    frames: Iterable[tuple[int, RadarFrame]],
    runs: list[MethodRun],
    candidate_counts: NDArray[np.int64] | None = None,
) -> dict[str, BestMatches]:
    """Query each frame against the earlier ones (online loop detection).

    Args:
        frames: (index, frame) in time order; the index is the frame's position in the
            evaluated list (what ground-truth arrays are indexed by), 0, 1, 2, ...
        runs: one per method; their recognizers must start empty.
        candidate_counts: (n,) frames each query may match (`intra_session_candidate_counts`):
            each frame then joins the databases just before the first query allowed to match
            it, and the recognizers must exclude nothing themselves. None: each frame joins
            right after its own query and the recognizers' exclusion windows apply.
    """
    held: deque[tuple[int, float, list[NDArray]]] = deque()
    for seen, (index, frame) in enumerate(frames):
        due = seen if candidate_counts is None else int(candidate_counts[index])
        while held and held[0][0] < due:
            key, time_s, descriptors = held.popleft()
            for run, desc in zip(runs, descriptors, strict=True):
                run.insert(key, time_s, desc)
        descriptors = [run.query(index, frame) for run in runs]
        held.append((index, frame.timestamp_ns / NS_PER_S, descriptors))
    return {run.method: run.result() for run in runs}


def build_map(frames: Iterable[tuple[int, RadarFrame]], runs: list[MethodRun]) -> None:
    """Insert every map frame into each method's database (multi-session, first pass)."""
    for index, frame in frames:
        for run in runs:
            run.add(index, frame)


def match_queries(
    frames: Iterable[tuple[int, RadarFrame]], runs: list[MethodRun]
) -> dict[str, BestMatches]:
    """Query each frame against the map built by `build_map` (multi-session, second pass)."""
    for index, frame in frames:
        for run in runs:
            run.query(index, frame)
    return {run.method: run.result() for run in runs}
