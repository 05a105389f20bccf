"""Benchmark the phase-correlation odometry at MulRan resolution (400 x 3360) on one core.

Two benchmarks:

- Speed (default): a sequence is made from one real MulRan scan
  (../shared/data/mulran/raw_scan/polar/*.png, or a random point world when it is absent): the
  scan is re-sampled as seen from poses along a constant-velocity arc, with motion distortion
  (each azimuth seen from the pose at its own time). `Odometry.register` is timed per frame;
  frames/s and the error against the known trajectory are reported.
- Accuracy (`--sequence`, repeatable): the odometry over real or simulated sequences
  (`synthetic/loop`, `synthetic/long`, ...; simulated ones are generated on first use under the
  data root), reporting KITTI-style drift [% and deg/100 m], ATE (Umeyama and first-pose
  alignment), the normalised squared errors (NEES) of the reported covariances and frames/s
  (register() only, frame loading excluded), gaps and the longest run of consecutive gaps. With
  `--stride K` (repeatable) every sequence also runs on every K-th scan (4 Hz data at 2 or 1 Hz);
  `--held-out SEQ` sequences are reported in their own part of the table (never tune on them);
  `--table FILE` writes the Markdown table (scenarios x strides) to a file, `--write-doc` into
  docs/benchmarks.md (the speed benchmark writes its own section there too).

Usage: python scripts/bench_odometry.py [--frames N] [--speed MPS] [--yaw-rate DPS] [--scan PNG]
       python scripts/bench_odometry.py --sequence synthetic/loop --sequence synthetic/long
           [--held-out SEQ] [--stride 1 --stride 2 --stride 4] [--table FILE]
           [--data-root DIR] [--max-frames N] [--config FILE.yaml] [--write-doc]
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from odometry import Odometry, OdometryConfig, OdometryResult, motion_from_twist
from radar_slam.datasets import RadarFrame, open_sequence
from radar_slam.datasets.stride import strided
from radar_slam.evaluation.metrics import evaluate
from radar_slam.pipeline import load_config
from radar_slam.plots import plot_trajectories
from radar_slam.trajectory import Trajectory
from raplace import NS_PER_S, between, compose, wrap_angle
from raplace.warp import polar_sample_coords, remap

logger = logging.getLogger("bench_odometry")

MULRAN_N_AZIMUTHS = 400
MULRAN_N_BINS = 3360
MULRAN_RANGE_RESOLUTION_M = 0.05952
MULRAN_FIRST_ENCODER = 9
MULRAN_ENCODER_STEP = 14
ENCODER_TICKS = 5600
SWEEP_S = 0.25
FRAME_PERIOD_NS = 250_000_000
DEFAULT_SCAN = (
    Path(__file__).resolve().parents[2]
    / "shared/data/mulran/raw_scan/polar/1564718976161407002.png"
)
SYNTHETIC_POINTS = 3000
SYNTHETIC_SEED = 7


def mulran_azimuths() -> NDArray[np.float64]:
    """CCW azimuths of MulRan's polar columns (clockwise encoder 9 + 14 j of 5600)."""
    encoder = MULRAN_FIRST_ENCODER + MULRAN_ENCODER_STEP * np.arange(MULRAN_N_AZIMUTHS)
    return -encoder * (2.0 * np.pi / ENCODER_TICKS)


def world_scan(path: Path) -> NDArray[np.uint8]:
    """The (400, 3360) polar scan used as the static world (real when available)."""
    if path.is_file():
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if image is not None and image.shape == (MULRAN_N_BINS, MULRAN_N_AZIMUTHS):
            return np.ascontiguousarray(image.T)
        logger.warning("%s is not a MulRan polar scan; using a random world", path)
    else:
        logger.warning("%s not found; using a random point world", path)
    rng = np.random.default_rng(SYNTHETIC_SEED)
    polar = rng.integers(0, 25, (MULRAN_N_AZIMUTHS, MULRAN_N_BINS)).astype(np.uint8)
    rows = rng.integers(0, MULRAN_N_AZIMUTHS, SYNTHETIC_POINTS)
    cols = rng.integers(100, MULRAN_N_BINS, SYNTHETIC_POINTS)
    polar[rows, cols] = rng.integers(80, 255, SYNTHETIC_POINTS)
    return cv2.GaussianBlur(polar, (5, 3), 0)


def render_frame(
    world: NDArray[np.uint8],
    azimuths: NDArray[np.float64],
    pose: NDArray[np.float64],
    twist: NDArray[np.float64],
    timestamp_ns: int,
) -> RadarFrame:
    """The world scan as measured from `pose` (at mid-sweep) while moving at `twist`."""
    n_az, n_bins = world.shape
    tau = (np.arange(n_az) - 0.5 * (n_az - 1)) * (SWEEP_S / n_az)
    poses = np.array([compose(pose, motion_from_twist(twist, t)) for t in tau])
    ranges = (np.arange(n_bins) + 0.5) * MULRAN_RANGE_RESOLUTION_M
    xs = ranges[None, :] * np.cos(azimuths)[:, None]
    ys = ranges[None, :] * np.sin(azimuths)[:, None]
    c, s = np.cos(poses[:, 2:3]), np.sin(poses[:, 2:3])
    x = c * xs - s * ys + poses[:, 0:1]
    y = s * xs + c * ys + poses[:, 1:2]
    bins, rows = polar_sample_coords(x, y, azimuths, MULRAN_RANGE_RESOLUTION_M)
    polar = np.clip(np.rint(remap(world, bins, rows)), 0, 255).astype(np.uint8)
    return RadarFrame(
        timestamp_ns=timestamp_ns,
        polar=polar,
        azimuths_rad=azimuths,
        range_resolution_m=MULRAN_RANGE_RESOLUTION_M,
        sensor="bench-mulran",
        azimuth_times_ns=(timestamp_ns + np.rint(tau * NS_PER_S)).astype(np.int64),
    )


def reference_nees(
    results: list[OdometryResult], truth: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Normalised squared error of each registered scan's motion from its reference scan
    (`keyframe_motion`) under its covariance (reported in the previous scan's axes; turned back
    into the reference's). 3 on average when the covariances are calibrated."""
    nees = []
    for r in results[1:]:
        if not r.ok:
            continue
        error = r.keyframe_motion - between(truth[r.keyframe_index], truth[r.index])
        error[2] = wrap_angle(error[2])
        turn = float(between(results[r.index - 1].pose, results[r.keyframe_index].pose)[2])
        c, s = np.cos(turn), np.sin(turn)
        rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
        covariance = rot @ r.covariance @ rot.T
        nees.append(float(error @ np.linalg.solve(covariance, error)))
    return np.array(nees)


@dataclass(frozen=True)
class SequenceRow:
    """One (sequence, stride) line of the accuracy table."""

    spec: str
    stride: int
    frames: int
    length_m: float | None
    drift_pct: float | None
    drift_deg_per_100m: float | None
    ate_m: float | None
    gaps: int
    longest_gap_run: int
    frames_per_s: float
    registrations: float = 0.0
    held_out: bool = False


def bench_sequence(
    spec: str,
    data_root: Path | None,
    max_frames: int | None,
    plot_dir: Path | None,
    stride: int = 1,
    held_out: bool = False,
    config: OdometryConfig | None = None,
) -> SequenceRow:
    """Run the odometry over one sequence (every `stride`-th scan) and log its accuracy and
    speed (`config`: the odometry settings, defaults when None); with `plot_dir`, save
    `odometry_<sequence>[_strideK].png` there (ground truth moved to start at the first
    odometry pose)."""
    sequence = strided(open_sequence(spec, data_root=data_root), stride)
    label = spec if stride == 1 else f"{spec} --stride {stride}"
    n = len(sequence) if max_frames is None else min(len(sequence), max_frames)
    odometry = Odometry(config)
    durations = []
    for k in range(n):
        frame = sequence[k]
        start = time.perf_counter()
        odometry.register(frame)
        durations.append(time.perf_counter() - start)
    ms = np.array(durations[1:]) * 1e3
    stamps = sequence.timestamps_ns[:n]
    estimate = Trajectory(stamps, odometry.poses)
    gap_run = odometry.longest_gap_run
    logger.info(
        "%s: %d frames, %d keyframes, %d gaps (longest run %d); %.2f registrations/frame; "
        "%.1f ms/frame -> %.1f frames/s",
        label,
        n,
        len(odometry.keyframes),
        len(odometry.gaps),
        gap_run,
        odometry.registrations_per_scan,
        ms.mean(),
        1e3 / ms.mean(),
    )
    row = SequenceRow(
        spec=spec,
        stride=stride,
        frames=n,
        length_m=None,
        drift_pct=None,
        drift_deg_per_100m=None,
        ate_m=None,
        gaps=len(odometry.gaps),
        longest_gap_run=gap_run,
        frames_per_s=float(1e3 / ms.mean()),
        registrations=odometry.registrations_per_scan,
        held_out=held_out,
    )
    gt_poses = sequence.ground_truth
    if gt_poses is None:
        logger.info("  no ground truth")
        return row
    truth = Trajectory.from_arrays(stamps, gt_poses[:n], drop_nonfinite=True)
    m = evaluate(estimate, truth)
    drift = (
        "n/a (< 100 m)"
        if m.drift_trans_pct is None or m.drift_rot_deg_per_100m is None
        else f"{m.drift_trans_pct:.2f} % / {m.drift_rot_deg_per_100m:.3f} deg/100 m"
    )
    nees = reference_nees(odometry.results, gt_poses[:n])
    logger.info(
        "  %.0f m: drift %s; ATE %.2f m (Umeyama), %.2f m (first pose); RPE %.3f m; "
        "NEES mean %.2f, median %.2f (3 and 2.37 when calibrated)",
        truth.length_m(),
        drift,
        m.ate_rmse_m,
        m.ate_origin_rmse_m,
        m.rpe_trans_rmse_m,
        nees.mean() if len(nees) else float("nan"),
        np.median(nees) if len(nees) else float("nan"),
    )
    if plot_dir is not None:
        start = between(truth.poses[0], truth.poses)
        suffix = "" if stride == 1 else f"_stride{stride}"
        path = plot_dir / f"odometry_{spec.replace('/', '_')}{suffix}.png"
        plot_trajectories(
            path,
            {"gt": Trajectory(truth.timestamps_ns, start), "odometry": estimate},
            title=f"{label}: odometry, drift {drift}",
        )
    return dataclasses.replace(
        row,
        length_m=truth.length_m(),
        drift_pct=m.drift_trans_pct,
        drift_deg_per_100m=m.drift_rot_deg_per_100m,
        ate_m=m.ate_rmse_m,
    )


def _fmt(value: float | None, digits: int) -> str:
    return "n/a" if value is None else f"{value:.{digits}f}"


def markdown_table(rows: list[SequenceRow]) -> str:
    """The accuracy table (one line per sequence and stride), held-out sequences last."""
    lines = [
        "| sequence | stride | scans | length [m] | drift [%] | drift [deg/100 m] | ATE [m] "
        "| gaps | longest gap run | registrations per scan |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for held_out in (False, True):
        chosen = [r for r in rows if r.held_out == held_out]
        if held_out and chosen:
            lines.append("| **held out** | | | | | | | | | |")
        for r in chosen:
            lines.append(
                f"| `{r.spec}` | {r.stride} | {r.frames} | {_fmt(r.length_m, 0)} "
                f"| {_fmt(r.drift_pct, 2)} | {_fmt(r.drift_deg_per_100m, 2)} "
                f"| {_fmt(r.ate_m, 2)} | {r.gaps} | {r.longest_gap_run} | {r.registrations:.2f} |"
            )
    means = [
        f"stride {stride}: {np.mean([r.registrations for r in rows if r.stride == stride]):.2f}"
        for stride in sorted({r.stride for r in rows})
    ]
    lines += ["", f"Registrations per scan, mean over the drives: {', '.join(means)}."]
    return "\n".join(lines) + "\n"


ACCURACY_SECTION = "Odometry on the synthetic drives"
SPEED_SECTION = "Odometry speed"
"""The sections of docs/benchmarks.md this script writes with `--write-doc`."""


def parse_arguments() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=40, help="frames to register")
    parser.add_argument("--speed", type=float, default=8.0, help="forward speed [m/s]")
    parser.add_argument("--yaw-rate", type=float, default=6.0, help="yaw rate [deg/s]")
    parser.add_argument("--scan", type=Path, default=DEFAULT_SCAN, help="MulRan polar PNG")
    parser.add_argument(
        "--sequence",
        action="append",
        default=[],
        help="run on this sequence (family/sequence or folder) instead; repeatable",
    )
    parser.add_argument(
        "--held-out",
        action="append",
        default=[],
        help="a sequence kept out of tuning: reported separately in the table; repeatable",
    )
    parser.add_argument(
        "--stride",
        action="append",
        type=int,
        default=[],
        help="use every K-th scan (repeatable: one table line per stride; default 1)",
    )
    parser.add_argument("--table", type=Path, default=None, help="write the Markdown table here")
    parser.add_argument("--write-doc", action="store_true", help="write docs/benchmarks.md")
    parser.add_argument("--data-root", type=Path, default=None, help="data root for --sequence")
    parser.add_argument("--max-frames", type=int, default=None, help="frames per --sequence")
    parser.add_argument(
        "--config",
        type=Path,
        default=None,
        help="a radar-slam config file whose odometry section is used (default: the defaults)",
    )
    parser.add_argument(
        "--plot-dir", type=Path, default=None, help="save a trajectory plot per --sequence here"
    )
    return parser.parse_args()


def bench_sequences(args: argparse.Namespace, config: OdometryConfig | None) -> None:
    """The accuracy table over `--sequence` and `--held-out`, one line per stride."""
    specs = [(spec, False) for spec in args.sequence] + [(s, True) for s in args.held_out]
    rows = [
        bench_sequence(spec, args.data_root, args.max_frames, args.plot_dir, stride, held, config)
        for spec, held in specs
        for stride in args.stride or [1]
    ]
    table = markdown_table(rows)
    logger.info("\n%s", table)
    if args.table is not None:
        tmp = args.table.with_name(args.table.name + ".tmp")
        tmp.write_text(table)
        tmp.replace(args.table)
    if args.write_doc:
        from benchmark_doc import update_section

        update_section(ACCURACY_SECTION, table, script="scripts/bench_odometry.py")


def bench_speed(args: argparse.Namespace, config: OdometryConfig | None) -> None:
    """The speed of registering frames rendered from one MulRan scan at a known motion."""
    world = world_scan(args.scan)
    azimuths = mulran_azimuths()
    twist = np.array([args.speed, 0.0, np.deg2rad(args.yaw_rate)])
    step = motion_from_twist(twist, FRAME_PERIOD_NS / NS_PER_S)
    logger.info("rendering %d frames from %s ...", args.frames, args.scan.name)
    truth = [np.zeros(3)]
    for _ in range(args.frames - 1):
        truth.append(compose(truth[-1], step))
    frames = [
        render_frame(world, azimuths, pose, twist, k * FRAME_PERIOD_NS)
        for k, pose in enumerate(truth)
    ]

    odometry = Odometry(config)
    durations = []
    for frame in frames:
        start = time.perf_counter()
        odometry.register(frame)
        durations.append(time.perf_counter() - start)
    ms = np.array(durations[1:]) * 1e3  # the first frame only conditions its scan
    poses = odometry.poses
    errors = between(np.array(truth), poses)
    distance = float(np.sum(np.hypot(*np.diff(np.array(truth)[:, :2], axis=0).T)))
    logger.info(
        "%d frames (%d x %d), pid %d: %.1f ms/frame mean, %.1f median, %.1f p95 -> %.1f frames/s",
        len(frames),
        *world.shape,
        os.getpid(),
        ms.mean(),
        np.median(ms),
        np.percentile(ms, 95),
        1e3 / ms.mean(),
    )
    logger.info(
        "keyframes %d, gaps %d; end error %.3f m over %.1f m (%.2f %%), %.3f deg",
        len(odometry.keyframes),
        len(odometry.gaps),
        np.hypot(*errors[-1, :2]),
        distance,
        100.0 * np.hypot(*errors[-1, :2]) / max(distance, 1e-9),
        np.rad2deg(errors[-1, 2]),
    )
    if args.write_doc:
        from benchmark_doc import update_section

        speed = (
            "| what | mean | p95 | frames/s |\n|---|---|---|---|\n"
            f"| odometry, {len(frames)} frames of {world.shape[0]} x {world.shape[1]}, "
            f"{args.speed:g} m/s, {args.yaw_rate:g} deg/s | {ms.mean():.1f} ms "
            f"| {np.percentile(ms, 95):.1f} ms | {1e3 / ms.mean():.0f} |"
        )
        update_section(SPEED_SECTION, speed, script="scripts/bench_odometry.py")


def main() -> None:
    args = parse_arguments()
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    cv2.setNumThreads(1)  # one core; numpy's FFT is single-threaded already
    config = None if args.config is None else load_config(None, args.config).odometry
    if args.sequence or args.held_out:
        bench_sequences(args, config)
    else:
        bench_speed(args, config)


if __name__ == "__main__":
    main()
