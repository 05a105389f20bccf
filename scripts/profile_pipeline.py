"""Profile the SLAM pipeline (cProfile) and print where the time goes by stage.

Runs `radar_slam.pipeline.Pipeline` on a sequence under cProfile, all in the main thread (no
reader or loop thread: cProfile sees one thread; the results are the same), and splits the run by
stage from the cumulative times of the pipeline's own step methods (one home for each stage):

    read/decode       Pipeline._read (the loader: PNG decode, polar array; the scan conditioned
                      for the odometry, `preprocess_polar`)
    odometry          Pipeline._track (Odometry.register of the conditioned scan)
    loop detection    the loop runner's _step + finish, minus verification
      of which query  PlaceRecognizer.query (RaPlace retrieval over the database)
      of which descr. the RaPlace descriptor of each database scan
    verification      GeometricVerifier.__call__ (sinogram pose + phase correlation), with the
                      re-reading of database scans it needs
    graph             Pipeline._extend_graph + _close_loops (GTSAM ISAM2)
    final             Pipeline._optimise (final GNC/LM pass) + _evaluate (metrics)

then the functions with the largest own time. Profiling slows Python-heavy code more than numpy
code, so shares are indicative; wall-clock figures come from scripts/bench_pipeline.py.

Usage: python scripts/profile_pipeline.py [SEQ ...] [--max-frames N] [--top N] [--stats FILE]
"""

from __future__ import annotations

import argparse
import cProfile
import dataclasses
import os
import pstats
import time
from pathlib import Path

from radar_slam.datasets import open_sequence
from radar_slam.pipeline import Pipeline, load_config

DEFAULT_SEQUENCES = ("synthetic/tiny_loop", "synthetic/loop")
STAGES: dict[str, tuple[tuple[str, str], ...]] = {
    "read/decode": (("slam.py", "_read"),),
    "odometry": (("slam.py", "_track"),),
    "loop detection": (("concurrency.py", "_step"), ("concurrency.py", "finish")),
    "verification": (("verification.py", "__call__"),),
    "graph": (("slam.py", "_extend_graph"), ("slam.py", "_close_loops")),
    "final": (("slam.py", "_optimise"), ("slam.py", "_evaluate")),
}
"""Stage -> (file name, function) whose cumulative times add up to it."""
DETAILS: dict[str, tuple[str, str]] = {
    "  of which RaPlace query": ("retrieval.py", "query"),
    "  of which RaPlace descriptor": ("descriptor.py", "descriptor"),
}


def cumulative(stats: pstats.Stats, file_name: str, function: str) -> float:
    """Cumulative seconds of every function `function` defined in a file called `file_name`."""
    total = 0.0
    for (path, _, name), row in stats.stats.items():  # type: ignore[attr-defined]
        if name == function and Path(path).name == file_name:
            total += row[3]
    return total


def calls(stats: pstats.Stats, file_name: str, function: str) -> int:
    """Calls of every function `function` defined in a file called `file_name`."""
    total = 0
    for (path, _, name), row in stats.stats.items():  # type: ignore[attr-defined]
        if name == function and Path(path).name == file_name:
            total += row[1]
    return total


PER_CALL: dict[str, tuple[str, str]] = {
    "verification per candidate": ("verification.py", "__call__"),
    "RaPlace descriptor per database scan": ("descriptor.py", "descriptor"),
    "scan reading per call": ("slam.py", "_reread"),
}
"""Label -> (file name, function) whose time per call is printed."""


def stage_seconds(stats: pstats.Stats) -> dict[str, float]:
    """Seconds per stage; verification is taken out of loop detection (it runs inside it)."""
    seconds = {
        stage: sum(cumulative(stats, f, n) for f, n in parts) for stage, parts in STAGES.items()
    }
    seconds["loop detection"] -= seconds["verification"]
    for label, (file_name, function) in DETAILS.items():
        seconds[label] = cumulative(stats, file_name, function)
    return seconds


def profile(spec: str, max_frames: int | None, top: int, stats_file: Path | None) -> None:
    sequence = open_sequence(spec)
    config = load_config(sequence.family)
    in_main_thread = dataclasses.replace(config.concurrency, loop_thread=False, read_ahead_scans=0)
    config = dataclasses.replace(config, concurrency=in_main_thread)
    pipeline = Pipeline(sequence, config, max_frames=max_frames)
    profiler = cProfile.Profile()
    start = time.perf_counter()
    profiler.enable()
    results = pipeline.run()
    profiler.disable()
    wall = time.perf_counter() - start
    stats = pstats.Stats(profiler)
    if stats_file is not None:
        stats.dump_stats(str(stats_file))
    frames = results.metrics.frames
    m = results.metrics
    print(f"\n{spec}: {frames} scans, {wall:.1f} s under the profiler ({frames / wall:.1f}/s)")
    print(f"loops {m.loops_accepted}, ATE odometry {m.ate_odometry_m}, SLAM {m.ate_slam_m}")
    stages = stage_seconds(stats)
    total = sum(v for k, v in stages.items() if not k.startswith(" "))
    for stage, seconds in stages.items():
        share = 100.0 * seconds / total if total > 0 else 0.0
        per_scan_ms = 1000 * seconds / frames
        print(f"  {stage:<30s} {seconds:7.2f} s {share:5.1f} %  {per_scan_ms:6.1f} ms/scan")
    print(f"  {'(sum of stages)':<30s} {total:7.2f} s")
    for label, (file_name, function) in PER_CALL.items():
        n = calls(stats, file_name, function)
        ms = 1000 * cumulative(stats, file_name, function) / n if n else 0.0
        print(f"  {label:<38s} {ms:6.1f} ms x {n} calls")
    print(f"\ntop {top} functions by own time:")
    stats.sort_stats("tottime").print_stats(top)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sequences", nargs="*", default=list(DEFAULT_SEQUENCES))
    parser.add_argument("--max-frames", type=int, default=200)
    parser.add_argument("--top", type=int, default=15)
    parser.add_argument("--stats", type=Path, default=None, help="also dump pstats here")
    args = parser.parse_args()
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    for spec in args.sequences:
        profile(spec, args.max_frames, args.top, args.stats)


if __name__ == "__main__":
    main()
