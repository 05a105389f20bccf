"""How well does the correlation peak quality tell a sweep's yaw rate at low frame rates?

Runs `Odometry` over a (strided) sequence with ground truth and, per registered scan, compares the
yaw rate the scan was de-skewed with (the one it kept, before and after the re-de-skew check) with
the sweep's true mean yaw rate (ground truth of the full-rate sequence over the sweep). For the
scans where the yaw rate is large or the de-skew is off (at most `--grid-scans` per sequence), the
scan is rendered again at a grid of yaw rates around the one it kept (speed as kept) and
registered against the same reference, seeded with the kept estimate; the peak quality as a function
of the yaw rate is printed, with the parabolic maximum of the best three grid points, and how the
maximum's error relates to the reference scan's de-skew error (docs/odometry_notes.md, issue 10y: it
follows it, so the peak quality measures the yaw rate relative to the reference's de-skew).

Usage: python scripts/diagnose_deskew_rate.py synthetic/roundabouts [SEQ ...] --stride 4
       [--data-root DIR] [--grid -24 -16 -8 -4 0 4 8 16 24] [--grid-scans 20] [--absolute]
(the figures in docs/odometry_notes.md: --grid-scans 60 --absolute --grid $(seq -60 6 60) on
roundabouts, u_turn, three_point_turn, junction_turns)
(tuning scenarios only: never the held-out drives.)
"""

from __future__ import annotations

import argparse
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from odometry.odometry import Odometry
from odometry.registration import PreparedScan, register_images
from radar_slam.datasets import open_sequence
from radar_slam.datasets.stride import strided
from raplace.se2 import wrap_angle
from raplace.units import NS_PER_S

logger = logging.getLogger("diagnose_deskew_rate")
FloatArray = NDArray[np.float64]


def true_sweep_yaw_rates(base: Any, stride: int) -> FloatArray:
    """(N,) mean yaw rate [rad/s] over each kept scan's sweep (the full-rate interval before it:
    the synthetic sweep is one scan period long), NaN for the first scan."""
    gt = np.asarray(base.ground_truth, dtype=np.float64)
    stamps = np.asarray(base.timestamps_ns, dtype=np.int64)
    idx = np.arange(0, len(base), stride)
    rates = np.full(len(idx), np.nan)
    ok = idx > 0
    prev = idx[ok] - 1
    dyaw = wrap_angle(gt[idx[ok], 2] - gt[prev, 2])
    rates[ok] = dyaw / ((stamps[idx[ok]] - stamps[prev]) / NS_PER_S)
    return rates


def parabolic_peak(x: FloatArray, q: FloatArray) -> float:
    """The maximum of the parabola through the best grid point and its neighbours (x units)."""
    k = int(np.nanargmax(q))
    if k == 0 or k == len(x) - 1:
        return float(x[k])
    a, b, c = np.polyfit(x[k - 1 : k + 2], q[k - 1 : k + 2], 2)
    return float(-b / (2 * a)) if a < 0 else float(x[k])


@dataclass
class Sweep:
    """One scan rendered at a grid of de-skew yaw rates [deg/s]: the rate it was registered
    with (`used`), kept after the re-de-skew check (`kept`), the sweep's true mean rate, the
    reference scan and its de-skew error, and the peak quality at each grid rate."""

    index: int
    used: float
    kept: float
    true: float
    reference: int
    reference_error: float
    rates: FloatArray
    qualities: FloatArray


def record(
    spec: str,
    stride: int,
    data_root: Path | None,
    grid: FloatArray,
    grid_scans: int,
    absolute: bool,
) -> tuple[FloatArray, list[Sweep]]:
    """Run the odometry over `spec` at `stride`: per registered scan (index, used, kept, true
    yaw rate [deg/s], peak quality), and the grid sweeps of up to `grid_scans` scans."""
    base = open_sequence(spec, data_root=data_root)
    sequence = strided(base, stride)
    truth = np.rad2deg(true_sweep_yaw_rates(base, stride))
    odometry = Odometry()
    cfg = odometry.config
    rows: list[tuple[int, float, float, float, float]] = []
    sweeps: list[Sweep] = []
    original_accept = odometry._accept

    def accept(index: int, scan: PreparedScan, reference: Any, estimate: Any, dt_s: float) -> Any:
        used = np.nan if scan.twist is None else float(np.rad2deg(scan.twist[2]))
        off = abs(used - truth[index]) if np.isfinite(used) else 0.0
        sweep = None
        if scan.twist is not None and (abs(truth[index]) > 10.0 or off > 3.0):
            rates = grid if absolute else used + grid
            qualities = np.full(len(rates), np.nan)
            for j, rate in enumerate(rates if len(sweeps) < grid_scans else []):
                twist = scan.twist.copy()
                twist[2] = np.deg2rad(rate)
                again = PreparedScan(scan.polar, twist, cfg)
                other = register_images(reference.scan, again, cfg, hint=estimate.motion)
                qualities[j] = other.quality if other.ok else np.nan
            ref_twist = reference.scan.twist
            ref_error = np.nan if ref_twist is None else np.rad2deg(ref_twist[2])
            ref_error -= float(truth[reference.index])
            if np.isfinite(qualities).any():
                sweep = Sweep(index, used, np.nan, float(truth[index]), reference.index,
                              float(ref_error), rates, qualities)  # fmt: skip
        result = original_accept(index, scan, reference, estimate, dt_s)
        kept = odometry._state.previous
        final = np.nan if kept is None or kept.scan.twist is None else kept.scan.twist[2]
        rows.append((index, used, float(np.rad2deg(final)), float(truth[index]), estimate.quality))
        if sweep is not None:
            sweep.kept = float(np.rad2deg(final))
            sweeps.append(sweep)
        return result

    odometry._accept = accept  # type: ignore[method-assign]
    for k in range(len(sequence)):
        odometry.register(sequence[k])
    return np.array(rows), sweeps


def report_rows(rows: FloatArray) -> None:
    """The de-skew yaw-rate errors of every registered scan; the scans more than 3 deg/s off."""
    err_used, err_kept = rows[:, 1] - rows[:, 3], rows[:, 2] - rows[:, 3]
    print(
        f"de-skew yaw-rate error [deg/s] (registered / kept after re-de-skew): rms "
        f"{np.sqrt(np.nanmean(err_used**2)):.2f} / {np.sqrt(np.nanmean(err_kept**2)):.2f}, "
        f"max |.| {np.nanmax(np.abs(err_used)):.1f} / {np.nanmax(np.abs(err_kept)):.1f}"
    )
    print("scan  used   kept   true   quality")
    for index, used, kept, true, quality in rows:
        if abs(kept - true) > 3.0:
            print(f"{int(index):4d} {used:6.1f} {kept:6.1f} {true:6.1f} {quality:7.1f}")


def report_sweeps(sweeps: list[Sweep]) -> None:
    """Each sweep's relative peak quality and parabolic maximum; how the maximum's error relates
    to the reference's de-skew error; the errors of the maximum, the used and the kept rates."""
    peak_err, ref_err = np.full(len(sweeps), np.nan), np.full(len(sweeps), np.nan)
    inside = np.zeros(len(sweeps), dtype=bool)
    for i, sweep in enumerate(sweeps):
        peak = parabolic_peak(sweep.rates, sweep.qualities)
        peak_err[i], ref_err[i] = peak - sweep.true, sweep.reference_error
        inside[i] = sweep.rates[0] < peak < sweep.rates[-1]
        rel = sweep.qualities / np.nanmax(sweep.qualities)
        print(
            f"{sweep.index:4d} used {sweep.used:6.1f} kept {sweep.kept:6.1f} true "
            f"{sweep.true:6.1f} peak {peak:6.1f} ref {sweep.reference:3d} off "
            f"{sweep.reference_error:6.1f} | " + " ".join(f"{r:4.2f}" for r in rel)
        )
    both = inside & np.isfinite(peak_err) & np.isfinite(ref_err)
    if both.sum() > 2:
        slope, intercept = np.polyfit(ref_err[both], peak_err[both], 1)
        residual = peak_err[both] - (slope * ref_err[both] + intercept)
        print(
            f"maximum's error vs the reference's de-skew error ({both.sum()} maxima inside the "
            f"grid): correlation {np.corrcoef(ref_err[both], peak_err[both])[0, 1]:+.2f}, "
            f"error = {slope:.2f} x reference error {intercept:+.1f} deg/s, residual "
            f"{np.sqrt(np.mean(residual**2)):.1f} deg/s rms"
        )
    good = both & (np.abs(ref_err) < 3.0)
    kept_err = np.array([s.kept - s.true for s in sweeps])
    used_err = np.array([s.used - s.true for s in sweeps])
    for name, err in (("peak", peak_err), ("used", used_err), ("kept", kept_err)):
        print(
            f"{name} yaw-rate error [deg/s]: rms {np.sqrt(np.nanmean(err**2)):.2f} over "
            f"{len(err)} scans; where the reference is within 3 deg/s ({good.sum()}): mean "
            f"{np.nanmean(err[good]):+.2f}, rms {np.sqrt(np.nanmean(err[good] ** 2)):.2f}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("sequences", nargs="+")
    parser.add_argument("--stride", type=int, default=4)
    parser.add_argument("--data-root", type=Path, default=None)
    parser.add_argument(
        "--grid", type=float, nargs="+", default=[-24, -16, -8, -4, 0, 4, 8, 16, 24]
    )
    parser.add_argument("--grid-scans", type=int, default=20)
    parser.add_argument("--absolute", action="store_true", help="grid of absolute yaw rates")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    all_sweeps: list[Sweep] = []
    grid = np.asarray(args.grid, float)
    for spec in args.sequences:
        rows, sweeps = record(
            spec, args.stride, args.data_root, grid, args.grid_scans, args.absolute
        )
        print(f"\n== {spec} stride {args.stride}: {len(rows)} registered scans")
        report_rows(rows)
        if sweeps:
            where = "" if args.absolute else "used + "
            print(f"peak quality at de-skew yaw rate = {where}{np.round(grid, 1).tolist()} deg/s")
            report_sweeps(sweeps)
        all_sweeps.extend(sweeps)
    if len(args.sequences) > 1 and all_sweeps:
        print("\n== all sequences")
        report_sweeps(all_sweeps)


if __name__ == "__main__":
    main()
