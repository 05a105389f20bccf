"""Odometry CPU cost per scan on one thread, optionally side by side with a baseline source tree.

`Odometry.register` is run over each sequence with one thread (`cv2.setNumThreads(1)`,
`OPENBLAS_NUM_THREADS=1`); the process CPU time (`time.process_time`, robust to other processes
on a shared machine, unlike wall-clock time) of every call after the first two (warm-up) is
summed, frame reading excluded.
Drift and ATE against the ground truth are reported too.

With `--baseline DIR` (a checkout of another commit, e.g. made with
`git worktree add --detach DIR COMMIT`), each sequence is also run with DIR's packages first on
PYTHONPATH, alternating the two in child processes (`--repeat` rounds) so that both see the same
load; the table then shows both costs, their ratio and the largest pose difference between the
two runs (0 when the results are bit-identical).

Usage: python scripts/bench_odometry_cpu.py SEQ [SEQ ...] [--baseline DIR] [--repeat N]
           [--max-frames N] [--data-root DIR]
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

    from odometry.odometry import Odometry
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


def child(spec: str, args: argparse.Namespace, source: Path | None, out: Path) -> dict:
    """Run one sequence in a child process with `source` (a source tree) first on the path."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    if source is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(source), *filter(None, [env.get("PYTHONPATH")])])
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sequences", nargs="+", help="family/sequence specs")
    parser.add_argument("--baseline", type=Path, default=None, help="baseline source tree")
    parser.add_argument("--repeat", type=int, default=1, help="alternating rounds per sequence")
    parser.add_argument("--max-frames", type=int, default=None)
    parser.add_argument("--data-root", type=Path, default=None)
    parser.add_argument("--child-out", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    if args.child_out is not None:
        run_sequence(args.sequences[0], args.data_root, args.max_frames, args.child_out)
        return
    variants: list[tuple[str, Path | None]] = [("this tree", None)]
    if args.baseline is not None:
        variants.insert(0, ("baseline", args.baseline.resolve()))
    lines = [
        "| sequence | variant | scans | CPU ms/scan | wall ms/scan | ATE [m] | drift [%] | gaps "
        "| max pose diff |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    with tempfile.TemporaryDirectory() as tmp:
        for spec in args.sequences:
            runs: dict[str, list[dict]] = {name: [] for name, _ in variants}
            for round_index in range(args.repeat):
                for name, source in variants:
                    out = Path(tmp) / f"{name.replace(' ', '_')}_{round_index}.json"
                    result = child(spec, args, source, out)
                    logger.info(
                        "%s %s round %d: %.2f ms/scan CPU",
                        spec,
                        name,
                        round_index,
                        result["cpu_ms_per_scan"],
                    )
                    runs[name].append(result)
            first = runs[variants[0][0]][0]["poses"]
            for name, _ in variants:
                results = runs[name]
                cpu = min(r["cpu_ms_per_scan"] for r in results)
                wall = min(r["wall_ms_per_scan"] for r in results)
                last = results[-1]
                diff = float(np.max(np.abs(last["poses"] - first))) if len(first) else 0.0
                lines.append(
                    f"| `{spec}` | {name} | {last['frames']} | {cpu:.2f} | {wall:.2f} "
                    f"| {_fmt(last['ate_m'], 4)} | {_fmt(last['drift_pct'], 4)} "
                    f"| {last['gaps']} | {diff:.2e} |"
                )
            if args.baseline is not None:
                base = min(r["cpu_ms_per_scan"] for r in runs["baseline"])
                this = min(r["cpu_ms_per_scan"] for r in runs["this tree"])
                lines.append(f"| `{spec}` | ratio this/baseline | | {this / base:.3f} | | | | | |")
    logger.info("\n%s", "\n".join(lines))


if __name__ == "__main__":
    main()
