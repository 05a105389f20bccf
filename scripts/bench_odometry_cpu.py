"""Odometry CPU cost per scan on one thread.

`Odometry.register` is run over each sequence with one thread (`cv2.setNumThreads(1)`,
`OPENBLAS_NUM_THREADS=1`); the process CPU time (`time.process_time`, robust to other processes
on a shared machine, unlike wall-clock time) of every call after the first two (warm-up) is
summed, frame reading excluded.
Drift and ATE against the ground truth are reported too.

Each sequence runs in a child process (`--repeat` rounds; the table keeps the lowest cost of
the rounds). `--write-doc` writes the table into docs/benchmarks.md.

Usage: python scripts/bench_odometry_cpu.py SEQ [SEQ ...] [--repeat N] [--max-frames N]
           [--data-root DIR] [--write-doc]
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

logger = logging.getLogger("bench_odometry_cpu")

WARM_UP_FRAMES = 2
"""Frames left out of the per-scan cost: the first registrations load compiled kernels."""


def run_sequence(spec: str, data_root: Path | None, max_frames: int | None, out: Path) -> None:
    """Run the odometry over one sequence in this process; write poses and costs to `out`."""
    import cv2

    from odometry import Odometry
    from radar_slam.datasets import open_sequence
    from radar_slam.evaluation.metrics import evaluate
    from radar_slam.trajectory import Trajectory

    cv2.setNumThreads(1)
    sequence = open_sequence(spec, data_root=data_root)
    n = len(sequence) if max_frames is None else min(len(sequence), max_frames)
    odometry = Odometry()
    cpu_s = 0.0
    wall_s = 0.0
    for k in range(n):
        frame = sequence[k]
        cpu0, wall0 = time.process_time(), time.perf_counter()
        odometry.register(frame)
        if k >= WARM_UP_FRAMES:
            cpu_s += time.process_time() - cpu0
            wall_s += time.perf_counter() - wall0
    timed = max(1, n - WARM_UP_FRAMES)
    poses = odometry.poses
    result = {
        "frames": n,
        "cpu_ms_per_scan": 1e3 * cpu_s / timed,
        "wall_ms_per_scan": 1e3 * wall_s / timed,
        "gaps": len(odometry.gaps),
        "ate_m": None,
        "drift_pct": None,
    }
    gt_poses = sequence.ground_truth
    if gt_poses is not None:
        stamps = sequence.timestamps_ns[:n]
        truth = Trajectory.from_arrays(stamps, gt_poses[:n], drop_nonfinite=True)
        metrics = evaluate(Trajectory(stamps, poses), truth)
        result["ate_m"] = metrics.ate_rmse_m
        result["drift_pct"] = metrics.drift_trans_pct
    np.save(out.with_suffix(".npy"), poses)
    out.write_text(json.dumps(result))


def child(spec: str, args: argparse.Namespace, out: Path) -> dict:
    """Run one sequence in a child process on one thread."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    command = [sys.executable, __file__, spec, "--child-out", str(out)]
    if args.max_frames is not None:
        command += ["--max-frames", str(args.max_frames)]
    if args.data_root is not None:
        command += ["--data-root", str(args.data_root)]
    subprocess.run(command, env=env, check=True)
    result: dict = json.loads(out.read_text())
    result["poses"] = np.load(out.with_suffix(".npy"))
    return result


def _fmt(value: float | None, digits: int) -> str:
    return "n/a" if value is None else f"{value:.{digits}f}"


DOC_SECTION = "Odometry CPU per scan"
"""The section of docs/benchmarks.md this script writes with `--write-doc`."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sequences", nargs="+", help="family/sequence specs")
    parser.add_argument("--repeat", type=int, default=1, help="rounds per sequence (lowest kept)")
    parser.add_argument("--max-frames", type=int, default=None)
    parser.add_argument("--data-root", type=Path, default=None)
    parser.add_argument("--write-doc", action="store_true", help="write docs/benchmarks.md")
    parser.add_argument("--child-out", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    if args.child_out is not None:
        run_sequence(args.sequences[0], args.data_root, args.max_frames, args.child_out)
        return
    lines = [
        "| sequence | scans | CPU ms/scan | wall ms/scan | ATE [m] | drift [%] | gaps |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    with tempfile.TemporaryDirectory() as tmp:
        for spec in args.sequences:
            results = []
            for round_index in range(args.repeat):
                out = Path(tmp) / f"run_{round_index}.json"
                result = child(spec, args, out)
                logger.info(
                    "%s round %d: %.2f ms/scan CPU", spec, round_index, result["cpu_ms_per_scan"]
                )
                results.append(result)
            cpu = min(r["cpu_ms_per_scan"] for r in results)
            wall = min(r["wall_ms_per_scan"] for r in results)
            last = results[-1]
            lines.append(
                f"| `{spec}` | {last['frames']} | {cpu:.2f} | {wall:.2f} "
                f"| {_fmt(last['ate_m'], 4)} | {_fmt(last['drift_pct'], 4)} | {last['gaps']} |"
            )
    table = "\n".join(lines)
    logger.info("\n%s", table)
    if args.write_doc:
        from benchmark_doc import update_section

        update_section(DOC_SECTION, table, script="scripts/bench_odometry_cpu.py")


if __name__ == "__main__":
    main()
