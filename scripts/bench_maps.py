"""Benchmark maps: localisation in a map and multi-session SLAM on simulated session pairs.

For each pair MAP_SEQ:QUERY_SEQ (default `synthetic/multisession_a:synthetic/multisession_b`
and the reverse-direction pair `synthetic/multisession_reverse_a:..._b`):

1. SLAM on MAP_SEQ, its map built, saved, loaded (the round trip is checked byte for byte);
2. QUERY_SEQ localised in the loaded map, one scan at a time (`Localizer.localize`): of the scans
   within 10 m of the map's route, the fraction localised within 1 m and 2 deg of GT (through
   the map's own GT alignment), scans localised more than 5 m off, lateral / longitudinal RMS;
   speed as scans/s of wall clock and of process CPU time (reading the scans excluded), on one
   core (OPENBLAS_NUM_THREADS=1), so a busy machine does not hide the cost;
3. SLAM on QUERY_SEQ joined to the map (`join_session`, as `radar-slam run QUERY --map MAP`):
   ATE of its trajectory in the map frame against GT through the map's alignment only (no
   re-alignment), over the scans within 10 m of the map's route and over all (streets the map
   does not hold drift as odometry does), inter-session loops accepted / true, and the extended
   map's round trip.

`--write-doc` writes the bars as a table into docs/benchmarks.md.

Usage: python scripts/bench_maps.py [MAP_SEQ:QUERY_SEQ ...] [--data-root DIR] [--json OUT]
       [--write-doc]
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import tempfile
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from radar_slam.datasets import open_sequence
from radar_slam.maps import Map, build_map
from radar_slam.maps.evaluate import evaluate_localization, near_map_route
from radar_slam.maps.format import encode_map, map_bytes
from radar_slam.maps.localizer import Localizer
from radar_slam.maps.session import InterSessionQueries, ate_in_map_frame, join_session
from radar_slam.maps.session import summary as joined_summary
from radar_slam.pipeline import Pipeline, load_config

logger = logging.getLogger("bench_maps")

DEFAULT_PAIRS = (
    "synthetic/multisession_a:synthetic/multisession_b",
    "synthetic/multisession_reverse_a:synthetic/multisession_reverse_b",
)


def round_trip(m: Map, folder: Path) -> tuple[Map, bool, int]:
    """Save, load, save again: (loaded map, byte-identical?, bytes on disk)."""
    first, second = folder / "first", folder / "second"
    m.save(first)
    loaded = Map.load(first)
    loaded.save(second)
    same = all(
        (first / f.name).read_bytes() == (second / f.name).read_bytes() for f in first.iterdir()
    )
    return loaded, same and encode_map(loaded) == encode_map(m), map_bytes(first)


def bench_pair(pair: str, data_root: Path | None) -> dict[str, Any]:
    map_spec, query_spec = pair.split(":")
    map_seq, query_seq = open_sequence(map_spec, data_root), open_sequence(query_spec, data_root)
    config = load_config(map_seq.family)
    with tempfile.TemporaryDirectory() as tmp:
        map_run = Pipeline(map_seq, config).run()
        m, same, size = round_trip(build_map(map_run, map_seq), Path(tmp) / "a")
        localizer = Localizer(m, config)
        fixes, wall, cpu = [], 0.0, 0.0
        for n in range(len(query_seq)):
            frame = query_seq[n]
            w, c = time.perf_counter(), time.process_time()
            fixes.append(localizer.localize(frame))
            wall += time.perf_counter() - w
            cpu += time.process_time() - c
        metrics = evaluate_localization(fixes, np.asarray(query_seq.ground_truth), m)
        assert metrics is not None
        queries = InterSessionQueries(m, config)
        query_run = Pipeline(query_seq, config, on_keyframe=queries).run()
        joined = join_session(query_run, m, queries)
        poses = joined.results.slam.poses  # in the map frame
        gt = np.asarray(query_seq.ground_truth, dtype=np.float64)[: len(poses)]
        near = near_map_route(gt, m)
        near_ate = ate_in_map_frame(poses[near], gt[near], m)
        _, joined_same, joined_size = round_trip(joined.map, Path(tmp) / "joined")
    return {
        "pair": pair,
        "map_keyframes": len(m),
        "map_bytes": size,
        "map_bytes_per_keyframe": size / len(m),
        "map_ate_slam_m": map_run.metrics.ate_slam_m,
        "round_trip_identical": same and joined_same,
        "localization": metrics.to_dict(),
        "localization_scans_per_s_wall": len(fixes) / wall,
        "localization_scans_per_s_cpu": len(fixes) / cpu,
        "multisession": joined_summary(joined),
        "multisession_ate_map_frame_near_route_m": near_ate,
        "multisession_near_route_scans": int(near.sum()),
        "multisession_ate_session_frame_umeyama_m": query_run.metrics.ate_slam_m,
        "joined_map_bytes": joined_size,
    }


def _m(value: float | None) -> str:
    return "none" if value is None else f"{value:.3f} m"


def report(row: dict[str, Any]) -> str:
    loc, ms = row["localization"], row["multisession"]
    correct = loc["near_route_correct"]
    return "\n".join(
        [
            f"{row['pair']}",
            f"  map           {row['map_keyframes']} keyframes, {row['map_bytes'] / 1e6:.2f} MB "
            f"({row['map_bytes_per_keyframe'] / 1e3:.1f} kB/keyframe), SLAM ATE "
            f"{row['map_ate_slam_m']:.3f} m, round trip identical: {row['round_trip_identical']}",
            f"  localisation  {loc['near_route_scans']} scans within 10 m of the map: "
            f"{100 * correct:.1f} % within 1 m / 2 deg; {loc['wrong_localised']} scans > 5 m off "
            f"(max error {loc['max_error_m']:.2f} m); lateral {loc['lateral_rmse_m']:.3f} m, "
            f"longitudinal {loc['longitudinal_rmse_m']:.3f} m RMS; "
            f"{loc['relocalisations']} relocalisations",
            f"  speed         {row['localization_scans_per_s_wall']:.1f} scans/s wall, "
            f"{row['localization_scans_per_s_cpu']:.1f} scans/s CPU (one core, reading excluded)",
            f"  multi-session met map: {ms['met_map']}, ATE in the map frame (no re-alignment) "
            f"{_m(row['multisession_ate_map_frame_near_route_m'])} over the "
            f"{row['multisession_near_route_scans']} scans within 10 m of the map's route, "
            f"{_m(ms['ate_map_frame_m'])} over all, inter-session loops "
            f"{ms['intersession_accepted_true']} true of {ms['intersession_accepted']} accepted "
            f"({ms['intersession_proposed']} proposed); map {ms['map_sessions']} sessions, "
            f"{ms['map_keyframes']} keyframes",
        ]
    )


DOC_SECTION = "Maps"
"""The section of docs/benchmarks.md this script writes with `--write-doc`."""


def doc_table(rows: list[dict[str, Any]]) -> str:
    """The bars as a Markdown table, one column per session pair."""
    header = ["bar", *(f"`{r['pair'].replace(':', '` -> `')}`" for r in rows)]
    lines = []
    for label, cell in (
        (
            "scans within 10 m of the map's route placed within 1 m and 2 deg of GT (>= 95 %)",
            lambda r: (
                f"{100 * r['localization']['near_route_correct']:.1f} % "
                f"(of {r['localization']['near_route_scans']})"
            ),
        ),
        (
            "scans reported localised more than 5 m off (0)",
            lambda r: (
                f"{r['localization']['wrong_localised']} "
                f"(max error {r['localization']['max_error_m']:.2f} m)"
            ),
        ),
        (
            "lateral / longitudinal RMS error",
            lambda r: (
                f"{r['localization']['lateral_rmse_m']:.3f} / "
                f"{r['localization']['longitudinal_rmse_m']:.3f} m"
            ),
        ),
        (
            "localisation speed, one core (>= 20 scans/s)",
            lambda r: f"{r['localization_scans_per_s_wall']:.1f} scans/s",
        ),
        (
            "`run --map`: ATE in the map frame, not re-aligned, scans within 10 m of the map's "
            "route (<= 1.0 m)",
            lambda r: (
                f"{_m(r['multisession_ate_map_frame_near_route_m'])} "
                f"(of {r['multisession_near_route_scans']})"
            ),
        ),
        (
            "`run --map`: the same, every scan (streets outside the map drift as odometry)",
            lambda r: _m(r["multisession"]["ate_map_frame_m"]),
        ),
        (
            "`run --map`: accepted inter-session loops true",
            lambda r: (
                f"{r['multisession']['intersession_accepted_true']} of "
                f"{r['multisession']['intersession_accepted']}"
            ),
        ),
        (
            "map saved, loaded, saved again byte-identical",
            lambda r: "yes" if r["round_trip_identical"] else "no",
        ),
        (
            "map size",
            lambda r: f"{r['map_keyframes']} keyframes, {r['map_bytes'] / 1e6:.2f} MB",
        ),
    ):
        lines.append([label, *(cell(r) for r in rows)])
    from benchmark_doc import markdown_table

    return markdown_table(header, lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("pairs", nargs="*", default=list(DEFAULT_PAIRS))
    parser.add_argument("--data-root", type=Path, default=None)
    parser.add_argument("--json", type=Path, default=None, help="write the figures as JSON here")
    parser.add_argument("--write-doc", action="store_true", help="write docs/benchmarks.md")
    args = parser.parse_args()
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    cv2.setNumThreads(1)
    logging.basicConfig(level=logging.WARNING)
    rows = []
    for pair in args.pairs:
        rows.append(bench_pair(pair, args.data_root))
        print(report(rows[-1]), flush=True)
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=2) + "\n")
    if args.write_doc:
        from benchmark_doc import update_section

        update_section(DOC_SECTION, doc_table(rows), script="scripts/bench_maps.py")


if __name__ == "__main__":
    main()
