"""Relocalisation on real scans: a map of one half of a real drive's scans, the other half
localised in it, scored against GNSS.

The RADIATE Edinburgh drive has no revisit, but its scans interleave: SLAM on every K-th scan
from scan 0 (`--stride`, default 4: one scan a second, about 8 m apart) makes the map, and every
K-th scan from K / 2 is localised in it, one at a time (`Localizer.localize`), so each query lies
between two map scans, a few metres from them. Variants:

- "as driven": the query scans as recorded, one localizer from the first query on;
- "turned by pi": every query scan turned by pi, what a pass in the other direction sees (the
  yaw is then expected off by pi);
- "cold starts": a new localizer every `COLD_START_QUERIES` queries, so global relocalisation,
  not tracking, places each stretch's first scans;
- "map with a gap": the map keyframes of `GAP_SCANS` removed (a street the map never saw): the
  queries there must be reported lost, not extrapolated, and placed again after it;
- "sparse map": one keyframe in three (`SPARSE_EVERY`), queries farther from their keyframes and
  registrations weaker;
- "map of the first half": only the keyframes of the drive's first half; the drive does not
  come back, so the second half's queries have no right place in the map: every one placed there
  is a wrong claim ("placed off the route"), and their `quality` is what a user's threshold
  must reject.

Each localised position is taken into the GNSS frame through the map's own alignment to GNSS
(`Map.gt_alignment`: the map run's trajectory aligned to its GNSS once), never re-aligned to the
queries; GNSS is read through the clock offset estimated from the odometry (`pr_real`). Queries
in GNSS outages are left out. Printed per variant: of the queries within 10 m of the map's
route (its keyframes' GNSS positions), the share placed within 5 m of GNSS and the share lost;
of all queries, the number placed more than 10 m off and the number placed while more than
10 m from the route (extrapolated past the map); the median yaw error (against the GNSS
heading, less the expected pi when turned); relocalisations; and how well the
CSV's `quality` and `sigma_m` columns separate good from bad placements (the loosest threshold
that keeps only scans within 5 m, and how many scans it keeps). Below the table, over all
variants, the single-scan hypotheses of global relocalisation (each candidate keyframe that
verified, before the chain of agreeing hypotheses decides): how many were wrong (more than 10 m
from GNSS) and right (within 5 m), and their registration quality, the value a fix's `quality`
column carries.

Limits: map and queries come from one pass, so they share the lane, the moment (the same
parked and moving vehicles) and the weather; a real return pass adds a lateral offset of a lane
and a changed scene. GNSS has no RTK (metre level).

Usage: python scripts/reloc_real.py [--data-root ../shared/data] [--stride 4] [--write-doc]
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from bench_real import real_data_parser
from benchmark_doc import machine_line, markdown_table, update_section
from numpy.typing import NDArray
from pr_real import gnss_positions

from radar_slam.datasets import RadarFrame
from radar_slam.datasets.frame import RadarSequence
from radar_slam.datasets.stride import ScanSelection
from radar_slam.loops.records import KeyScan
from radar_slam.maps import Localization, Map, build_map
from radar_slam.maps.evaluate import map_route_gt
from radar_slam.maps.localizer import Localizer
from radar_slam.pipeline import Pipeline, PipelineConfig, load_config
from raplace import compose, wrap_angle

FloatArray = NDArray[np.float64]
GOOD_M = 5.0
"""A query placed within this distance of GNSS is correct [m] (GNSS without RTK)."""
WRONG_M = 10.0
"""A query placed farther than this from GNSS is wrong [m]."""
NEAR_ROUTE_M = 10.0
"""Queries within this distance of the map's route should be placed [m]."""
COLD_START_QUERIES = 20
"""Queries per localizer in the "cold starts" variant (about 160 m of the drive at stride 4)."""
GAP_SCANS = (300, 420)
"""Scans of the drive whose map keyframes the "map with a gap" variant removes (about 250 m)."""
SPARSE_EVERY = 3
"""The "sparse map" variant keeps every this-many-th keyframe (queries up to about 12 m from one,
registrations as weak as a map made in the other lane can give)."""
DOC_SECTION = "Relocalisation on real scans"


class Turned(ScanSelection):
    """Scans of a sequence turned by pi (what a pass in the other direction sees)."""

    def __getitem__(self, index: int) -> RadarFrame:
        frame = super().__getitem__(index)
        return dataclasses.replace(frame, azimuths_rad=frame.azimuths_rad + np.pi)


@dataclass(frozen=True)
class Variant:
    """One way of localising the queries: the scans, the map, how often the localizer starts
    afresh, the yaw expected of a correct placement relative to GNSS [rad], and the map whose
    keyframes trace the route (the map itself unless given: a sparse map covers the streets
    of the full one)."""

    name: str
    queries: RadarSequence
    map: Map
    restart_every: int | None = None
    expected_yaw: float = 0.0
    route: Map | None = None


@dataclass(frozen=True)
class Scored:
    """One variant's outcome: per query, its `Localization`, its position and yaw errors
    against GNSS ([m], [rad]; NaN when lost or without GNSS) and whether it is near the map's
    route."""

    variant: str
    fixes: list[Localization]
    error_m: FloatArray
    yaw_error: FloatArray
    has_gnss: NDArray[np.bool_]
    near_route: NDArray[np.bool_]
    relocalisations: int
    global_attempts: int
    scans_per_s: float
    hypothesis_error_m: FloatArray
    hypothesis_quality: FloatArray


class RecordingLocalizer(Localizer):
    """A `Localizer` that keeps every single-scan hypothesis of global relocalisation (a
    verified candidate keyframe) as (its pose T_map_scan, quality)."""

    def __init__(self, m: Map, config: PipelineConfig) -> None:
        super().__init__(m, config)
        self.hypotheses: list[tuple[FloatArray, float]] = []

    def _verified(self, query: KeyScan, keyframes: list[int]) -> list[Any]:
        fixes = super()._verified(query, keyframes)
        self.hypotheses += [(f.pose, f.quality) for f in fixes]
        return fixes


def make_map(sequence: RadarSequence, stride: int, config: PipelineConfig) -> Map:
    """SLAM on every `stride`-th scan from 0, made into a map (with its GNSS alignment)."""
    scans = ScanSelection(sequence, np.arange(0, len(sequence), stride), sequence.name + "_map")
    return build_map(Pipeline(scans, config).run(), scans)


def keyframe_subset(m: Map, keep: NDArray[np.bool_]) -> Map:
    """`m` with only the keyframes where `keep` (K,) holds; the pose graph is dropped
    (localisation does not use it)."""
    return dataclasses.replace(
        m,
        keyframes=m.keyframes[keep],
        descriptors=m.descriptors[keep],
        images=tuple(image for image, k in zip(m.images, keep, strict=True) if k),
        edges=m.edges[:0],
    )


def with_gap(m: Map, map_scans: NDArray[np.int64], gap: tuple[int, int]) -> Map:
    """`m` without the keyframes of the drive's scans in [gap[0], gap[1]) (`map_scans`: the
    drive's index of each map scan)."""
    scan_of_keyframe = map_scans[np.asarray(m.keyframes["scan"], dtype=np.int64)]
    return keyframe_subset(m, (scan_of_keyframe < gap[0]) | (scan_of_keyframe >= gap[1]))


def localize(variant: Variant, gnss: FloatArray, config: PipelineConfig) -> Scored:
    """Localise every query of `variant`; errors through the map's GNSS alignment.

    Args:
        gnss: (len(queries), 3) GNSS poses of the queries (x, y [m], yaw [rad]; NaN rows in
            outages).
    """
    m = variant.map
    assert m.gt_alignment is not None
    fixes: list[Localization] = []
    seconds, relocalisations, attempts = 0.0, 0, 0
    localizer = RecordingLocalizer(m, config)
    hypotheses: list[tuple[int, FloatArray, float]] = []
    for n in range(len(variant.queries)):
        if variant.restart_every and n and n % variant.restart_every == 0:
            relocalisations += localizer.relocalisations
            attempts += localizer.global_attempts
            localizer = RecordingLocalizer(m, config)
        frame = variant.queries[n]
        start = time.perf_counter()
        fixes.append(localizer.localize(frame))
        seconds += time.perf_counter() - start
        hypotheses += [(n, pose, quality) for pose, quality in localizer.hypotheses]
        localizer.hypotheses = []
    hypothesis_error = np.array(
        [np.hypot(*(compose(m.gt_alignment, pose)[:2] - gnss[n, :2])) for n, pose, _ in hypotheses]
    )
    error, yaw_error = np.full(len(fixes), np.nan), np.full(len(fixes), np.nan)
    for n, f in enumerate(fixes):
        if f.localised:
            placed = compose(m.gt_alignment, f.pose)
            error[n] = float(np.hypot(*(placed[:2] - gnss[n, :2])))
            yaw_error[n] = float(wrap_angle(placed[2] - gnss[n, 2] - variant.expected_yaw))
    route = map_route_gt(m if variant.route is None else variant.route)
    has_gnss = np.isfinite(gnss[:, 0])
    distance = np.full(len(gnss), np.inf)
    for k in np.flatnonzero(has_gnss):
        distance[k] = float(np.min(np.hypot(*(route - gnss[k, :2]).T)))
    return Scored(
        variant.name,
        fixes,
        error,
        yaw_error,
        has_gnss,
        distance <= NEAR_ROUTE_M,
        relocalisations + localizer.relocalisations,
        attempts + localizer.global_attempts,
        len(fixes) / seconds,
        hypothesis_error,
        np.array([quality for _, _, quality in hypotheses]),
    )


def separation(values: FloatArray, good: NDArray[np.bool_], higher_is_better: bool) -> str:
    """The loosest threshold on `values` that keeps only good scans, and how many it keeps
    ("none" when no threshold keeps any scan)."""
    if not len(values):
        return "n/a"
    order = np.argsort(-values if higher_is_better else values, kind="stable")
    bad_at = np.flatnonzero(~good[order])
    kept = int(bad_at[0]) if len(bad_at) else len(order)
    if kept == 0:
        return "none"
    threshold = values[order[kept - 1]]
    sign = ">=" if higher_is_better else "<="
    return f"{sign} {threshold:.3g} keeps {kept} of {int(good.sum())}"


def hypothesis_line(scored: list[Scored]) -> str:
    """The wrong and right single-scan hypotheses of all variants and their quality."""
    error = np.concatenate([s.hypothesis_error_m for s in scored])
    quality = np.concatenate([s.hypothesis_quality for s in scored])
    has_gnss = np.isfinite(error)
    wrong, right = has_gnss & (error > WRONG_M), has_gnss & (error <= GOOD_M)

    def spread(values: FloatArray) -> str:
        if not len(values):
            return "none"
        low, mid, high = np.percentile(values, [0, 50, 100])
        return f"{len(values)}, quality min / median / max {low:.1f} / {mid:.1f} / {high:.1f}"

    return (
        f"Single-scan hypotheses of global relocalisation, all variants ({int(has_gnss.sum())} "
        f"with GNSS): wrong (more than {WRONG_M:.0f} m off) {spread(quality[wrong])}; right "
        f"(within {GOOD_M:.0f} m) {spread(quality[right])}."
    )


def row(s: Scored) -> list[str]:
    """The table row of a variant."""
    localised = np.array([f.localised for f in s.fixes]) & s.has_gnss
    near = s.near_route
    n = int(near.sum())
    good = localised & near & (s.error_m <= GOOD_M)
    wrong = localised & (s.error_m > WRONG_M)
    kept = np.flatnonzero(localised)
    quality = np.array([s.fixes[k].quality for k in kept])
    sigma = np.array([s.fixes[k].sigma_m for k in kept])
    is_good = s.error_m[kept] <= GOOD_M
    median = float(np.median(s.error_m[kept])) if len(kept) else float("nan")
    yaw = float(np.median(np.abs(s.yaw_error[kept]))) if len(kept) else float("nan")
    largest = float(np.max(s.error_m[kept])) if len(kept) else 0.0
    return [
        s.variant,
        f"{n} of {int(s.has_gnss.sum())}",
        f"{100 * good.sum() / n:.1f} %",
        f"{100 * (near & ~localised).sum() / n:.1f} %",
        f"{int(wrong.sum())} (max {largest:.1f} m)",
        str(int((localised & ~near).sum())),
        f"{median:.2f} m / {np.rad2deg(yaw):.1f} deg",
        f"{s.relocalisations} of {s.global_attempts}",
        separation(quality, is_good, higher_is_better=True),
        separation(sigma, is_good, higher_is_better=False),
        f"{s.scans_per_s:.1f}",
    ]


HEADER = [
    "variant",
    "queries near the route (of those with GNSS)",
    "within 5 m of GNSS",
    "lost",
    "more than 10 m off",
    "placed off the route",
    "median error: position / yaw",
    "relocalisations (of attempts)",
    "quality keeping only scans within 5 m",
    "sigma_m keeping only scans within 5 m",
    "scans/s",
]


def variants(sequence: RadarSequence, m: Map, stride: int) -> tuple[list[Variant], NDArray]:
    """The variants of the module docstring and the drive's indices of the queries."""
    picks = np.arange(stride // 2, len(sequence), stride)
    queries = ScanSelection(sequence, picks, sequence.name + "_queries")
    map_scans = np.arange(0, len(sequence), stride)
    gapped = with_gap(m, map_scans, GAP_SCANS)
    first_half = with_gap(m, map_scans, (len(sequence) // 2, len(sequence)))
    return [
        Variant("as driven", queries, m),
        Variant(
            "turned by pi", Turned(sequence, picks, queries.name + "_turned"), m, expected_yaw=np.pi
        ),
        Variant("cold starts", queries, m, restart_every=COLD_START_QUERIES),
        Variant("map with a gap", queries, gapped),
        Variant(
            f"sparse map (1 keyframe in {SPARSE_EVERY})",
            queries,
            keyframe_subset(m, np.arange(len(m)) % SPARSE_EVERY == 0),
            route=m,
        ),
        Variant("map of the first half", queries, first_half),
    ], picks


def run(root: Path, stride: int) -> str:
    """The Markdown text: a head line and the table."""
    sequence, _, offset_s = gnss_positions(root)
    assert sequence.ground_truth is not None
    gnss = np.asarray(sequence.ground_truth, dtype=np.float64)
    config = load_config(sequence.family)
    m = make_map(sequence, stride, config)
    chosen, picks = variants(sequence, m, stride)
    scored = [localize(v, gnss[picks], config) for v in chosen]
    head = (
        f"RADIATE Edinburgh drive ({len(sequence)} scans): map from SLAM on every {stride}th scan "
        f"from 0 ({len(m)} keyframes), queries every {stride}th scan from {stride // 2}, "
        f"localised in order; cold starts every {COLD_START_QUERIES} queries; the gap removes "
        f"the keyframes of scans {GAP_SCANS[0]}-{GAP_SCANS[1] - 1}. GNSS read through a clock "
        f"offset of {offset_s:+.2f} s; queries in GNSS outages left out; positions through the "
        f"map's own GNSS alignment; 'near the route': within {NEAR_ROUTE_M:.0f} m of a map "
        "keyframe (of the full map for the sparse one). The quality and sigma_m columns: the "
        "loosest threshold that keeps only scans within 5 m, and how many it keeps."
    )
    table = markdown_table(HEADER, [row(s) for s in scored])
    return head + "\n\n" + table + "\n\n" + hypothesis_line(scored)


def main(argv: list[str] | None = None) -> int:
    parser = real_data_parser(__doc__.splitlines()[0])
    parser.add_argument("--stride", type=int, default=4, help="map and query scan spacing")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    print(machine_line("scripts/reloc_real.py"), flush=True)
    text = run(args.data_root, args.stride)
    print(f"\n{text}")
    if args.write_doc:
        update_section(DOC_SECTION, text, script="scripts/reloc_real.py")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
