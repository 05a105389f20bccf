"""The summary of a batch: `summary.csv`, `summary.md` and `summary.png` in the batch folder.

One row per (sequence, configuration), columns `SUMMARY_COLUMNS` (see `tasks.BatchRow`): empty
cells (CSV) or "n/a" (Markdown) where a figure does not exist (no ground truth, failed run). Files
are written under a temporary name and renamed into place.
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Sequence
from dataclasses import fields
from pathlib import Path

import numpy as np

from radar_slam.batch.tasks import BatchRow
from radar_slam.plots import TRAJECTORY_COLOURS

SUMMARY_COLUMNS = tuple(f.name for f in fields(BatchRow))
CSV_FILE = "summary.csv"
MARKDOWN_FILE = "summary.md"
PLOT_FILE = "summary.png"
FLOAT_DIGITS = {"scans_per_s": 1, "drift_odometry_pct": 2, "drift_slam_pct": 2}
"""Decimals in the Markdown table (ATE columns: 3)."""
DEFAULT_DIGITS = 3
BAR_HEIGHT = 0.38
ROW_HEIGHT_IN = 0.45
PLOT_WIDTH_IN = 8.0
DPI = 120


def _write_atomic(path: Path, data: bytes) -> None:
    temporary = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    temporary.write_bytes(data)
    temporary.replace(path)


def csv_text(rows: Sequence[BatchRow]) -> str:
    """The table as CSV (full precision; empty cells for missing figures)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(SUMMARY_COLUMNS)
    for row in rows:
        values = row.to_dict()
        writer.writerow(["" if values[c] is None else values[c] for c in SUMMARY_COLUMNS])
    return buffer.getvalue()


def _cell(column: str, value: object) -> str:
    if value is None or value == "":
        return "n/a" if column not in ("folder", "error") else ""
    if isinstance(value, float):
        return f"{value:.{FLOAT_DIGITS.get(column, DEFAULT_DIGITS)}f}"
    return str(value).replace("|", "\\|")


def markdown_text(rows: Sequence[BatchRow]) -> str:
    """The table as GitHub Markdown."""
    lines = [
        "| " + " | ".join(SUMMARY_COLUMNS) + " |",
        "|" + "---|" * len(SUMMARY_COLUMNS),
    ]
    for row in rows:
        values = row.to_dict()
        lines.append("| " + " | ".join(_cell(c, values[c]) for c in SUMMARY_COLUMNS) + " |")
    return "\n".join(lines) + "\n"


def plot_summary(path: Path, rows: Sequence[BatchRow]) -> None:
    """Horizontal bars of odometry and SLAM ATE per run; failed runs (or runs without ground
    truth) are labelled instead of drawn."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    labels = [f"{r.sequence} [{r.config}]" for r in rows]
    odometry = np.array([np.nan if r.ate_odometry_m is None else r.ate_odometry_m for r in rows])
    slam = np.array([np.nan if r.ate_slam_m is None else r.ate_slam_m for r in rows])
    y = np.arange(len(rows), dtype=np.float64)
    figure = Figure(figsize=(PLOT_WIDTH_IN, 1.5 + ROW_HEIGHT_IN * len(rows)), dpi=DPI)
    FigureCanvasAgg(figure)
    axes = figure.add_subplot()
    axes.barh(
        y - BAR_HEIGHT / 2,
        odometry,
        BAR_HEIGHT,
        label="odometry",
        color=TRAJECTORY_COLOURS["odometry"],
    )
    axes.barh(y + BAR_HEIGHT / 2, slam, BAR_HEIGHT, label="SLAM", color=TRAJECTORY_COLOURS["slam"])
    for n, row in enumerate(rows):
        if not np.isfinite(slam[n]):
            note = "failed" if not row.ok else "no ground truth"
            axes.text(0.0, y[n], f" {note}", va="center", color="tab:red")
    axes.set_yticks(y, labels)
    axes.invert_yaxis()
    axes.set_xlabel("ATE RMSE [m] (Umeyama-aligned)")
    axes.set_title("radar-slam batch: ATE per run")
    axes.legend(loc="lower right")
    figure.tight_layout()
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png")
    _write_atomic(path, buffer.getvalue())


def write_summary(folder: Path, rows: Sequence[BatchRow]) -> list[Path]:
    """Write summary.csv, summary.md and summary.png into `folder`; returns their paths."""
    folder = Path(folder)
    paths = [folder / CSV_FILE, folder / MARKDOWN_FILE, folder / PLOT_FILE]
    _write_atomic(paths[0], csv_text(rows).encode())
    _write_atomic(paths[1], markdown_text(rows).encode())
    plot_summary(paths[2], rows)
    return paths
