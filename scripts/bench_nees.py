"""Consistency of the pose graph's factors: mean NEES of the odometry and loop factors.

Runs the SLAM pipeline (`radar_slam.pipeline.Pipeline`, the same as `radar-slam run`) on each
sequence at each stride and compares, factor by factor, what the graph was given with the ground
truth (`radar_slam.evaluation.nees`): the odometry factors (the results of `Odometry.register`
revised once the next scan registered, as the pipeline adds them; gaps counted apart) and the
accepted loop factors. Prints per factor type the mean NEES (3 when calibrated), its median
(2.37), the share above the 99 % quantile (11.34) and the per-axis normalised squared errors (1
when calibrated), split by driving: odometry factors on straight and turning steps (true yaw
rate above `--turn-dps`), loops with the two scans facing the same or opposite ways. Also the
SLAM ATE and the loops accepted / true of the run, so one run shows both.

Usage: python scripts/bench_nees.py [SEQ ...] [--data-root ROOT] [--stride 1 4]
       [--config FILE.yaml] [--set section.key=value ...] [--loop-covariance key=value ...]
       [--json OUT]

`--loop-covariance` replaces terms of the loop covariance model, a constant of the method
(`radar_slam.loops.verification.LOOP_COVARIANCE`, e.g. `sigma_scale=0.5`), for calibrating it.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from radar_slam.datasets import open_sequence
from radar_slam.datasets.stride import strided
from radar_slam.evaluation.nees import FactorNees, factor_nees
from radar_slam.loops import verification
from radar_slam.loops.config import CHI2_3DOF_99
from radar_slam.pipeline import Pipeline, Results, load_config
from radar_slam.pipeline.steps import odometry_factor
from raplace import NS_PER_S, between, wrap_angle

logger = logging.getLogger("bench_nees")

DEFAULT_SEQUENCES = ("synthetic/loop", "synthetic/reverse")


@dataclass(frozen=True)
class Group:
    """NEES summary of one group of factors."""

    label: str
    count: int
    mean: float
    median: float
    above_99: float
    axes: tuple[float, float, float]

    def row(self) -> str:
        if self.count == 0:
            return f"  {self.label:<22} {0:>5}"
        x, y, yaw = self.axes
        return (
            f"  {self.label:<22} {self.count:>5} {self.mean:>8.2f} {self.median:>7.2f} "
            f"{100 * self.above_99:>6.1f} {x:>7.2f} {y:>7.2f} {yaw:>7.2f}"
        )


def summarise(label: str, items: list[FactorNees]) -> Group:
    """Mean / median NEES, share above the 99 % quantile and per-axis means of `items`."""
    if not items:
        return Group(label, 0, float("nan"), float("nan"), float("nan"), (np.nan,) * 3)
    nees = np.array([f.nees for f in items])
    axes = np.mean([f.axes for f in items], axis=0)
    return Group(
        label,
        len(items),
        float(nees.mean()),
        float(np.median(nees)),
        float(np.mean(nees > CHI2_3DOF_99)),
        (float(axes[0]), float(axes[1]), float(axes[2])),
    )


def odometry_groups(results: Results, truth: NDArray[np.float64], turn_dps: float) -> list[Group]:
    """The odometry factors (revised, as added to the graph): all, straight, turning."""
    straight: list[FactorNees] = []
    turning: list[FactorNees] = []
    stamps = np.array([r.timestamp_ns for r in results.odometry_results], dtype=np.float64)
    for r in results.odometry_results[1:]:
        if r.gap:
            continue
        measurement, covariance = odometry_factor(r)
        i, j = r.index - 1, r.index
        item = factor_nees(measurement, covariance, truth[i], truth[j])
        true_turn = wrap_angle(between(truth[i], truth[j])[2])
        rate_dps = np.rad2deg(abs(true_turn)) / max((stamps[j] - stamps[i]) / NS_PER_S, 1e-9)
        (turning if rate_dps > turn_dps else straight).append(item)
    return [
        summarise("odometry", straight + turning),
        summarise("  straight", straight),
        summarise("  turning", turning),
    ]


def loop_groups(results: Results, truth: NDArray[np.float64]) -> list[Group]:
    """The accepted loop factors: all, same direction, opposite direction (|yaw| > 90 deg)."""
    same: list[FactorNees] = []
    opposite: list[FactorNees] = []
    for d in results.loops:
        if d.status != "accepted":
            continue
        item = factor_nees(d.measurement, d.covariance, truth[d.query_key], truth[d.match_key])
        (opposite if abs(float(d.measurement[2])) > np.pi / 2 else same).append(item)
    return [
        summarise("loops", same + opposite),
        summarise("  same direction", same),
        summarise("  opposite", opposite),
    ]


def overrides_of(pairs: list[str]) -> dict[str, Any]:
    """A nested mapping from `section.key=value` pairs (values parsed as YAML)."""
    out: dict[str, Any] = {}
    for pair in pairs:
        dotted, _, value = pair.partition("=")
        node = out
        *path, leaf = dotted.split(".")
        for key in path:
            node = node.setdefault(key, {})
        node[leaf] = yaml.safe_load(value)
    return out


def bench(spec: str, stride: int, args: argparse.Namespace) -> dict[str, Any]:
    """Run the pipeline on `spec` at `stride`; print and return the NEES and accuracy."""
    config = load_config(spec.split("/")[0], args.config, overrides_of(args.set))
    model = overrides_of(args.loop_covariance)
    verification.LOOP_COVARIANCE = replace(verification.LOOP_COVARIANCE, **model)
    sequence = strided(open_sequence(spec, args.data_root), stride)
    results = Pipeline(sequence, config).run()
    truth = results.ground_truth_poses
    if truth is None:
        raise SystemExit(f"{spec}: no ground truth")
    gaps = sum(r.gap for r in results.odometry_results)
    groups = odometry_groups(results, truth, args.turn_dps) + loop_groups(results, truth)
    m = results.metrics.to_dict()
    print(
        f"\n{spec} stride {stride}: ATE odometry {m['ate_odometry_m']:.3f} m, SLAM "
        f"{m['ate_slam_m']:.3f} m, loops {m['loops_accepted']} accepted / "
        f"{m['loops_accepted_true']} true, gaps {gaps}"
    )
    print(
        f"  {'factors':<22} {'n':>5} {'NEES':>8} {'median':>7} {'>99%':>6} {'x':>7} {'y':>7}"
        f" {'yaw':>7}"
    )
    for group in groups:
        print(group.row())
    return {
        "sequence": spec,
        "stride": stride,
        "metrics": {
            k: m[k]
            for k in ("ate_odometry_m", "ate_slam_m", "loops_accepted", "loops_accepted_true")
        },
        "groups": [group.__dict__ for group in groups],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("sequences", nargs="*", default=list(DEFAULT_SEQUENCES))
    parser.add_argument("--data-root", type=Path, default=Path("data"))
    parser.add_argument("--stride", type=int, nargs="+", default=[1])
    parser.add_argument("--config", type=Path, default=None, help="a --config file of `run`")
    parser.add_argument("--set", action="append", default=[], help="section.key=value")
    parser.add_argument(
        "--loop-covariance", action="append", default=[], help="key=value of LOOP_COVARIANCE"
    )
    parser.add_argument("--turn-dps", type=float, default=5.0, help="turning above [deg/s]")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    rows = [bench(spec, stride, args) for spec in args.sequences for stride in args.stride]
    if args.json is not None:
        tmp = args.json.with_suffix(args.json.suffix + ".tmp")
        tmp.write_text(json.dumps(rows, indent=1))
        tmp.replace(args.json)


if __name__ == "__main__":
    main()
