"""`radar-slam eval EST [EST ...] GT`: accuracy of one or more trajectories against ground truth."""

from __future__ import annotations

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
from radar_slam.outputs import json_text
from radar_slam.results import check_output_file, write_text_atomically
from radar_slam.trajectory import Trajectory, detect_format, read_trajectory
from raplace.units import NS_PER_MS

MISSING = "n/a"
TABLE_COLUMNS = (
    ("poses", "poses_matched", "{:d}"),
    ("ATE [m]", "ate_rmse_m", "{:.3f}"),
    ("ATE origin [m]", "ate_origin_rmse_m", "{:.3f}"),
    ("RPE [m]", "rpe_trans_rmse_m", "{:.4f}"),
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


def eval_command(
    trajectories: list[Path] = typer.Argument(
        ...,
        help="One or more estimated trajectories, then the ground truth (always last).",
        exists=True,
        dir_okay=False,
        readable=True,
    ),
    fmt: TrajectoryFormat = typer.Option(
        TrajectoryFormat.auto,
        "--format",
        help="File format: tum (t x y z qx qy qz qw), kitti (3x4 row-major), auto by columns.",
    ),
    json_path: Path | None = typer.Option(
        None, "--json", help="Also write the metrics as JSON to this file.", dir_okay=False
    ),
    force: bool = typer.Option(False, "--force", help="Overwrite an existing --json file."),
    rpe_delta: int = typer.Option(
        DEFAULT_RPE_DELTA, "--rpe-delta", min=1, help="RPE pose-pair distance, in frames."
    ),
    max_diff_ms: float = typer.Option(
        DEFAULT_MAX_TIME_DIFF_NS / NS_PER_MS,
        "--max-diff-ms",
        min=0.0,
        max=MAX_DIFF_MS,
        help="TUM association tolerance between timestamps, in milliseconds.",
    ),
) -> None:
    """Compare trajectories with ground truth: ATE (aligned and first-pose), RPE, KITTI drift.

    Arguments: EST [EST ...] GT, the ground truth last. TUM files are associated by timestamp,
    KITTI files by index (equal pose counts needed).
    """
    if len(trajectories) < 2:
        raise typer.BadParameter(
            "give at least one estimate and the ground truth", param_hint="TRAJECTORIES"
        )
    if json_path is not None:
        check_output_file(json_path, "--json", force)
    *est_paths, gt_path = trajectories
    formats = [
        detect_format(p) if fmt == TrajectoryFormat.auto else fmt.value for p in trajectories
    ]
    association: Association = "index" if "kitti" in formats else "timestamp"
    gt = read_trajectory(gt_path, formats[-1])
    results: dict[str, TrajectoryMetrics] = {}
    for name, path, path_fmt in zip(
        trajectory_names(est_paths), est_paths, formats[:-1], strict=True
    ):
        est: Trajectory = read_trajectory(path, path_fmt)
        try:
            results[name] = evaluate(
                est,
                gt,
                by=association,
                max_diff_ns=round(max_diff_ms * NS_PER_MS),
                rpe_delta=rpe_delta,
            )
        except TrajectoryError as exc:  # name the files (issue 12)
            raise TrajectoryError(f"{path} against {gt_path}: {exc}") from None
    typer.echo(
        f"ground truth: {gt_path} ({len(gt)} poses, {gt.length_m():.1f} m); "
        f"association by {association}; RPE over {rpe_delta} frame(s)"
    )
    typer.echo(format_table(results))
    if any(m.drift_trans_pct is None for m in results.values()):
        typer.echo(
            "note: drift needs a ground-truth path of at least "
            f"{min(KITTI_SEGMENT_LENGTHS_M):.0f} m between matched poses; shown as n/a"
        )
    if json_path is not None:
        write_text_atomically(json_path, json_text(metrics_json(results)))
        typer.echo(f"wrote {json_path}")


def register(app: typer.Typer) -> None:
    """Add the `eval` command to `app`."""
    app.command("eval")(eval_command)
