"""Benchmark the whole SLAM pipeline: speed, accuracy, loops, and robustness to false loops.

Runs `radar_slam.pipeline.Pipeline` on a sequence (default `synthetic/loop`, generated on first use
at MulRan resolution: 400 azimuths x 3360 bins) and reports frames/s (wall clock and process CPU
time, so a busy machine does not hide the cost), time per step, ATE of odometry and SLAM (Umeyama
and first-pose aligned), KITTI drift, and loops proposed / accepted / true.

`--workers` chooses the paths run one after the other in the same process (default both):
1 = sequential on one core (pinned; no reader or loop thread), 2 = concurrent on two cores
(scans read ahead, loops closed on a worker thread; `PipelineConfig.concurrency`). Both add the
loops at the same scans, so their accuracy figures must agree; the table at the end puts them
side by side. BLAS and OpenCV run single-threaded in both. The peak RSS is the process's
(`resource.getrusage`) after each run, so it covers the runs before it too: for one run's
memory, run one sequence with one `--workers`.

`--inject-false F` adds the robustness experiment: on a fraction F of the database queries a
random database scan is put first among the candidates; a fake verifier passes it when it lies
more than 50 m from the query (ground truth) with a plausible measurement (a small random offset,
as confident as a good real loop) and ignores it otherwise; real candidates are verified as
usual. The report compares the SLAM ATE with and without the injection.

`--stride K` (repeatable) runs every sequence on every K-th scan too (4 Hz data at 1 Hz with 4);
`--write-doc` writes one table line per sequence and stride (the first of `--workers`) into
docs/benchmarks.md.

`--whole-command` times `radar-slam run` instead, as a user runs it (`whole_command.py`): one
subprocess per sequence, stride and `--workers` (1: pinned to one core with `taskset -c`, 2: on
two cores), default configuration, from its start to its exit (map/ written). It reports the
whole command's scans/s beside the run's own figure (the line the command prints), the time of
the last file written, the subprocess's CPU time and the machine's load average; with
`--write-doc` that table goes into docs/benchmarks.md (section "Whole command").

Usage: python scripts/bench_pipeline.py [SEQ ...] [--workers 1 2] [--max-frames N]
       [--stride K ...] [--inject-false F] [--json OUT] [--write-doc] [--whole-command]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import os
import resource
import sys
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from odometry import Scan
from radar_slam.datasets import open_sequence
from radar_slam.datasets.frame import RadarSequence
from radar_slam.datasets.stride import strided
from radar_slam.evaluation.false_loops import FalseLoopInjection
from radar_slam.loops import GeometricVerifier, LoopDetector
from radar_slam.loops.config import LOOP_RAPLACE
from radar_slam.loops.detector import DescriptorListener
from radar_slam.pipeline import Pipeline, PipelineConfig, Results, load_config
from raplace import PlaceRecognizer

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_raplace import pin_to_one_core  # noqa: E402
from whole_command import WholeCommand, time_run  # noqa: E402
from whole_command import table as whole_command_table  # noqa: E402

logger = logging.getLogger("bench_pipeline")

DEFAULT_SEQUENCES = ("synthetic/loop",)
INJECTION_SEED = 1
WORKER_CHOICES = (1, 2)
COMPARED = (
    ("frames_per_second", "scans/s wall", "{:.1f}"),
    ("frames_per_cpu_second", "scans/s CPU", "{:.1f}"),
    ("seconds", "wall [s]", "{:.1f}"),
    ("cpu_seconds", "CPU [s]", "{:.1f}"),
    ("ate_odometry_m", "ATE odometry [m]", "{:.6f}"),
    ("ate_slam_m", "ATE SLAM [m]", "{:.6f}"),
    ("drift_odometry_pct", "drift odometry [%]", "{:.4f}"),
    ("drift_slam_pct", "drift SLAM [%]", "{:.4f}"),
    ("loops_proposed", "loops proposed", "{}"),
    ("loops_accepted", "loops accepted", "{}"),
    ("loops_accepted_true", "loops true", "{}"),
    ("peak_rss_mb", "peak RSS [MB]", "{:.0f}"),
)
"""(metrics row key, label, format) of the side-by-side table."""
KIB_PER_MB = 1024
"""`ru_maxrss` is in KiB on Linux."""


def with_workers(config: PipelineConfig, workers: int) -> PipelineConfig:
    """The config of the sequential (1) or concurrent (2) path."""
    concurrency = dataclasses.replace(
        config.concurrency,
        loop_thread=workers > 1,
        read_ahead_scans=config.concurrency.read_ahead_scans if workers > 1 else 0,
    )
    return dataclasses.replace(config, concurrency=concurrency)


def use_cores(workers: int, cores: set[int]) -> None:
    """Run on one of `cores` (1 worker) or on `workers` of them."""
    os.sched_setaffinity(0, set(sorted(cores)[:workers]))


def side_by_side(rows: list[dict[str, object]]) -> str:
    """The rows' speed, steps and accuracy as a table, one column per row."""
    names = [str(r["sequence"]) for r in rows]
    lines = [f"{'':<22s}" + "".join(f"{n:>28s}" for n in names)]
    for key, label, fmt in COMPARED:
        cells = [rows_value(r, key, fmt) for r in rows]
        lines.append(f"{label:<22s}" + "".join(f"{c:>28s}" for c in cells))
    steps = sorted({s for r in rows for s in r["timings_s"]})  # type: ignore[attr-defined]
    for step in steps:
        cells = [f"{r['timings_s'].get(step, 0.0):.2f}" for r in rows]  # type: ignore[attr-defined]
        lines.append(f"{step + ' [s]':<22s}" + "".join(f"{c:>28s}" for c in cells))
    return "\n".join(lines)


def rows_value(row: dict[str, object], key: str, fmt: str) -> str:
    value = row.get(key)
    return "n/a" if value is None else fmt.format(value)


def run_once(
    sequence: RadarSequence, config: PipelineConfig, max_frames: int | None, inject: float | None
) -> tuple[Results, float, int]:
    """(results, CPU seconds, injected false loops that passed verification)."""
    factory = None
    injection = None
    if inject is not None:
        gt = sequence.ground_truth
        if gt is None:
            raise SystemExit("--inject-false needs a sequence with ground truth")
        rng = np.random.default_rng(INJECTION_SEED)
        injection = FalseLoopInjection(np.asarray(gt), inject, rng)
        # every candidate verified, however far the odometry puts it: the false loops get through
        cfg = dataclasses.replace(config.loop_closure, odometry_drift_fraction=np.inf)
        recognizer = injection.recognizer(PlaceRecognizer(LOOP_RAPLACE.retrieval))
        verifier = injection.verifier(GeometricVerifier(cfg, config.odometry))

        def factory(
            scans: Callable[[int], Scan], descriptors: DescriptorListener
        ) -> LoopDetector:  # verifies from the run's scan records, as the configured one
            return LoopDetector(
                cfg,
                scan_loader=scans,
                recognizer=recognizer,
                verifier=verifier,
                on_describe=descriptors,
                odometry=config.odometry,
            )

    cpu = time.process_time()
    pipeline = Pipeline(sequence, config, max_frames=max_frames, loop_detector_factory=factory)
    results = pipeline.run()
    cpu = time.process_time() - cpu
    return results, cpu, 0 if injection is None else len(injection.passed)


def report(name: str, results: Results, cpu_s: float) -> dict[str, object]:
    m = results.metrics
    row: dict[str, object] = dict(m.to_dict())
    row["sequence"] = name
    row["cpu_seconds"] = cpu_s
    row["frames_per_cpu_second"] = m.frames / cpu_s if cpu_s > 0 else 0.0
    row["timings_s"] = results.timings_s
    row["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / KIB_PER_MB
    logger.info(
        "%s: %d frames, %.1f frames/s wall, %.1f frames/s CPU; steps %s",
        name,
        m.frames,
        m.frames_per_second,
        row["frames_per_cpu_second"],
        ", ".join(f"{k} {v:.1f} s" for k, v in results.timings_s.items()),
    )
    logger.info(
        "%s: ATE odometry %s m -> SLAM %s m (origin-aligned %s -> %s m); drift %s -> %s %%; "
        "loops proposed %d, accepted %d, true %s",
        name,
        _f(m.ate_odometry_m),
        _f(m.ate_slam_m),
        _f(m.ate_origin_odometry_m),
        _f(m.ate_origin_slam_m),
        _f(m.drift_odometry_pct),
        _f(m.drift_slam_pct),
        m.loops_proposed,
        m.loops_accepted,
        m.loops_accepted_true,
    )
    return row


def _f(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.3f}"


DOC_SECTION = "SLAM on the synthetic drives"
"""The section of docs/benchmarks.md this script writes with `--write-doc`."""
WHOLE_COMMAND_SECTION = "Whole command"
"""... and with `--whole-command --write-doc`."""
DOC_HEADER = (
    "| sequence | stride | cores | scans/s | odometry ATE [m] | SLAM ATE [m] | ratio "
    "| loops accepted / true |\n|---|---|---|---|---|---|---|---|"
)


def doc_line(spec: str, stride: int, workers: int, results: Results) -> str:
    """One line of the docs table."""
    m = results.metrics
    odometry, slam = m.ate_odometry_m, m.ate_slam_m
    ratio = "n/a" if not odometry or slam is None else f"{slam / odometry:.2f}"
    return (
        f"| `{spec}` | {stride} | {workers} | {m.frames_per_second:.1f} | {_f(odometry)} "
        f"| {_f(slam)} | {ratio} | {m.loops_accepted} / {m.loops_accepted_true} |"
    )


def whole_command_rows(args: argparse.Namespace, cores: set[int]) -> list[WholeCommand]:
    """`radar-slam run` timed as a subprocess per sequence, stride and worker count."""
    shared: list[str] = []
    if args.data_root is not None:
        shared += ["--data-root", str(args.data_root.resolve())]
    if args.config is not None:
        shared += ["--config", str(args.config.resolve())]
    if args.max_frames is not None:
        shared += ["--max-frames", str(args.max_frames)]
    rows = []
    for spec, stride in [(s, k) for s in args.sequences for k in args.stride or [1]]:
        name = spec if stride == 1 else f"{spec} --stride {stride}"
        target = str(Path(spec).resolve()) if Path(spec).exists() else spec  # a folder or bag
        for workers in args.workers:
            row = time_run(
                target, sorted(cores)[:workers], [*shared, "--stride", str(stride)], label=name
            )
            logger.info(
                "%s on %d core(s): %d scans, whole command %.1f s = %.1f scans/s (last file at "
                "%.1f s, CPU %.1f s, peak RSS %.0f MiB), in run %.1f scans/s; SLAM ATE %s m; "
                "load %.1f -> %.1f",
                name,
                workers,
                row.scans,
                row.wall_s,
                row.scans_per_s,
                row.last_file_s,
                row.cpu_s,
                row.peak_rss_mib,
                row.run_scans_per_s,
                _f(row.ate_slam_m),
                row.load_before,
                row.load_after,
            )
            rows.append(row)
    return rows


def injected_row(
    spec: str,
    sequence: RadarSequence,
    config: PipelineConfig,
    args: argparse.Namespace,
    results: Results,
) -> dict[str, object]:
    """The robustness experiment (`--inject-false F`) on `sequence`: its report row, with the
    injected false loops verified and accepted and the SLAM ATE's rise over `results`'."""
    injected, cpu, passed = run_once(sequence, config, args.max_frames, args.inject_false)
    row = report(f"{spec} + {args.inject_false:.0%} false", injected, cpu)
    accepted_false = sum(
        1
        for d, t in zip(injected.loops, injected.true_loops, strict=True)
        if d.accepted and t is False
    )
    base, slam = results.metrics.ate_slam_m, injected.metrics.ate_slam_m
    rise = None if not base or slam is None else slam / base - 1.0
    row.update(
        injected_false_verified=passed,
        injected_false_accepted=accepted_false,
        ate_slam_rise=rise,
    )
    logger.info(
        "%s: %d injected false loops passed the fake verifier, %d accepted; "
        "SLAM ATE %s -> %s m (%s)",
        spec,
        passed,
        accepted_false,
        _f(base),
        _f(slam),
        "n/a" if rise is None else f"{100 * rise:+.1f} %",
    )
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sequences", nargs="*", default=list(DEFAULT_SEQUENCES))
    parser.add_argument(
        "--workers",
        type=int,
        nargs="+",
        choices=WORKER_CHOICES,
        default=list(WORKER_CHOICES),
        help="1: sequential on one core; 2: concurrent on two (default: both, side by side)",
    )
    parser.add_argument("--max-frames", type=int, default=None)
    parser.add_argument("--config", type=Path, default=None, help="YAML overrides")
    parser.add_argument("--data-root", type=Path, default=None)
    parser.add_argument(
        "--inject-false", type=float, default=None, help="fraction of queries given a false loop"
    )
    parser.add_argument("--json", type=Path, default=None, help="write the rows as JSON")
    parser.add_argument(
        "--stride", type=int, action="append", default=[], help="every K-th scan; repeatable"
    )
    parser.add_argument("--write-doc", action="store_true", help="write docs/benchmarks.md")
    parser.add_argument(
        "--whole-command",
        action="store_true",
        help="time `radar-slam run` as a subprocess (whole command beside in-run scans/s)",
    )
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    logging.getLogger("odometry").setLevel(logging.ERROR)
    cores = os.sched_getaffinity(0)
    if args.whole_command:
        timed = whole_command_rows(args, cores)
        table = whole_command_table(timed)
        logger.info("%s", table)
        if args.json is not None:
            args.json.write_text(json.dumps([r.to_dict() for r in timed], indent=2) + "\n")
        if args.write_doc:
            from benchmark_doc import update_section

            update_section(WHOLE_COMMAND_SECTION, table, script="scripts/bench_pipeline.py")
        return
    pin_to_one_core()  # re-executes with single-threaded BLAS the first time
    cv2.setNumThreads(1)
    if len(cores) < max(args.workers):
        logger.warning("only %d core(s) available: the 2-worker run shares them", len(cores))
    rows = []
    doc_lines = []
    for spec, stride in [(s, k) for s in args.sequences for k in args.stride or [1]]:
        sequence = strided(open_sequence(spec, args.data_root), stride)
        base_config = load_config(sequence.family, args.config)
        name = spec if stride == 1 else f"{spec} --stride {stride}"
        paired = []
        for workers in args.workers:
            use_cores(workers, cores)
            config = with_workers(base_config, workers)
            results, cpu = run_once(sequence, config, args.max_frames, None)[:2]
            paired.append(report(f"{name} ({workers} core{'s' * (workers > 1)})", results, cpu))
            if workers == args.workers[0]:
                doc_lines.append(doc_line(spec, stride, workers, results))
        rows += paired
        logger.info("%s\n%s", name, side_by_side(paired))
        if args.inject_false is not None:
            rows.append(injected_row(spec, sequence, config, args, results))
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=2, default=float) + "\n")
    if args.write_doc:
        from benchmark_doc import update_section

        table = "\n".join([DOC_HEADER, *doc_lines])
        update_section(DOC_SECTION, table, script="scripts/bench_pipeline.py")


if __name__ == "__main__":
    main()
