"""PNG plots of trajectories and precision-recall curves (matplotlib, Agg, no pyplot state).

matplotlib loads when a figure is first made (`MATPLOTLIB_MODULES`), not with this module: a run
draws at its end only, and `radar-slam run` loads it on a thread while the scans go by."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import NDArray

from radar_slam.trajectory import Trajectory

if TYPE_CHECKING:
    from matplotlib.figure import Figure

logger = logging.getLogger(__name__)

GT_KEY = "gt"
FIGURE_SIZE_IN = (7.0, 7.0)
DPI = 150
TRAJECTORY_LINE_WIDTH = 1.2
LOOP_LINE_WIDTH = 0.5
LOOP_COLOR = "tab:red"
LOOP_ALPHA = 0.6
LOOP_COLUMNS = 4
LOOP_MARKER_SIZE = 18.0
"""Loops are also marked at their query position: on an optimised trajectory the two ends of a
loop coincide, and its segment alone would be invisible."""
TRAJECTORY_COLOURS = {GT_KEY: "black", "odometry": "tab:blue", "slam": "tab:orange"}
"""The same colours in every figure (trajectory.png, batch's summary.png) and the viewer."""
GT_Z_ORDER = 3
"""GT is drawn over the estimates (dashed), so that it is never hidden under them."""
MATPLOTLIB_MODULES = (
    "matplotlib.figure",
    "matplotlib.backends.backend_agg",
    "matplotlib.collections",
)
"""The matplotlib modules the figures of a result folder use (imported on first use)."""


def _new_figure() -> Figure:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=FIGURE_SIZE_IN, dpi=DPI)
    FigureCanvasAgg(figure)
    return figure


def display_origin(trajectories: dict[str, Trajectory]) -> NDArray[np.float64]:
    """The (x, y) [m] subtracted before drawing: the first position of the first trajectory drawn
    (GT first), so that UTM-like world coordinates (MulRan: ~353000, 4026000) plot as metres from
    the start. Zero when there is nothing to draw."""
    names = sorted(trajectories, key=lambda name: name != GT_KEY)
    for name in names:
        if len(trajectories[name].positions):
            return np.asarray(trajectories[name].positions[0], dtype=np.float64)
    return np.zeros(2)


def plot_trajectories(
    path: Path,
    trajectories: dict[str, Trajectory],
    loops: NDArray[np.float64] | None = None,
    title: str = "",
) -> None:
    """Save a top view (x right, y up, equal axes [m]) of the trajectories as a PNG.

    The entry named "gt", if any, is listed first and drawn dashed in black over the others;
    colours are `TRAJECTORY_COLOURS`. `loops` is an (M, 4) array of (x1, y1, x2, y2) [m] rows,
    drawn as thin lines with a ring at (x1, y1) (e.g. accepted loop closures). Everything is
    drawn relative to `display_origin`, which the axis labels state when it is not zero.
    """
    figure = _new_figure()
    axes = figure.add_subplot()
    origin = display_origin(trajectories)
    names = sorted(trajectories, key=lambda name: name != GT_KEY)  # gt first, order kept
    for name in names:
        xy = trajectories[name].positions - origin
        style: dict[str, Any] = {"color": TRAJECTORY_COLOURS.get(name)}
        if name == GT_KEY:
            style.update(linestyle="--", zorder=GT_Z_ORDER)
        axes.plot(xy[:, 0], xy[:, 1], label=name, linewidth=TRAJECTORY_LINE_WIDTH, **style)
    if loops is not None and len(loops):
        from matplotlib.collections import LineCollection

        segments = np.asarray(loops, dtype=np.float64).reshape(-1, LOOP_COLUMNS).reshape(-1, 2, 2)
        segments = segments - origin
        axes.add_collection(
            LineCollection(
                # matplotlib's stubs want a Sequence; an (M, 2, 2) array is documented as accepted.
                cast(Sequence[NDArray[np.float64]], segments),
                colors=LOOP_COLOR,
                linewidths=LOOP_LINE_WIDTH,
                alpha=LOOP_ALPHA,
            )
        )
        axes.scatter(
            segments[:, 0, 0],
            segments[:, 0, 1],
            s=LOOP_MARKER_SIZE,
            facecolors="none",
            edgecolors=LOOP_COLOR,
            linewidths=LOOP_LINE_WIDTH * 2,
            label=f"loop closures ({len(segments)})",
            zorder=GT_Z_ORDER + 1,
        )
    axes.set_aspect("equal", adjustable="datalim")
    shifted = bool(np.any(origin != 0.0))
    axes.set_xlabel(f"x - {origin[0]:.1f} [m]" if shifted else "x [m]")
    axes.set_ylabel(f"y - {origin[1]:.1f} [m]" if shifted else "y [m]")
    axes.grid(True, linewidth=0.3)
    if title:
        axes.set_title(title)
    if names or (loops is not None and len(loops)):
        axes.legend(loc="best")
    figure.savefig(path, bbox_inches="tight")
    logger.info("wrote %s", path)


def plot_pr_curves(
    path: Path, curves: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]], title: str = ""
) -> None:
    """Save precision-recall curves as a PNG; `curves` maps a name to (precision, recall) arrays
    of equal length (fractions in [0, 1])."""
    figure = _new_figure()
    axes = figure.add_subplot()
    for name, (precision, recall) in curves.items():
        axes.plot(recall, precision, label=name, linewidth=TRAJECTORY_LINE_WIDTH)
    axes.set_xlim(0.0, 1.0)
    axes.set_ylim(0.0, 1.05)
    axes.set_xlabel("recall")
    axes.set_ylabel("precision")
    axes.grid(True, linewidth=0.3)
    if title:
        axes.set_title(title)
    if curves:
        axes.legend(loc="best")
    figure.savefig(path, bbox_inches="tight")
    logger.info("wrote %s", path)
