"""Sensitivity of RaPlace and Scan Context distances to rotation and translation (a figure).

Takes one real scan (the partial Oxford Radar RobotCar sequence in ../shared/data by default,
or any sequence the project can open), re-samples it as seen from moved sensor poses, and plots
each method's distance between the original and the moved scan against its loop threshold, as in
the sensitivity figure of the RaPlace paper:

- rotation: yaw 0..350 deg in steps of 10 deg (at the same position);
- translation: 0..30 m in steps of 2 m, forward (x) and sideways (y), without rotation.

The moved scan is re-sampled from the polar scan itself (each output sample (azimuth, range) of
the moved sensor is looked up in the original polar image, bilinearly), and both the reference
and the moved scans are cropped to the original range minus the largest translation, so that no
empty border ever enters a scan. Both scans go through the same re-sampling.

Usage: python scripts/pr_sensitivity.py [--sequence SPEC] [--frame 0] [--out PNG]
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import cv2
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import NDArray

from radar_slam.datasets import RadarFrame, RadarSequence, open_sequence
from radar_slam.placerec import method_runs, with_exclusion
from raplace import ExclusionConfig, RaPlaceConfig

log = logging.getLogger("pr_sensitivity")

PROJECT = Path(__file__).resolve().parents[1]
DEFAULT_SEQUENCE = PROJECT.parent / "shared" / "data" / "oxford" / "2019-01-10-14-36-48-partial"
DEFAULT_OUT = PROJECT / "docs" / "pr_sensitivity.png"
ROTATION_STEP_DEG = 10.0
FULL_TURN_DEG = 360.0
TRANSLATION_STEP_M = 2.0
MAX_TRANSLATION_M = 30.0
REVISIT_CRITERION_M = 20.0
OTHER_PLACE_M = 50.0
"""Frames at least this far from the scan (by ground truth) are other places."""
MAX_OTHER_PLACES = 60
METHOD_STYLE = {
    "raplace": ("RaPlace", "tab:blue"),
    "scancontext": ("Scan Context", "tab:orange"),
}
FIGURE_SIZE_IN = (11.0, 4.0)
DPI = 150


def moved_scan(
    frame: RadarFrame, pose: tuple[float, float, float], max_range_m: float
) -> RadarFrame:
    """The scan a sensor at `pose` (x, y, yaw in the original sensor frame; m, m, rad) would see,
    re-sampled from the original polar scan (bilinear, azimuth wrapping around).

    The output has the original azimuths and range resolution, and bins up to `max_range_m`;
    every output sample must lie within the original range (max_range_m + |(x, y)| <= original
    range), so no sample falls outside the scan.
    """
    res = frame.range_resolution_m
    n_azimuths = frame.n_azimuths
    if max_range_m + np.hypot(pose[0], pose[1]) > frame.max_range_m:
        raise ValueError(f"pose {pose} moves the {max_range_m} m disc outside the scan")
    azimuths = frame.azimuths_rad
    ranges = (np.arange(int(max_range_m / res)) + 0.5) * res
    local_x = ranges[None, :] * np.cos(azimuths)[:, None]
    local_y = ranges[None, :] * np.sin(azimuths)[:, None]
    c, s = np.cos(pose[2]), np.sin(pose[2])
    x = pose[0] + c * local_x - s * local_y
    y = pose[1] + s * local_x + c * local_y
    # Rows are equally spaced in azimuth (one turn per n_azimuths), in the scan's own direction.
    step = np.sign(azimuths[1] - azimuths[0]) * 2.0 * np.pi / n_azimuths
    rows = np.mod((np.arctan2(y, x) - azimuths[0]) / step, n_azimuths)
    cols = np.hypot(x, y) / res - 0.5
    polar = cv2.remap(
        frame.polar.astype(np.float32),
        cols.astype(np.float32),
        rows.astype(np.float32),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_WRAP,
    )
    return RadarFrame(
        timestamp_ns=frame.timestamp_ns,
        polar=np.clip(np.rint(polar), 0, 255).astype(np.uint8),
        azimuths_rad=azimuths,
        range_resolution_m=res,
        sensor=frame.sensor,
    )


def distances(
    frame: RadarFrame, poses: NDArray[np.float64], max_range_m: float, cfg: RaPlaceConfig
) -> dict[str, NDArray[np.float64]]:
    """Each method's distance between the scan at the origin and the scan at each pose (n,)."""
    runs = method_runs(METHOD_STYLE, with_exclusion(cfg, ExclusionConfig(0, 0.0)))
    reference = moved_scan(frame, (0.0, 0.0, 0.0), max_range_m)
    for run in runs:
        run.add(0, reference)
    for index, pose in enumerate(poses):
        scan = moved_scan(frame, (float(pose[0]), float(pose[1]), float(pose[2])), max_range_m)
        for run in runs:
            run.query(index, scan)
    return {run.method: np.asarray(run.distance) for run in runs}


def other_places(sequence: RadarSequence, frame_index: int) -> list[int]:
    """Up to MAX_OTHER_PLACES frames (evenly spread) at least OTHER_PLACE_M from the frame."""
    gt = sequence.ground_truth
    if gt is None:
        return []
    gap = np.linalg.norm(gt[:, :2] - gt[frame_index, :2], axis=1)
    far = np.flatnonzero(gap >= OTHER_PLACE_M)
    if len(far) > MAX_OTHER_PLACES:
        far = far[np.linspace(0, len(far) - 1, MAX_OTHER_PLACES).round().astype(int)]
    return far.tolist()


def closest_other_place(
    sequence: RadarSequence, frame_index: int, max_range_m: float, cfg: RaPlaceConfig
) -> dict[str, float] | None:
    """Each method's smallest distance from the scan to the scans of other places (the hardest
    negative), or None when the sequence has no ground truth or no other place."""
    indices = other_places(sequence, frame_index)
    if not indices:
        return None
    runs = method_runs(METHOD_STYLE, with_exclusion(cfg, ExclusionConfig(0, 0.0)))
    reference = moved_scan(sequence[frame_index], (0.0, 0.0, 0.0), max_range_m)
    for run in runs:
        run.add(0, reference)
    for index in indices:
        scan = moved_scan(sequence[index], (0.0, 0.0, 0.0), max_range_m)
        for run in runs:
            run.query(index, scan)
    return {run.method: float(np.min(run.distance)) for run in runs}


def plot(
    path: Path,
    angles_deg: NDArray[np.float64],
    rotation: dict[str, NDArray[np.float64]],
    shifts_m: NDArray[np.float64],
    forward: dict[str, NDArray[np.float64]],
    sideways: dict[str, NDArray[np.float64]],
    thresholds: dict[str, float],
    other: dict[str, float] | None,
    title: str,
) -> None:
    figure = Figure(figsize=FIGURE_SIZE_IN, dpi=DPI)
    FigureCanvasAgg(figure)
    rot_axes, shift_axes = figure.subplots(1, 2, sharey=True)
    for method, (label, colour) in METHOD_STYLE.items():
        rot_axes.plot(angles_deg, rotation[method], "o-", color=colour, label=label, markersize=3)
        shift_axes.plot(
            shifts_m, forward[method], "o-", color=colour, markersize=3, label=f"{label}, along x"
        )
        shift_axes.plot(
            shifts_m, sideways[method], "s--", color=colour, markersize=3, label=f"{label}, along y"
        )
        for axes in (rot_axes, shift_axes):
            show = axes is rot_axes  # label the reference lines once
            axes.axhline(
                thresholds[method],
                color=colour,
                linestyle=":",
                linewidth=1.2,
                label=f"{label} loop threshold" if show else None,
            )
            if other is not None:
                axes.axhline(
                    other[method],
                    color=colour,
                    linestyle="-.",
                    linewidth=1.0,
                    label=f"{label}: closest place >= {OTHER_PLACE_M:.0f} m away" if show else None,
                )
    shift_axes.axvline(REVISIT_CRITERION_M, color="grey", linewidth=0.8)
    shift_axes.text(REVISIT_CRITERION_M, 0.02, " 20 m criterion", color="grey", fontsize=8)
    rot_axes.set_xlabel("rotation [deg]")
    rot_axes.set_ylabel("distance to the original scan")
    rot_axes.set_xticks(np.arange(0.0, FULL_TURN_DEG + 1, 45.0))
    shift_axes.set_xlabel("translation [m]")
    for axes in (rot_axes, shift_axes):
        axes.grid(True, linewidth=0.3)
        axes.set_ylim(bottom=0.0)
    rot_axes.legend(loc="center right", fontsize=7)
    shift_axes.legend(loc="upper left", fontsize=7)
    figure.suptitle(title, fontsize=10)
    figure.savefig(path, bbox_inches="tight")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sequence", default=str(DEFAULT_SEQUENCE), help="sequence spec or folder")
    parser.add_argument("--data-root", default=None, help="data root for family/sequence specs")
    parser.add_argument("--frame", type=int, default=0, help="index of the scan used")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="PNG written")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")

    sequence = open_sequence(args.sequence, args.data_root)
    frame = sequence[args.frame]
    max_range_m = frame.max_range_m - MAX_TRANSLATION_M - 1.0
    cfg = RaPlaceConfig()
    angles_deg = np.arange(0.0, FULL_TURN_DEG, ROTATION_STEP_DEG)
    shifts_m = np.arange(0.0, MAX_TRANSLATION_M + 0.5 * TRANSLATION_STEP_M, TRANSLATION_STEP_M)
    zeros = np.zeros_like(shifts_m)
    rotation = distances(
        frame,
        np.stack([np.zeros_like(angles_deg), np.zeros_like(angles_deg), np.deg2rad(angles_deg)], 1),
        max_range_m,
        cfg,
    )
    forward = distances(frame, np.stack([shifts_m, zeros, zeros], 1), max_range_m, cfg)
    sideways = distances(frame, np.stack([zeros, shifts_m, zeros], 1), max_range_m, cfg)
    thresholds = {
        "raplace": cfg.retrieval.loop_threshold,
        "scancontext": cfg.scancontext.loop_threshold,
    }
    other = closest_other_place(sequence, args.frame, max_range_m, cfg)
    for method in METHOD_STYLE:
        if other is not None:
            log.info("%-12s closest other place: %.3f", method, other[method])
        log.info(
            "%-12s rotation: max %.3f; translation x: %s; y: %s (threshold %.2f)",
            method,
            rotation[method].max(),
            np.array2string(forward[method], precision=3),
            np.array2string(sideways[method], precision=3),
            thresholds[method],
        )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    title = (
        f"Sensitivity of the place distance: {sequence.family}/{sequence.name} scan {args.frame} "
        f"re-sampled from moved poses ({max_range_m:.0f} m range)"
    )
    plot(args.out, angles_deg, rotation, shifts_m, forward, sideways, thresholds, other, title)
    log.info("wrote %s", args.out)


if __name__ == "__main__":
    main()
