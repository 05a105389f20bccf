"""Ablate the odometry: each mechanism switched off in turn, on real and simulated drives.

Every variant runs the odometry (`radar_slam.pipeline.run_odometry`, the family config as
`radar-slam odometry` loads it) with one mechanism off, through its config key or, where it has
none, a small override patched in for the run. Drives:

- the RADIATE Edinburgh drive (real, GNSS/INS ground truth) at the `--real-stride` strides (4 Hz
  and stride 4 by default); scored with the GT clock offset estimated from the odometry's speed
  profile (ATE, end-point error, drift over 400-800 m segments; strided runs take the offset
  estimated at 4 Hz when their own speed profile is too coarse for it);
- the Oxford scans (real, GT radar odometry): ATE;
- the `--sim` simulated drives at 4 Hz and stride 4: drift and the longest run of gaps.

Each cell also gives the registrations per scan (`OdometryResult.registrations`, coarse and fine
count as one). With all variants the defaults take about half an hour on two shared cores (the
real drive at 4 Hz is most of it); `--variants` runs a subset, `--real-stride` and `--sim` choose
the drives, `--max-frames` cuts the simulated drives (the real drive always runs in full: its GT
offset needs the speed profile).

Usage: python scripts/ablate_odometry.py [--data-root ../shared/data] [--sim-root DIR]
           [--real-stride 4 ...] [--sim tiny_u_turn ...] [--variants base,no_trend,...]
           [--max-frames N] [--out FILE.md]
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import logging
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import odometry.odometry as odometry_module
import odometry.registration as registration
import odometry.velocity as velocity
from odometry.phase_correlation import ROTATION
from radar_slam.datasets import open_sequence
from radar_slam.datasets.stride import strided
from radar_slam.evaluation.metrics import evaluate
from radar_slam.evaluation.time_offset import ground_truth_with_offset
from radar_slam.pipeline import load_config, run_odometry
from radar_slam.pipeline.steps import ground_truth_of

sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchmark_doc import update_section  # noqa: E402

logger = logging.getLogger("ablate_odometry")
SCRIPT = "scripts/ablate_odometry.py"
ABLATION_NOTE = (
    "Each row switches one odometry mechanism off. Real drive: ATE [m] through the GT clock "
    "offset, end-point error and drift over 400-800 m [%]; Oxford: ATE [m]; simulated drives: "
    "KITTI drift [%] and the longest run of gaps; every drive: registrations per scan. A "
    "mechanism stays where switching it off makes the real drive clearly worse, or a simulated "
    "drive worse for a physical effect real driving has (docs/decisions.md). The table before "
    "the removals is in docs/odometry_ablation.md."
)

DEFAULT_ROOT = Path(__file__).resolve().parents[2] / "shared" / "data"
REAL_DRIVE = "radiate/edinburgh_2019-02-12-15-33"
OXFORD = "oxford/2019-01-10-14-36-48-partial"
DEFAULT_REAL_STRIDES = (1, 4)
DEFAULT_SIMS = ("tiny_u_turn", "tiny_roundabout")
SIM_STRIDES = (1, 4)


@dataclass(frozen=True)
class Variant:
    """One row: the odometry with one mechanism off.

    Attributes:
        name: short name (`--variants`).
        mechanism: what is switched off, as the table says it.
        overrides: the `odometry:` config keys changed (nested mapping).
        patch: a context manager that switches off a mechanism without a key (None: none).
    """

    name: str
    mechanism: str
    overrides: dict[str, Any] = field(default_factory=dict)
    patch: Callable[[], contextlib.AbstractContextManager[None]] | None = None


@contextlib.contextmanager
def _patched(module: object, name: str, replacement: object) -> Iterator[None]:
    original = getattr(module, name)
    setattr(module, name, replacement)
    try:
        yield
    finally:
        setattr(module, name, original)


def _no_redeskew() -> contextlib.AbstractContextManager[None]:
    return _patched(velocity, "redeskewed", lambda _r, rendered, *_a, **_k: rendered)


def _no_deferred_first_images() -> contextlib.AbstractContextManager[None]:
    return _patched(odometry_module.Odometry, "_place_first_images", lambda *_a: None)


def _no_trend() -> contextlib.AbstractContextManager[None]:
    return _patched(velocity, "YAW_TREND_GAIN", 0.0)


def _keyframe_only() -> contextlib.AbstractContextManager[None]:
    return _patched(odometry_module.Odometry, "_fallback", lambda *_a: None)


def _coarse_refinements_only() -> contextlib.AbstractContextManager[None]:
    return _patched(registration, "ROTATION", dataclasses.replace(ROTATION, refine_at_fine=False))


def _one_refinement() -> contextlib.AbstractContextManager[None]:
    return _patched(registration, "ROTATION", dataclasses.replace(ROTATION, refine_passes=1))


def _no_refinement() -> contextlib.AbstractContextManager[None]:
    return _patched(registration, "ROTATION", dataclasses.replace(ROTATION, refine=False))


VARIANTS = (
    Variant("base", "(nothing: the defaults)"),
    Variant("no_trend", "yaw-trend hypothesis", patch=_no_trend),
    Variant("no_redeskew", "re-de-skew", patch=_no_redeskew),
    Variant("no_deferred", "deferred first images", patch=_no_deferred_first_images),
    Variant("no_fallback", "fallback to the last registered scan", patch=_keyframe_only),
    Variant(
        "coarse_refine_only",
        "rotation refinement at the fine translation",
        patch=_coarse_refinements_only,
    ),
    Variant("one_refine", "second refinement at the coarse translation", patch=_one_refinement),
    Variant("no_refine", "Fourier-Mellin refinement", patch=_no_refinement),
)


@dataclass(frozen=True)
class Cell:
    """One drive's figures for one variant (None: not measured)."""

    ate_m: float | None = None
    end_pct: float | None = None
    drift_pct: float | None = None
    longest_gap_run: int = 0
    registrations: float = 0.0


def _run(
    spec: str,
    root: Path,
    stride: int,
    variant: Variant,
    max_frames: int | None,
    offsets: dict[str, float] | None,
) -> Cell:
    """Run `variant` over `spec` at `stride` and score it; with `offsets` (the GT clock offset
    [s] by sequence, filled here), through the GT clock offset: the run's own estimate, else the
    one estimated on the same sequence before (at 1 Hz the speed profile is too coarse)."""
    family = spec.split("/")[0]
    config = load_config(family, overrides={"odometry": variant.overrides})
    full = open_sequence(spec, data_root=root)
    sequence = strided(full, stride)
    patch = variant.patch() if variant.patch is not None else contextlib.nullcontext()
    with patch:
        run = run_odometry(sequence, config, max_frames=max_frames)
    counts = [r.registrations for r in run.results[1:]]
    best = run_ = 0
    for result in run.results:
        run_ = run_ + 1 if result.gap else 0
        best = max(best, run_)
    metrics = run.metrics
    report = run.gt_report
    if offsets is not None and report is not None:
        if report.time_offset is not None:
            offsets.setdefault(spec, report.time_offset.offset_s)
            metrics = report.offset_applied.get("odometry", metrics)
        elif spec in offsets:
            _, full_gt = ground_truth_of(full, len(full))  # the GT between the strided scans
            assert full_gt is not None
            stamps = run.trajectory.timestamps_ns
            shifted = ground_truth_with_offset(full_gt, stamps, offsets[spec])
            accuracy_m = 0.0 if report.source is None else report.source.accuracy_m
            metrics = evaluate(run.trajectory, shifted, gt_accuracy_m=accuracy_m)
    if metrics is None:
        return Cell(longest_gap_run=best, registrations=float(np.mean(counts)))
    return Cell(
        ate_m=metrics.ate_rmse_m,
        end_pct=metrics.end_point_error_pct,
        drift_pct=metrics.drift_trans_pct,
        longest_gap_run=best,
        registrations=float(np.mean(counts)),
    )


def _fmt(value: float | None, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


@dataclass(frozen=True)
class Drive:
    """A column group of the table."""

    label: str
    spec: str
    root: Path
    stride: int
    kind: str  # "real" (ATE with the GT offset, end point, drift), "oxford" or "sim"

    def header(self) -> list[str]:
        if self.kind == "real":
            return [f"{self.label} ATE m", "end %", "drift %", "reg/scan"]
        if self.kind == "oxford":
            return [f"{self.label} ATE m", "reg/scan"]
        return [f"{self.label} drift %", "gaps", "reg/scan"]

    def cells(self, cell: Cell) -> list[str]:
        reg = _fmt(cell.registrations)
        if self.kind == "real":
            return [_fmt(cell.ate_m), _fmt(cell.end_pct), _fmt(cell.drift_pct), reg]
        if self.kind == "oxford":
            return [_fmt(cell.ate_m, 3), reg]
        return [_fmt(cell.drift_pct), str(cell.longest_gap_run), reg]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-root", type=Path, default=DEFAULT_ROOT)
    parser.add_argument("--sim-root", type=Path, default=Path("/tmp/radar_slam_sim"))
    parser.add_argument("--real-stride", type=int, action="append")
    parser.add_argument("--sim", action="append")
    parser.add_argument("--variants", help="comma-separated names (default: all)")
    parser.add_argument("--max-frames", type=int)
    parser.add_argument("--out", type=Path, help="also write the Markdown table here")
    parser.add_argument(
        "--write-doc", action="store_true", help="write the table into docs/benchmarks.md"
    )
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING, format="%(name)s: %(message)s")
    logger.setLevel(logging.INFO)
    logging.getLogger("odometry").setLevel(logging.ERROR)

    drives = [
        Drive(f"real {s}x" if s > 1 else "real 4 Hz", REAL_DRIVE, args.data_root, s, "real")
        for s in (args.real_stride or DEFAULT_REAL_STRIDES)
    ]
    drives.append(Drive("Oxford", OXFORD, args.data_root, 1, "oxford"))
    for name in args.sim or DEFAULT_SIMS:
        for s in SIM_STRIDES:
            label = name if s == 1 else f"{name} {s}x"
            drives.append(Drive(label, f"synthetic/{name}", args.sim_root, s, "sim"))
    wanted = None if args.variants is None else set(args.variants.split(","))
    variants = [v for v in VARIANTS if wanted is None or v.name in wanted]

    offsets: dict[str, float] = {}  # the GT clock offset of the real drive, from its 4 Hz run
    rows = []
    for variant in variants:
        start = time.perf_counter()
        row = [variant.mechanism]
        for drive in drives:
            frames = None if drive.kind == "real" else args.max_frames
            real = offsets if drive.kind == "real" else None
            cell = _run(drive.spec, drive.root, drive.stride, variant, frames, real)
            row += drive.cells(cell)
        rows.append(row)
        logger.info("%s (%.0f s): %s", variant.name, time.perf_counter() - start, " | ".join(row))
    header = ["mechanism off"] + [h for d in drives for h in d.header()]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    table = "\n".join(lines)
    print(table)
    if args.out is not None:
        args.out.write_text(table + "\n")
    if args.write_doc:
        update_section("Odometry ablation", f"{ABLATION_NOTE}\n\n{table}", script=SCRIPT)


if __name__ == "__main__":
    main()
