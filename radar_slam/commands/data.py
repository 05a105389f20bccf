"""`radar-slam list` and `radar-slam info`: what datasets are there, and what a sequence holds."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import typer
from numpy.typing import NDArray

from radar_slam.commands.options import DATA_ROOT_OPTION
from radar_slam.datasets import RadarFrame, RadarSequence, data_root, families, open_sequence
from radar_slam.datasets.registry import family_folder
from radar_slam.errors import RadarSlamError
from raplace import NS_PER_MS, NS_PER_S

AZIMUTH_SPACING_TOLERANCE = 0.1
"""Largest deviation of one azimuth step from the mean step, as a fraction of the mean."""
FULL_TURN_TOLERANCE_RAD = np.deg2rad(5.0)
"""How far n_azimuths * mean step may be from 360 deg before the sweep is flagged."""
MAX_SWEEP_PERIODS = 2.0
"""A sweep whose azimuth times span more than this many frame periods is flagged."""


@dataclass(frozen=True)
class SequenceListing:
    """One row of `radar-slam list`.

    Attributes:
        spec: `family/sequence`.
        frames: number of scans (counted from the file list, no scan read).
        has_ground_truth: True when the sequence has GT.
        problem: the error met while opening it, or None.
    """

    spec: str
    frames: int
    has_ground_truth: bool
    problem: str | None = None


def list_sequences(root: Path) -> list[SequenceListing]:
    """Every sequence folder found under `<root>/<family>/`, for each registered family."""
    listings: list[SequenceListing] = []
    for name, family in sorted(families().items()):
        folder = family_folder(root, name)
        if not folder.is_dir():
            continue
        for child in sorted(folder.iterdir()):
            if not ((child.is_dir() or child.is_file()) and family.detect(child)):  # bag files
                continue
            spec = f"{name}/{child.name}"
            try:
                sequence = family.open(child)
                listings.append(
                    SequenceListing(spec, len(sequence), sequence.ground_truth is not None)
                )
            except RadarSlamError as exc:
                listings.append(SequenceListing(spec, 0, False, problem=str(exc)))
    return listings


def frame_problems(frame: RadarFrame, frame_period_ns: float | None) -> list[str]:
    """Consistency checks of one scan; an empty list means it looks right.

    Args:
        frame: the scan.
        frame_period_ns: time between consecutive scans [ns], or None when unknown.
    """
    problems: list[str] = []
    polar, azimuths = frame.polar, frame.azimuths_rad
    if polar.ndim != 2 or polar.dtype != np.uint8:
        problems.append(f"polar is {polar.dtype} with shape {polar.shape}, expected 2-D uint8")
    if azimuths.shape != (polar.shape[0],):
        problems.append(f"{azimuths.shape[0]} azimuths for {polar.shape[0]} polar rows")
    elif azimuths.size > 1:
        steps = np.diff(azimuths)
        mean_step = float(np.mean(steps))
        if np.any(np.abs(steps - mean_step) > AZIMUTH_SPACING_TOLERANCE * abs(mean_step)):
            problems.append("azimuth spacing is not uniform")
        if abs(abs(mean_step) * azimuths.size - 2.0 * np.pi) > FULL_TURN_TOLERANCE_RAD:
            problems.append(
                f"azimuths cover {np.rad2deg(abs(mean_step) * azimuths.size):.1f} deg, not 360"
            )
    times = frame.azimuth_times_ns
    if times is not None:
        if np.any(np.diff(times) < 0):
            problems.append("azimuth times decrease along the sweep")
        span = float(times[-1] - times[0])
        if frame_period_ns is not None and span > MAX_SWEEP_PERIODS * frame_period_ns:
            problems.append(f"sweep lasts {span / NS_PER_MS:.1f} ms, longer than two frame periods")
    if not np.any(polar):
        problems.append("all intensities are zero")
    return problems


def trajectory_length_m(poses: NDArray[np.float64]) -> float:
    """Path length [m] of (N, 3) poses, skipping steps that touch a NaN pose."""
    steps = np.linalg.norm(np.diff(poses[:, :2], axis=0), axis=1)
    return float(np.nansum(steps))


def describe_sequence(sequence: RadarSequence, spec: str) -> list[str]:
    """Human-readable lines describing `sequence` (reads its first scan and its GT)."""
    frame = sequence[0]
    stamps = sequence.timestamps_ns
    n = len(sequence)
    span_s = float(stamps[-1] - stamps[0]) / NS_PER_S
    frame_period_ns = float(np.median(np.diff(stamps))) if n > 1 else None
    lines = [
        f"sequence:          {sequence.family}/{sequence.name}  ({spec})",
        f"sensor:            {frame.sensor}",
        f"frames:            {n}",
        f"azimuths:          {frame.n_azimuths}  "
        f"(step {np.rad2deg(np.mean(np.diff(frame.azimuths_rad))):+.4f} deg, "
        f"first {np.rad2deg(frame.azimuths_rad[0]):+.4f} deg, CCW from forward)",
        f"range bins:        {frame.n_bins}",
        f"range resolution:  {frame.range_resolution_m:.5f} m",
        f"max range:         {frame.max_range_m:.2f} m",
    ]
    if frame.azimuth_times_ns is not None:
        sweep_ms = float(frame.azimuth_times_ns[-1] - frame.azimuth_times_ns[0]) / NS_PER_MS
        lines.append(f"scan duration:     {sweep_ms:.1f} ms (first to last azimuth)")
    else:
        lines.append("scan duration:     unknown (no azimuth times)")
    rate = f"{NS_PER_S / frame_period_ns:.3f} Hz" if frame_period_ns else "n/a (one frame)"
    lines += [
        f"frame rate:        {rate}",
        f"time span:         {span_s:.3f} s  (first scan at {int(stamps[0])} ns)",
    ]
    ground_truth = sequence.ground_truth
    if ground_truth is None:
        lines.append("ground truth:      none")
    else:
        missing = int(np.isnan(ground_truth[:, 0]).sum())
        note = f", {missing} poses NaN (outside the GT or in its outages)" if missing else ""
        lines.append(
            f"ground truth:      {len(ground_truth)} poses, trajectory length "
            f"{trajectory_length_m(ground_truth):.2f} m{note}"
        )
    problems = frame_problems(frame, frame_period_ns)
    lines.append("first scan check:  ok" if not problems else "first scan check:  PROBLEMS")
    lines += [f"  warning: {problem}" for problem in problems]
    return lines


def list_command(data_root_dir: Path | None = DATA_ROOT_OPTION) -> None:
    """Show the dataset families and the sequences found under the data root."""
    root = data_root(data_root_dir)
    typer.echo(f"data root: {root}" + ("" if root.is_dir() else "  (missing)"))
    typer.echo("families:")
    for name, family in sorted(families().items()):
        typer.echo(f"  {name:<10} {family.layout}")
        typer.echo(f"  {'':<10} obtain: {family.obtain}")
    listings = list_sequences(root) if root.is_dir() else []
    typer.echo("sequences:" if listings else "sequences: none found")
    for item in listings:
        if item.problem is not None:
            typer.echo(f"  {item.spec:<40} error: {item.problem}")
        else:
            gt = "GT" if item.has_ground_truth else "no GT"
            typer.echo(f"  {item.spec:<40} {item.frames:>7} frames  {gt}")


def info_command(
    sequence: str = typer.Argument(..., help="family/sequence, or a sequence folder path."),
    data_root_dir: Path | None = DATA_ROOT_OPTION,
) -> None:
    """Read and check the first scan of a sequence; print its geometry, timing and GT."""
    opened = open_sequence(sequence, data_root_dir)
    for line in describe_sequence(opened, sequence):
        typer.echo(line)


def register(app: typer.Typer) -> None:
    """Add `list` and `info` to the CLI app."""
    app.command("list")(list_command)
    app.command("info")(info_command)
