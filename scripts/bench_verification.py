"""Benchmark loop detection on one CPU core: per-candidate verification and the rest (not a test).

Feeds every scan of a sequence (default `synthetic/loop`) with its ground-truth pose to a
`radar_slam.loops.LoopDetector` (the pipeline's loop-closing config of the sequence's family; no
odometry, no graph) and measures in process CPU time, so a busy machine does not hide the cost:
- the verification of each proposed candidate (`GeometricVerifier`), mean / median / min;
- the rest of loop detection per scan (descriptor, place query, bookkeeping), without reading;
- scan reading (the loader's decoding) per scan, for reference.

`--json OUT` writes every verification (keys, decision, reason, measurement, qualities); with
`--compare OTHER.json` (from another checkout, same sequence) the decisions and the largest
measurement differences are printed, so a faster verifier can be shown to decide the same.

Usage: python scripts/bench_verification.py [SEQ] [--max-frames N] [--json OUT] [--compare FILE]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from radar_slam.datasets import open_sequence
from radar_slam.loops import GeometricVerifier, LoopDetector
from radar_slam.loops.records import KeyScan, Verification
from radar_slam.pipeline import load_config

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_raplace import pin_to_one_core  # noqa: E402

DEFAULT_SEQUENCE = "synthetic/loop"


class TimedVerifier:
    """A `GeometricVerifier` whose calls are timed (CPU) and recorded."""

    def __init__(self, verifier: GeometricVerifier) -> None:
        self.verifier = verifier
        self.cpu_s: list[float] = []
        self.records: list[dict[str, Any]] = []

    def __call__(self, query: KeyScan, match: KeyScan) -> Verification:
        start = time.process_time()
        result = self.verifier(query, match)
        self.cpu_s.append(time.process_time() - start)
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


def compare(ours: list[dict[str, Any]], theirs: list[dict[str, Any]]) -> None:
    """Print how two runs' verifications differ (decisions, reasons, measurements)."""
    pairs = {(r["query"], r["match"]): r for r in theirs}
    common = [
        (r, pairs[(r["query"], r["match"])]) for r in ours if (r["query"], r["match"]) in pairs
    ]
    print(
        f"compared {len(common)} common candidates (ours {len(ours)}, other {len(theirs)}); "
        f"accepted ours {sum(r['ok'] for r in ours)}, other {sum(r['ok'] for r in theirs)}"
    )
    flips = [(a, b) for a, b in common if a["ok"] != b["ok"]]
    print(f"  decisions differing: {len(flips)}")
    for a, b in flips:
        print(
            f"    {a['query']} -> {a['match']}: ours {a['reason'] or 'ok'!r}, "
            f"other {b['reason'] or 'ok'!r}"
        )
    for field in ("measurement", "sinogram"):
        diffs = np.array(
            [
                np.subtract(a[field], b[field])
                for a, b in common
                if np.all(np.isfinite(a[field])) and np.all(np.isfinite(b[field]))
            ]
        ).reshape(-1, 3)
        if len(diffs):
            xy = np.hypot(diffs[:, 0], diffs[:, 1])
            yaw = np.rad2deg(np.abs(np.angle(np.exp(1j * diffs[:, 2]))))
            print(
                f"  {field:<11s} max |dxy| {xy.max():.2e} m (median {np.median(xy):.1e}), "
                f"max |dyaw| {yaw.max():.2e} deg over {len(diffs)}"
            )
    for field in ("sinogram_quality", "refined_quality"):
        d = np.array([abs(a[field] - b[field]) for a, b in common])
        if len(d):
            print(f"  {field:<17s} max |diff| {d.max():.2e}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sequence", nargs="?", default=DEFAULT_SEQUENCE)
    parser.add_argument("--max-frames", type=int, default=None)
    parser.add_argument("--json", type=Path, default=None, help="write the verifications here")
    parser.add_argument("--compare", type=Path, default=None, help="verifications of another run")
    args = parser.parse_args()
    core = pin_to_one_core()
    sequence = open_sequence(args.sequence)
    gt = sequence.ground_truth
    if gt is None:
        raise SystemExit(f"{args.sequence} has no ground truth (its poses drive the detector)")
    n = len(sequence) if args.max_frames is None else min(args.max_frames, len(sequence))
    cfg = load_config(sequence.family).loop_closure
    verifier = TimedVerifier(GeometricVerifier(cfg))
    detector = LoopDetector(cfg, scan_loader=lambda k: sequence[k], verifier=verifier)

    read_s = detect_s = 0.0
    for index in range(n):
        start = time.process_time()
        scan = sequence[index]
        read_s += time.process_time() - start
        start = time.process_time()
        detector.add(scan, gt[index], index)
        detect_s += time.process_time() - start
    start = time.process_time()
    detector.finish()
    detect_s += time.process_time() - start

    ms = 1e3 * np.array(verifier.cpu_s)
    verify_s = float(ms.sum()) / 1e3
    accepted, rejected = detector.tally()
    print(f"loop detection on CPU core {core}: {args.sequence}, {n} scans (ground-truth poses)")
    print(f"  scan reading               {read_s:6.2f} s CPU  {1e3 * read_s / n:6.2f} ms/scan")
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
    if args.json is not None:
        args.json.write_text(json.dumps(verifier.records))
    if args.compare is not None:
        compare(verifier.records, json.loads(args.compare.read_text()))


if __name__ == "__main__":
    main()
