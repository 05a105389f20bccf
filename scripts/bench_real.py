"""Odometry and SLAM on every real radar sequence in ../shared/data, scored against its own GT.

Sequences: the RADIATE Edinburgh drive (1.5 km, GNSS/INS without RTK), the Oxford scans (GT
radar odometry), the RADIATE fog frames (no GT: speed only). Each runs at 4 Hz, and the
Edinburgh drive also at strides 2 and 4 and without sweep times (every scan taken as an
instant, as the loader did before it spread azimuth times over the sweep).

A GNSS track runs on another clock than the radar: its offset is estimated from the odometry's
speed profile (`radar_slam.evaluation.time_offset`) and the metrics are given as stamped and
with that offset applied. Accuracy against GNSS is metre level: drift is taken over KITTI
segments of 400-800 m only (`metrics.drift_lengths_m`). Scans/s is the pipeline's own wall time
per scan on this machine (reading included, result writing excluded).

Usage: python scripts/bench_real.py [--data-root ../shared/data] [--write-doc]
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from radar_slam.datasets import RadarFrame, open_sequence
from radar_slam.datasets.frame import GroundTruthSource, RadarSequence
from radar_slam.datasets.stride import strided
from radar_slam.evaluation.metrics import TrajectoryMetrics
from radar_slam.pipeline import Pipeline, load_config, run_odometry
from radar_slam.pipeline.steps import gt_report_of

DEFAULT_ROOT = Path(__file__).resolve().parents[2] / "shared" / "data"
EDINBURGH = "radiate/edinburgh_2019-02-12-15-33"
OXFORD = "oxford/2019-01-10-14-36-48-partial"
FOG = "radiate/fog_6_0-partial"
STATE_OF_THE_ART = (
    "Published radar odometry on Oxford and MulRan (KITTI drift over 100-800 m, centimetre GT): "
    "CFEAR-3 1.31 % / 1.62 %, CFEAR-3-s50 1.09 % / 1.50 %, CFEAR 2024 1.16 % / 1.18 %."
)


class Timeless:
    """A sequence whose scans carry no azimuth times (each taken as an instant): no de-skew."""

    def __init__(self, base: RadarSequence) -> None:
        self.base = base
        self.name = base.name + "_timeless"
        self.family = base.family

    def __len__(self) -> int:
        return len(self.base)

    def __getitem__(self, index: int) -> RadarFrame:
        return dataclasses.replace(self.base[index], azimuth_times_ns=None)

    @property
    def timestamps_ns(self) -> NDArray[np.int64]:
        return self.base.timestamps_ns

    @property
    def ground_truth(self) -> NDArray[np.float64] | None:
        return self.base.ground_truth

    @property
    def ground_truth_source(self) -> GroundTruthSource | None:
        return self.base.ground_truth_source


@dataclass(frozen=True)
class Row:
    """One line of the table."""

    sequence: str
    variant: str
    scans: int
    scans_per_s: float
    stamped: TrajectoryMetrics | None
    shifted: TrajectoryMetrics | None
    offset_s: float | None
    loops: int | None = None


def _fmt(value: float | None, spec: str) -> str:
    return "n/a" if value is None else format(value, spec)


def measure(
    label: str,
    variant: str,
    sequence: RadarSequence,
    slam: bool,
) -> Row:
    """Run odometry (or SLAM) over `sequence` and score it."""
    config = load_config(sequence.family)
    start = time.perf_counter()
    if slam:
        results = Pipeline(sequence, config).run()
        seconds = time.perf_counter() - start
        trajectory, metrics, report = results.slam, results.slam_metrics, results.gt_report
        loops: int | None = results.metrics.loops_accepted
        name = "slam"
    else:
        run = run_odometry(sequence, config)
        seconds = time.perf_counter() - start
        trajectory, metrics, loops, name = run.trajectory, run.metrics, None, "odometry"
        report = gt_report_of(sequence, run.ground_truth, {"odometry": trajectory})
    offset = None if report is None or report.time_offset is None else report.time_offset
    shifted = None if report is None else report.offset_applied.get(name)
    return Row(
        label,
        variant,
        len(trajectory),
        len(trajectory) / seconds,
        metrics,
        shifted,
        None if offset is None else offset.offset_s,
        loops,
    )


def table(rows: list[Row]) -> str:
    """Markdown table of the rows."""
    head = (
        "| sequence | run | scans | scans/s | GT offset [s] | ATE [m] stamped | ATE [m] offset | "
        "end point [%] offset | drift [%] offset | loops |"
    )
    lines = [head, "|" + " --- |" * 10]
    for r in rows:
        s, o = r.stamped, r.shifted
        lines.append(
            f"| {r.sequence} | {r.variant} | {r.scans} | {r.scans_per_s:.1f} | "
            f"{_fmt(r.offset_s, '+.3f')} | {_fmt(s and s.ate_rmse_m, '.2f')} | "
            f"{_fmt(o and o.ate_rmse_m, '.2f')} | {_fmt(o and o.end_point_error_pct, '.2f')} | "
            f"{_fmt(o and o.drift_trans_pct, '.2f')} | {_fmt(r.loops, 'd')} |"
        )
    return "\n".join(lines)


def oxford_table(rows: list[Row]) -> str:
    """The Oxford scans: GT on the radar's own clock, a few scans (no drift)."""
    lines = ["| sequence | run | scans | scans/s | ATE [m] | RPE [m] |", "|" + " --- |" * 6]
    for r in rows:
        s = r.stamped
        lines.append(
            f"| {r.sequence} | {r.variant} | {r.scans} | {r.scans_per_s:.1f} | "
            f"{_fmt(s and s.ate_rmse_m, '.3f')} | {_fmt(s and s.rpe_trans_rmse_m, '.3f')} |"
        )
    return "\n".join(lines)


def machine() -> str:
    """One line naming this machine."""
    cpu = platform.processor() or platform.machine()
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file():
        for line in cpuinfo.read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}"


def run_all(root: Path) -> tuple[list[Row], list[Row], list[Row]]:
    """(Edinburgh rows, Oxford rows, fog rows)."""
    edinburgh = open_sequence(EDINBURGH, root)
    runs: list[tuple[str, Callable[[], RadarSequence], bool]] = [
        ("odometry, no sweep times", lambda: Timeless(edinburgh), False),
        ("odometry 4 Hz", lambda: edinburgh, False),
        ("odometry 2 Hz (stride 2)", lambda: strided(edinburgh, 2), False),
        ("odometry 1 Hz (stride 4)", lambda: strided(edinburgh, 4), False),
        ("SLAM 4 Hz", lambda: edinburgh, True),
    ]
    real = [measure(EDINBURGH, v, make(), slam) for v, make, slam in runs]
    oxford = open_sequence(OXFORD, root)
    ox = [measure(OXFORD, "odometry 4 Hz", oxford, False)]
    fog = [measure(FOG, "odometry 4 Hz", open_sequence(FOG, root), False)]
    return real, ox, fog


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-root", type=Path, default=DEFAULT_ROOT)
    parser.add_argument(
        "--write-doc", action="store_true", help="rewrite the table in docs/benchmarks.md"
    )
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    real, oxford, fog = run_all(args.data_root)
    text = "\n\n".join(
        [
            "RADIATE Edinburgh drive (714 scans, 178 s, 1.5 km), against GNSS/INS without RTK "
            "(metre level); 'offset' columns read the GNSS through the clock offset estimated "
            "from the odometry's speed profile; drift over 400-800 m segments; scans in GNSS "
            "outages (about 136) have no GT and are left out.",
            table(real),
            "Oxford scans (7 consecutive, GT radar odometry on the radar's clock):",
            oxford_table(oxford),
            f"RADIATE fog frames (18, no GT): {fog[0].scans_per_s:.1f} scans/s.",
            STATE_OF_THE_ART,
        ]
    )
    print(f"machine: {machine()}\n\n{text}")
    if args.write_doc:
        sys.path.insert(0, str(Path(__file__).parent))
        from benchmark_doc import update_section

        update_section("Real drives", text, script="scripts/bench_real.py")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
