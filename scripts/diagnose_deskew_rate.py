"""How well does the correlation peak quality tell a sweep's yaw rate at low frame rates?

Runs `Odometry` over a (strided) sequence with ground truth and, per registered scan, compares the
yaw rate the scan was de-skewed with (the one it kept, before and after the re-de-skew check) with
the sweep's true mean yaw rate (ground truth of the full-rate sequence over the sweep). For the
scans where the yaw rate is large or the de-skew is off (at most `--grid-scans` per sequence), the
scan is rendered again at a grid of yaw rates around the one it kept (speed as kept) and
registered against the same reference, seeded with the kept estimate; the peak quality as a
function of the yaw rate is printed, with the parabolic maximum of the best three grid points.

Usage: python scripts/diagnose_deskew_rate.py synthetic/roundabouts [SEQ ...] --stride 4
       [--data-root DIR] [--grid -24 -16 -8 -4 0 4 8 16 24] [--grid-scans 20]
(tuning scenarios only: never the held-out drives.)
"""

from __future__ import annotations

import argparse
import logging
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


def run(
    spec: str,
    stride: int,
    data_root: Path | None,
    grid: FloatArray,
    grid_scans: int,
    absolute: bool,
) -> None:
    base = open_sequence(spec, data_root=data_root)
    sequence = strided(base, stride)
    truth = np.rad2deg(true_sweep_yaw_rates(base, stride))
    odometry = Odometry()
    rows: list[tuple[int, float, float, float, float]] = []
    sweeps: list[tuple[int, float, float, FloatArray]] = []
    kept_of: dict[int, float] = {}
    ref_of: dict[int, tuple[float, int]] = {}
    original_accept = odometry._accept

    def accept(index: int, scan: PreparedScan, reference: Any, estimate: Any, dt_s: float) -> Any:
        used = np.nan if scan.twist is None else float(np.rad2deg(scan.twist[2]))
        off = abs(used - truth[index]) if np.isfinite(used) else 0.0
        big = abs(truth[index]) > 10.0 or off > 3.0
        if scan.twist is not None and big and len(sweeps) < grid_scans:
            qualities = np.empty(len(grid))
            for j, offset in enumerate(grid):
                twist = scan.twist.copy()
                twist[2] = np.deg2rad(offset) if absolute else twist[2] + np.deg2rad(offset)
                again = PreparedScan(scan.polar, twist, odometry.config)
                other = register_images(
                    reference.scan, again, odometry.config, hint=estimate.motion
                )
                qualities[j] = other.quality if other.ok else np.nan
            sweeps.append((index, used, float(truth[index]), qualities))
            ref_twist = reference.scan.twist
            ref_used = np.nan if ref_twist is None else float(np.rad2deg(ref_twist[2]))
            ref_of[index] = (ref_used - float(truth[reference.index]), reference.index)
        else:
            qualities = None
        result = original_accept(index, scan, reference, estimate, dt_s)
        kept = odometry._state.previous
        final = np.nan if kept is None or kept.scan.twist is None else kept.scan.twist[2]
        rows.append((index, used, float(np.rad2deg(final)), float(truth[index]), estimate.quality))
        if qualities is not None:
            kept_of[index] = float(np.rad2deg(final))
        return result

    odometry._accept = accept  # type: ignore[method-assign]
    for k in range(len(sequence)):
        odometry.register(sequence[k])
    table = np.array(rows)
    err_used = table[:, 1] - table[:, 3]
    err_final = table[:, 2] - table[:, 3]
    print(f"\n== {spec} stride {stride}: {len(table)} registered scans")
    print(
        f"de-skew yaw-rate error [deg/s] (registered / kept after re-de-skew): rms "
        f"{np.sqrt(np.nanmean(err_used**2)):.2f} / {np.sqrt(np.nanmean(err_final**2)):.2f}, "
        f"max |.| {np.nanmax(np.abs(err_used)):.1f} / {np.nanmax(np.abs(err_final)):.1f}"
    )
    print("scan  used   kept   true   quality")
    for index, used, final, true, quality in rows:
        if abs(final - true) > 3.0:
            print(f"{index:4d} {used:6.1f} {final:6.1f} {true:6.1f} {quality:7.1f}")
    if not sweeps:
        return
    where = "" if absolute else "used + "
    print(f"peak quality at de-skew yaw rate = {where}{np.round(grid, 1).tolist()} deg/s")
    est_err, used_err, kept_err, ref_err = [], [], [], []
    for index, used, true, qualities in sweeps:
        rates = grid if absolute else used + grid
        kept_err.append(kept_of[index] - true)
        ref_err.append(ref_of[index][0])
        peak = parabolic_peak(rates, qualities) if np.isfinite(qualities).any() else np.nan
        rel = qualities / np.nanmax(qualities)
        est_err.append(peak - true)
        used_err.append(used - true)
        print(
            f"{index:4d} used {used:6.1f} kept {kept_of[index]:6.1f} true {true:6.1f} "
            f"peak {peak:6.1f} ref {ref_of[index][1]:3d} off {ref_of[index][0]:6.1f} | "
            + " ".join(f"{r:4.2f}" for r in rel)
        )
    est, ref = np.array(est_err), np.array(ref_err)
    both = np.isfinite(est) & np.isfinite(ref)
    print(
        "correlation of the peak's error with the reference scan's de-skew error: "
        f"{np.corrcoef(est[both], ref[both])[0, 1]:+.2f}"
    )
    for name, err in (("peak", est_err), ("used", used_err), ("kept", kept_err)):
        e = np.array(err)
        print(
            f"{name} yaw-rate error [deg/s]: mean {np.nanmean(e):+.2f}, rms "
            f"{np.sqrt(np.nanmean(e**2)):.2f}, median |.| {np.nanmedian(np.abs(e)):.2f} "
            f"over {len(e)} scans"
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
    for spec in args.sequences:
        grid = np.asarray(args.grid, float)
        run(spec, args.stride, args.data_root, grid, args.grid_scans, args.absolute)


if __name__ == "__main__":
    main()
