"""`radar-slam eval EST [EST ...] GT`: accuracy of one or more trajectories against ground truth."""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from pathlib import Path

import typer

from radar_slam.errors import TrajectoryError
from radar_slam.evaluation.metrics import (
    DEFAULT_MAX_TIME_DIFF_NS,
    DEFAULT_RPE_DELTA,
    KITTI_SEGMENT_LENGTHS_M,
    Association,
    TrajectoryMetrics,
    evaluate,
)
from radar_slam.evaluation.time_offset import (
    TimeOffset,
    estimate_time_offset,
    ground_truth_with_offset,
)
from radar_slam.outputs import json_text
from radar_slam.results import check_output_file, write_text_atomically
from radar_slam.trajectory import Trajectory, detect_format, read_trajectory
from raplace import NS_PER_MS

MISSING = "n/a"
TABLE_COLUMNS = (
    ("poses", "poses_matched", "{:d}"),
    ("ATE [m]", "ate_rmse_m", "{:.3f}"),
    ("ATE origin [m]", "ate_origin_rmse_m", "{:.3f}"),
    ("RPE [m]", "rpe_trans_rmse_m", "{:.4f}"),
    ("end [%]", "end_point_error_pct", "{:.2f}"),
    ("drift [%]", "drift_trans_pct", "{:.2f}"),
    ("drift [deg/100m]", "drift_rot_deg_per_100m", "{:.3f}"),
)


class TrajectoryFormat(str, Enum):
    """Trajectory file format; "auto" decides per file by its column count (8 TUM, 12 KITTI)."""

    auto = "auto"
    tum = "tum"
    kitti = "kitti"


def trajectory_names(paths: list[Path]) -> list[str]:
    """Row names: file stems, with the parent folder added where stems repeat."""
    stems = [p.stem for p in paths]
    names = [f"{p.parent.name}/{p.stem}" if stems.count(p.stem) > 1 else p.stem for p in paths]
    return [str(p) if names.count(n) > 1 else n for p, n in zip(paths, names, strict=True)]


def format_table(results: dict[str, TrajectoryMetrics]) -> str:
    """A plain-text table, one row per named result; None shows as n/a."""
    header = ["trajectory", *(title for title, _, _ in TABLE_COLUMNS)]
    rows = [header]
    for name, metrics in results.items():
        values = metrics.to_dict()
        cells = [name]
        for _, key, spec in TABLE_COLUMNS:
            value = values[key]
            cells.append(MISSING if value is None else spec.format(value))
        rows.append(cells)
    widths = [max(len(row[i]) for row in rows) for i in range(len(header))]
    lines = [
        "  ".join(
            cell.ljust(width) if i == 0 else cell.rjust(width)
            for i, (cell, width) in enumerate(zip(row, widths, strict=True))
        )
        for row in rows
    ]
    lines.insert(1, "  ".join("-" * width for width in widths))
    return "\n".join(lines)


def metrics_json(results: dict[str, TrajectoryMetrics]) -> dict[str, object]:
    """Flat metric dict for one result; {name: metrics} for several."""
    if len(results) == 1:
        return dict(next(iter(results.values())).to_dict())
    return {name: metrics.to_dict() for name, metrics in results.items()}


MAX_DIFF_MS = 1e9
"""Upper bound of --max-diff-ms (rejects inf, which has no nanosecond count)."""
MAX_GT_ACCURACY_M = 1e3
"""Upper bound of --gt-accuracy (rejects inf)."""


TRAJECTORIES_ARGUMENT = typer.Argument(
    ...,
    help="One or more estimated trajectories, then the ground truth (always last).",
    exists=True,
    dir_okay=False,
    readable=True,
)
FORMAT_OPTION = typer.Option(
    TrajectoryFormat.auto,
    "--format",
    help="File format: tum (t x y z qx qy qz qw), kitti (3x4 row-major), auto by columns.",
)
MAX_DIFF_OPTION = typer.Option(
    DEFAULT_MAX_TIME_DIFF_NS / NS_PER_MS,
    "--max-diff-ms",
    min=0.0,
    max=MAX_DIFF_MS,
    help="TUM association tolerance between timestamps, in milliseconds.",
)
ESTIMATE_OFFSET_OPTION = typer.Option(
    False,
    "--estimate-offset",
    help="Estimate the GT's clock offset from the first estimate's speed profile, print "
    "it with its uncertainty, and add rows scored with it applied (TUM files only).",
)
GT_OFFSET_OPTION = typer.Option(
    None,
    "--gt-offset",
    help="A known GT clock offset \\[s] (GT minus estimate): add rows scored with it applied.",
)
GT_ACCURACY_OPTION = typer.Option(
    0.0,
    "--gt-accuracy",
    min=0.0,
    max=MAX_GT_ACCURACY_M,
    help="Position accuracy of the GT \\[m]: drift then uses only segments long enough for "
    "it (2 for GNSS without RTK: 400-800 m).",
)


@dataclass(frozen=True)
class EvalInputs:
    """The files of one `eval`, read.

    Attributes:
        gt_path, gt: the ground truth's file and trajectory.
        estimates: row name -> (file, trajectory) of each estimate, in the order given.
        association: "index" when any file is KITTI, else "timestamp".
    """

    gt_path: Path
    gt: Trajectory
    estimates: dict[str, tuple[Path, Trajectory]]
    association: Association


def eval_command(
    trajectories: list[Path] = TRAJECTORIES_ARGUMENT,
    fmt: TrajectoryFormat = FORMAT_OPTION,
    json_path: Path | None = typer.Option(
        None, "--json", help="Also write the metrics as JSON to this file.", dir_okay=False
    ),
    force: bool = typer.Option(False, "--force", help="Overwrite an existing --json file."),
    rpe_delta: int = typer.Option(
        DEFAULT_RPE_DELTA, "--rpe-delta", min=1, help="RPE pose-pair distance, in frames."
    ),
    max_diff_ms: float = MAX_DIFF_OPTION,
    estimate_offset: bool = ESTIMATE_OFFSET_OPTION,
    gt_offset_s: float | None = GT_OFFSET_OPTION,
    gt_accuracy_m: float = GT_ACCURACY_OPTION,
) -> None:
    """Compare trajectories with ground truth: ATE (aligned and first-pose), RPE, end-point
    error, KITTI drift.

    Arguments: EST [EST ...] GT, the ground truth last. TUM files are associated by timestamp,
    KITTI files by index (equal pose counts needed). A GT on another clock (GNSS) can be read
    through a clock offset, estimated (--estimate-offset) or given (--gt-offset); both sets of
    rows are shown, labelled.
    """
    if len(trajectories) < 2:
        raise typer.BadParameter(
            "give at least one estimate and the ground truth", param_hint="TRAJECTORIES"
        )
    if json_path is not None:
        check_output_file(json_path, "--json", force)
    inputs = read_inputs(trajectories, fmt, estimate_offset or gt_offset_s is not None)
    first = next(iter(inputs.estimates.values()))[1]
    offset = _clock_offset(first, inputs.gt, estimate_offset, gt_offset_s)
    max_diff_ns = round(max_diff_ms * NS_PER_MS)
    results = score(inputs, offset, max_diff_ns, rpe_delta, gt_accuracy_m)
    typer.echo(
        f"ground truth: {inputs.gt_path} ({len(inputs.gt)} poses, {inputs.gt.length_m():.1f} m); "
        f"association by {inputs.association}; RPE over {rpe_delta} frame(s)"
    )
    if offset is not None:
        typer.echo(_offset_line(offset, estimate_offset))
    typer.echo(report_text(results, gt_accuracy_m))
    if json_path is not None:
        write_text_atomically(json_path, json_text(metrics_json(results)))
        typer.echo(f"wrote {json_path}")


def read_inputs(trajectories: list[Path], fmt: TrajectoryFormat, offset: bool) -> EvalInputs:
    """Read the estimates and the ground truth (the last of `trajectories`) in `fmt`.

    Raises:
        typer.BadParameter: a clock `offset` is asked for KITTI files (no timestamps).
    """
    *est_paths, gt_path = trajectories
    formats = [
        detect_format(p) if fmt == TrajectoryFormat.auto else fmt.value for p in trajectories
    ]
    association: Association = "index" if "kitti" in formats else "timestamp"
    if association == "index" and offset:
        raise typer.BadParameter(
            "a clock offset needs timestamps: give TUM files", param_hint="--estimate-offset"
        )
    gt = read_trajectory(gt_path, formats[-1])
    estimates = {
        name: (path, read_trajectory(path, path_fmt))
        for name, path, path_fmt in zip(
            trajectory_names(est_paths), est_paths, formats[:-1], strict=True
        )
    }
    return EvalInputs(gt_path, gt, estimates, association)


def score(
    inputs: EvalInputs,
    offset: TimeOffset | None,
    max_diff_ns: int,
    rpe_delta: int,
    gt_accuracy_m: float,
) -> dict[str, TrajectoryMetrics]:
    """Each estimate's metrics against the GT, and against the GT read through `offset` too
    (a labelled row), in the order given.

    Raises:
        TrajectoryError: an estimate cannot be scored (names its file and the GT's).
    """
    results: dict[str, TrajectoryMetrics] = {}
    for name, (path, est) in inputs.estimates.items():
        references = {name: inputs.gt}
        if offset is not None:
            shifted = ground_truth_with_offset(inputs.gt, est.timestamps_ns, offset.offset_s)
            references[f"{name} (GT offset {offset.offset_s:+.3f} s)"] = shifted
        for row, reference in references.items():
            try:
                results[row] = evaluate(
                    est,
                    reference,
                    by=inputs.association,
                    max_diff_ns=max_diff_ns,
                    rpe_delta=rpe_delta,
                    gt_accuracy_m=gt_accuracy_m,
                )
            except TrajectoryError as exc:  # name the files
                raise TrajectoryError(f"{path} against {inputs.gt_path}: {exc}") from None
    return results


def report_text(results: dict[str, TrajectoryMetrics], gt_accuracy_m: float) -> str:
    """The table of `results`, the drift's segment lengths and, when some drift is missing,
    why (no trailing newline)."""
    shortest = next(iter(results.values())).drift_min_segment_m
    lines = [
        format_table(results),
        f"drift over KITTI segments of {shortest:.0f}-{max(KITTI_SEGMENT_LENGTHS_M):.0f} m"
        + ("" if gt_accuracy_m == 0 else f" (GT accuracy {gt_accuracy_m:g} m)"),
    ]
    if any(m.drift_trans_pct is None for m in results.values()):
        lines.append(
            f"note: drift needs a ground-truth path of at least {shortest:.0f} m between "
            "matched poses; shown as n/a"
        )
    return "\n".join(lines)


def _clock_offset(
    estimate: Trajectory, gt: Trajectory, estimate_offset: bool, given_s: float | None
) -> TimeOffset | None:
    """The offset to read the GT through: estimated, given, or None."""
    if given_s is not None:
        if not math.isfinite(given_s):
            raise typer.BadParameter(f"must be finite, got {given_s}", param_hint="--gt-offset")
        return TimeOffset(given_s, 0.0, float("nan"), 0.0, (float("nan"), float("nan")))
    if not estimate_offset:
        return None
    offset = estimate_time_offset(estimate, gt)
    if offset is None:
        raise TrajectoryError(
            "cannot estimate the GT clock offset: the trajectories share less than "
            "20 s of driving, or the speed barely varies"
        )
    return offset


def _offset_line(offset: TimeOffset, estimated: bool) -> str:
    """One line saying which clock offset the labelled rows use."""
    if not estimated:
        return f"GT clock offset {offset.offset_s:+.3f} s (given; GT minus estimate)"
    first, second = offset.halves_s
    return (
        f"GT clock offset {offset.offset_s:+.3f} +- {offset.sigma_s:.3f} s (GT minus estimate, "
        f"from the speed profiles; correlation {offset.correlation:.3f}; halves of the drive "
        f"{first:+.3f} and {second:+.3f} s)"
    )


def register(app: typer.Typer) -> None:
    """Add the `eval` command to `app`."""
    app.command("eval")(eval_command)
