"""Writers of `radar-slam localize` results and the `map info` text.

A localisation result folder holds:

    config.yaml        the settings used
    localization.tum   the pose in the map frame of every localised scan (TUM)
    localization.csv   one row per scan (LOCALIZATION_CSV_COLUMNS)
    localization_boreas.txt  the localised scans in the Boreas localisation benchmark's form
                       (`radar_slam.maps.boreas`)
    metrics.json       `LocalizationMetrics` (when the sequence and the map have GT)
    summary.txt        a short human summary
    localization.png   the map's keyframes with the localised trajectory, lost scans marked

`radar-slam run SEQ --map MAP` adds intersession_loops.csv and multisession.json to the SLAM
result folder (its slam.tum/.kitti are then in MAP's frame).
"""

from __future__ import annotations

import csv
import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from radar_slam.maps.boreas import BOREAS_FILE, write_boreas
from radar_slam.maps.evaluate import LocalizationMetrics
from radar_slam.maps.format import Map, map_bytes
from radar_slam.maps.localizer import Localization
from radar_slam.maps.session import JoinedSession
from radar_slam.maps.session import summary as joined_summary
from radar_slam.outputs import write_json, write_loops_csv
from radar_slam.trajectory import Trajectory, write_tum

log = logging.getLogger(__name__)

LOCALIZATION_CSV_COLUMNS = (
    "scan_ns", "status", "map_key", "x", "y", "yaw", "quality", "sigma_m",
    "rel_x", "rel_y", "rel_yaw", "cov_xx", "cov_xy", "cov_xyaw", "cov_yy", "cov_yyaw", "cov_yawyaw",
)  # fmt: skip
"""localization.csv header: scan time [ns]; relocalised / tracked / lost; the map keyframe index
of the latest fix (-1 when lost); the pose T_map_radar (x, y [m], yaw [rad]); quality: the
peak-to-noise ratio of that fix's registration to the map (dimensionless, never below
`loop_closure.verification.min_refined_quality`, higher is sharper); sigma_m: the standard
deviation of the position along its least certain axis [m], which grows with the travel since
the fix (threshold it for a position tolerance); the pose relative to the map keyframe,
T_keyframe_radar (rel_x, rel_y [m], rel_yaw [rad]: the Boreas localisation benchmark's form);
and the upper triangle of its 3x3 covariance in the radar frame (x, y [m], yaw [rad]). Every
column after status is empty when lost, but map_key (-1) and quality (0)."""
TUM_FILE = "localization.tum"
CSV_FILE = "localization.csv"
PLOT_FILE = "localization.png"
INTERSESSION_LOOPS_FILE = "intersession_loops.csv"
"""`run --map`: the inter-session loop proposals (loops.csv columns; match = map keyframe)."""
MULTISESSION_FILE = "multisession.json"
"""`run --map`: met_map, inter-session loops proposed/accepted/true, ATE in the map frame."""
FIGURE_SIZE_IN = (8.0, 8.0)
DPI = 120


def localized_trajectory(fixes: Sequence[Localization]) -> Trajectory:
    """The localised scans' poses T_map_radar at their timestamps."""
    kept = [f for f in fixes if f.localised]
    stamps = np.array([f.timestamp_ns for f in kept], dtype=np.int64)
    return Trajectory(stamps, np.array([f.pose for f in kept], dtype=np.float64).reshape(-1, 3))


def write_localization_csv(path: Path, fixes: Sequence[Localization]) -> None:
    """localization.csv: one row per scan."""
    with Path(path).open("w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(LOCALIZATION_CSV_COLUMNS)
        for f in fixes:
            writer.writerow(
                [f.timestamp_ns, f.status, f.map_key, *_pose_cells(f), f"{f.quality:.2f}"]
                + _uncertainty_cells(f)
            )


def _pose_cells(f: Localization) -> list[str]:
    return [repr(float(v)) for v in f.pose] if f.localised else ["", "", ""]


def _uncertainty_cells(f: Localization) -> list[str]:
    """sigma_m, the relative pose and the covariance's upper triangle (empty when lost)."""
    if not f.localised:
        return [""] * (len(LOCALIZATION_CSV_COLUMNS) - 7)
    upper = f.covariance[np.triu_indices(3)]
    return [f"{f.sigma_m:.3g}", *(repr(float(v)) for v in f.relative), *(f"{v:.6g}" for v in upper)]


def plot_localization(path: Path, m: Map, fixes: Sequence[Localization], title: str) -> None:
    """Top view in the map frame: keyframes (grey dots), the localised trajectory, the
    relocalisations (green circles), and lost scans (red crosses at the last localised
    position: a lost scan has no pose)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=FIGURE_SIZE_IN, dpi=DPI)
    FigureCanvasAgg(figure)
    axes = figure.add_subplot()
    poses = m.poses
    axes.scatter(poses[:, 0], poses[:, 1], s=4, color="0.6", label=f"map keyframes ({len(m)})")
    xy = np.array([f.pose[:2] if f.localised else (np.nan, np.nan) for f in fixes]).reshape(-1, 2)
    axes.plot(xy[:, 0], xy[:, 1], linewidth=1.2, color="tab:blue", label="localised")
    relocalised = np.array([f.status == "relocalised" for f in fixes], dtype=bool)
    if relocalised.any():
        axes.scatter(
            xy[relocalised, 0],
            xy[relocalised, 1],
            marker="o",
            s=40,
            facecolors="none",
            color="tab:green",
            label="relocalised",
        )
    last = np.full(2, np.nan)
    marks = []
    for f in fixes:
        if f.localised:
            last = f.pose[:2]
        elif np.all(np.isfinite(last)):
            marks.append(last)
    if marks:
        axes.scatter(
            np.array(marks)[:, 0],
            np.array(marks)[:, 1],
            marker="x",
            s=30,
            color="tab:red",
            label=f"lost after localisation ({len(marks)} scans)",
        )
    axes.set_aspect("equal", adjustable="datalim")
    axes.set_xlabel("x (map frame) [m]")
    axes.set_ylabel("y (map frame) [m]")
    axes.grid(True, linewidth=0.3)
    axes.set_title(title)
    axes.legend(loc="best")
    figure.savefig(path, bbox_inches="tight")
    log.info("wrote %s", path)


def localization_summary(
    sequence: str,
    fixes: Sequence[Localization],
    seconds: float,
    metrics: LocalizationMetrics | None,
) -> str:
    """A few lines for humans."""
    counts = {s: sum(f.status == s for f in fixes) for s in ("relocalised", "tracked", "lost")}
    rate = len(fixes) / seconds if seconds > 0 else 0.0
    lines = [
        f"sequence      {sequence}: {len(fixes)} scans in {seconds:.1f} s ({rate:.1f} scans/s)",
        f"status        {counts['relocalised']} relocalised, {counts['tracked']} tracked, "
        f"{counts['lost']} lost",
    ]
    if metrics is None:
        lines.append("accuracy      n/a (the sequence or the map has no ground truth)")
    else:
        correct = metrics.near_route_correct
        lines += [
            f"near route    {metrics.near_route_scans} scans within 10 m of the map's route, "
            + ("n/a" if correct is None else f"{100 * correct:.1f} % localised within 1 m, 2 deg"),
            f"errors        longitudinal {_m(metrics.longitudinal_rmse_m)}, lateral "
            f"{_m(metrics.lateral_rmse_m)} RMS, max {_m(metrics.max_error_m)}; "
            f"{metrics.wrong_localised} scans > 5 m off, "
            f"{metrics.wrong_relocalisations} wrong relocalisations",
        ]
    return "\n".join(lines) + "\n"


def _m(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.3f} m"


def write_localization(
    folder: Path,
    sequence: str,
    m: Map,
    fixes: Sequence[Localization],
    seconds: float,
    metrics: LocalizationMetrics | None,
) -> None:
    """localization.tum/.csv/.png, localization_boreas.txt, summary.txt and (with metrics)
    metrics.json into `folder`."""
    write_tum(folder / TUM_FILE, localized_trajectory(fixes))
    write_localization_csv(folder / CSV_FILE, fixes)
    write_boreas(folder / BOREAS_FILE, fixes, m.keyframes["timestamp_ns"])
    if metrics is not None:
        write_json(folder / "metrics.json", metrics.to_dict())
    (folder / "summary.txt").write_text(localization_summary(sequence, fixes, seconds, metrics))
    plot_localization(folder / PLOT_FILE, m, fixes, f"{sequence} localised in the map")


def map_info(path: Path, m: Map) -> dict[str, Any]:
    """`radar-slam map info` content: sessions, keyframes, extent, size, GT alignment."""
    poses = m.poses
    size = map_bytes(path)
    lo = poses[:, :2].min(axis=0) if len(m) else np.zeros(2)
    hi = poses[:, :2].max(axis=0) if len(m) else np.zeros(2)
    sessions = []
    for n, s in enumerate(m.sessions):
        count = int(np.sum(m.keyframes["session"] == n))
        sessions.append(f"{s.sequence} ({s.scans} scans, {count} keyframes, {s.joined})")
    alignment = m.gt_alignment
    return {
        "sessions": sessions,
        "keyframes": len(m),
        "edges": len(m.edges),
        "extent_m": [float(v) for v in (hi - lo)],
        "bytes": size,
        "bytes_per_keyframe": size / max(1, len(m)),
        "gt_alignment": None
        if alignment is None
        else [float(alignment[0]), float(alignment[1]), float(np.rad2deg(alignment[2]))],
    }


def write_joined(folder: Path, joined: JoinedSession) -> str:
    """intersession_loops.csv and multisession.json of `run --map`; returns summary lines."""
    write_loops_csv(folder / INTERSESSION_LOOPS_FILE, joined.loops, joined.true_loops)
    content = joined_summary(joined)
    write_json(folder / MULTISESSION_FILE, content)
    if not joined.met_map:
        text = (
            f"map           never met the map: {content['intersession_proposed']} inter-session "
            "proposals, none accepted; trajectory and map/ in the session's own frame\n"
        )
    else:
        true = content["intersession_accepted_true"]
        ate = content["ate_map_frame_m"]
        text = (
            f"map           joined by {content['intersession_accepted']} inter-session loops "
            f"({'n/a' if true is None else true} true) of {content['intersession_proposed']}; "
            f"trajectory in the map frame, ATE {_m(ate)} through the map's GT alignment; "
            f"map/ holds {content['map_sessions']} sessions\n"
        )
    (folder / "summary.txt").write_text((folder / "summary.txt").read_text() + text)
    return text
