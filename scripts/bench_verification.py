"""Benchmark loop detection on one CPU core: per-candidate verification and the rest (not a test).

Feeds every scan of a sequence (default `synthetic/loop`) with its ground-truth pose to a
`radar_slam.loops.LoopDetector` (the pipeline's loop-closing config of the sequence's family; no
odometry, no graph) and measures in process CPU time, so a busy machine does not hide the cost:
- the verification of each proposed candidate (`GeometricVerifier`), mean / median / min;
- the rest of loop detection per scan (descriptor, place query, bookkeeping), without reading;
- scan reading (the loader's decoding) per scan, for reference.

`--json OUT` writes every verification (keys, decision, reason, measurement, qualities).

`--odometry` also runs the odometry on the scans (timed apart) and hands each scan's conditioned
form to the detector with the scan (`LoopDetector.add`), as the pipeline does, so the detector
does not condition it again.

`--profile N` runs the verifications under cProfile and prints the N functions with the most
cumulative time per candidate (the profiler's overhead inflates the totals).

Usage: python scripts/bench_verification.py [SEQ] [--max-frames N] [--json OUT]
       [--odometry] [--profile N]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import pstats
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from odometry import Odometry
from radar_slam.datasets import open_sequence
from radar_slam.loops import GeometricVerifier, LoopDetector
from radar_slam.loops.records import KeyScan, Verification
from radar_slam.pipeline import load_config

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_raplace import pin_to_one_core  # noqa: E402

DEFAULT_SEQUENCE = "synthetic/loop"


class TimedVerifier:
    """A `GeometricVerifier` whose calls are timed (CPU) and recorded."""

    def __init__(self, verifier: GeometricVerifier, profiler: cProfile.Profile | None) -> None:
        self.verifier = verifier
        self.profiler = profiler
        self.cpu_s: list[float] = []
        self.records: list[dict[str, Any]] = []

    def __call__(self, query: KeyScan, match: KeyScan) -> Verification:
        if self.profiler is not None:
            self.profiler.enable()
        start = time.process_time()
        result = self.verifier(query, match)
        self.cpu_s.append(time.process_time() - start)
        if self.profiler is not None:
            self.profiler.disable()
        self.records.append(
            {
                "query": int(query.key),
                "match": int(match.key),
                "ok": bool(result.ok),
                "reason": result.reason,
                "measurement": [float(v) for v in result.measurement],
                "sinogram": [float(v) for v in result.sinogram],
                "sinogram_quality": float(result.sinogram_quality),
                "refined_quality": float(result.refined_quality),
            }
        )
        return result


def print_profile(profiler: cProfile.Profile, candidates: int, rows: int) -> None:
    """The `rows` functions with the most cumulative verification time, in ms per candidate."""
    stats = pstats.Stats(profiler, stream=io.StringIO())
    table = stats.stats  # type: ignore[attr-defined]
    entries = sorted(
        ((cumulative, own, calls, func) for func, (_, calls, own, cumulative, _) in table.items()),
        reverse=True,
    )
    print(f"  profile (ms per candidate, cumulative / own, calls per candidate), top {rows}:")
    for cumulative, own, calls, (path, line, name) in entries[:rows]:
        where = f"{Path(path).name}:{line}({name})" if line else name
        print(
            f"    {1e3 * cumulative / candidates:7.2f} {1e3 * own / candidates:7.2f} "
            f"{calls / candidates:7.1f}  {where}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sequence", nargs="?", default=DEFAULT_SEQUENCE)
    parser.add_argument("--max-frames", type=int, default=None)
    parser.add_argument("--json", type=Path, default=None, help="write the verifications here")
    parser.add_argument("--odometry", action="store_true", help="hand over conditioned scans")
    parser.add_argument("--profile", type=int, default=0, help="print this many profile rows")
    args = parser.parse_args()
    core = pin_to_one_core()
    sequence = open_sequence(args.sequence)
    gt = sequence.ground_truth
    if gt is None:
        raise SystemExit(f"{args.sequence} has no ground truth (its poses drive the detector)")
    n = len(sequence) if args.max_frames is None else min(args.max_frames, len(sequence))
    config = load_config(sequence.family)
    cfg = config.loop_closure
    profiler = cProfile.Profile() if args.profile > 0 else None
    verifier = TimedVerifier(GeometricVerifier(cfg, config.odometry), profiler)
    detector = LoopDetector(
        cfg, scan_loader=lambda k: sequence[k], verifier=verifier, odometry=config.odometry
    )

    odometry = Odometry(config.odometry) if args.odometry else None
    read_s = detect_s = odometry_s = 0.0
    for index in range(n):
        start = time.process_time()
        scan = sequence[index]
        read_s += time.process_time() - start
        polar = None
        if odometry is not None:
            start = time.process_time()
            odometry.register(scan)
            odometry_s += time.process_time() - start
            prepared = odometry.prepared
            assert prepared is not None
            polar = prepared.polar
        start = time.process_time()
        detector.add(scan, gt[index], index, polar)
        detect_s += time.process_time() - start
    start = time.process_time()
    detector.finish()
    detect_s += time.process_time() - start

    ms = 1e3 * np.array(verifier.cpu_s)
    verify_s = float(ms.sum()) / 1e3
    accepted, rejected = detector.tally()
    print(f"loop detection on CPU core {core}: {args.sequence}, {n} scans (ground-truth poses)")
    print(f"  scan reading               {read_s:6.2f} s CPU  {1e3 * read_s / n:6.2f} ms/scan")
    if odometry is not None:
        print(
            f"  odometry                   {odometry_s:6.2f} s CPU  "
            f"{1e3 * odometry_s / n:6.2f} ms/scan (its conditioned scans handed to the detector)"
        )
    print(
        f"  detection w/o verification {detect_s - verify_s:6.2f} s CPU  "
        f"{1e3 * (detect_s - verify_s) / n:6.2f} ms/scan ({len(detector)} database scans)"
    )
    if len(ms):
        print(
            f"  verification               {verify_s:6.2f} s CPU  {len(ms)} candidates: "
            f"{ms.mean():.1f} ms mean, {np.median(ms):.1f} median, {ms.min():.1f} min"
        )
    print(f"  decisions: {accepted} accepted, {rejected} rejected, {detector.proposed} proposed")
    if profiler is not None and len(ms):
        print_profile(profiler, len(ms), args.profile)
    if args.json is not None:
        args.json.write_text(json.dumps(verifier.records))


if __name__ == "__main__":
    main()
