"""Benchmark the whole SLAM pipeline: speed, accuracy, loops, and robustness to false loops.

Runs `radar_slam.pipeline.Pipeline` on a sequence (default `synthetic/loop`, generated on first use
at MulRan resolution: 400 azimuths x 3360 bins) on one core, and reports frames/s (wall clock and
process CPU time, so a busy machine does not hide the cost), time per step, ATE of odometry and
SLAM (Umeyama and first-pose aligned), KITTI drift, and loops proposed / accepted / true.

`--inject-false F` adds the robustness experiment: on a fraction F of the database queries a
random database scan is put first among the candidates; a fake verifier passes it when it lies
more than 50 m from the query (ground truth) with a plausible measurement (a small random offset,
as confident as a good real loop) and ignores it otherwise; real candidates are verified as
usual. The report compares the SLAM ATE with and without the injection.

Usage: python scripts/bench_pipeline.py [SEQ ...] [--max-frames N] [--inject-false F] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import time
from pathlib import Path

import cv2
import numpy as np

from radar_slam.datasets import open_sequence
from radar_slam.datasets.frame import RadarSequence
from radar_slam.evaluation.false_loops import FalseLoopInjection
from radar_slam.loops import GeometricVerifier, LoopDetector
from radar_slam.pipeline import Pipeline, PipelineConfig, Results, load_config
from raplace.retrieval import PlaceRecognizer

logger = logging.getLogger("bench_pipeline")

DEFAULT_SEQUENCES = ("synthetic/loop",)
INJECTION_SEED = 1


def run_once(
    sequence: RadarSequence, config: PipelineConfig, max_frames: int | None, inject: float | None
) -> tuple[Results, float, int]:
    """(results, CPU seconds, injected false loops that passed verification)."""
    detector = None
    injection = None
    if inject is not None:
        gt = sequence.ground_truth
        if gt is None:
            raise SystemExit("--inject-false needs a sequence with ground truth")
        rng = np.random.default_rng(INJECTION_SEED)
        injection = FalseLoopInjection(np.asarray(gt), inject, rng)
        cfg = config.loop_closure
        recognizer = injection.recognizer(PlaceRecognizer(cfg.raplace.retrieval))
        verifier = injection.verifier(GeometricVerifier(cfg))
        detector = LoopDetector(
            cfg, scan_loader=lambda k: sequence[k], recognizer=recognizer, verifier=verifier
        )
    cpu = time.process_time()
    results = Pipeline(sequence, config, max_frames=max_frames, loop_detector=detector).run()
    cpu = time.process_time() - cpu
    return results, cpu, 0 if injection is None else len(injection.passed)


def report(name: str, results: Results, cpu_s: float) -> dict[str, object]:
    m = results.metrics
    row: dict[str, object] = dict(m.to_dict())
    row["sequence"] = name
    row["cpu_seconds"] = cpu_s
    row["frames_per_cpu_second"] = m.frames / cpu_s if cpu_s > 0 else 0.0
    row["timings_s"] = results.timings_s
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sequences", nargs="*", default=list(DEFAULT_SEQUENCES))
    parser.add_argument("--max-frames", type=int, default=None)
    parser.add_argument("--config", type=Path, default=None, help="YAML overrides")
    parser.add_argument("--data-root", type=Path, default=None)
    parser.add_argument(
        "--inject-false", type=float, default=None, help="fraction of queries given a false loop"
    )
    parser.add_argument("--json", type=Path, default=None, help="write the rows as JSON")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    logging.getLogger("odometry").setLevel(logging.ERROR)
    cv2.setNumThreads(1)
    if os.environ.get("OPENBLAS_NUM_THREADS") != "1":
        logger.warning("set OPENBLAS_NUM_THREADS=1 for one-core timings")
    rows = []
    for spec in args.sequences:
        sequence = open_sequence(spec, args.data_root)
        config = load_config(sequence.family, args.config)
        results, cpu = run_once(sequence, config, args.max_frames, None)[:2]
        rows.append(report(spec, results, cpu))
        if args.inject_false is not None:
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
            rows.append(row)
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=2, default=float) + "\n")


if __name__ == "__main__":
    main()
