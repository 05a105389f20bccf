"""Overview figure of a simulated sequence: town map with the trajectory, and Cartesian scans
(optionally next to real scans for comparison). Side effects only (matplotlib, one PNG)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Ellipse, Polygon  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

from radar_slam.sim.generate import Scene, make_renderer, render_frame  # noqa: E402
from raplace import CartesianGrid, CartesianWarper  # noqa: E402

SCAN_HALF_EXTENT_M = 80.0
"""Cartesian scans show +-80 m around the sensor."""
SCAN_CELL_M = 0.2
"""Pixel size of the Cartesian scans [m]."""
DISPLAY_GAIN = 2.5
"""Display scaling of intensities (level * gain, clipped at 255), the same for every scan."""
DEFAULT_SHOWN_FRAMES = 3
FIGURE_DPI = 110


@dataclass(frozen=True)
class ScanPanel:
    """A polar scan to show as a Cartesian image.

    Attributes:
        title: panel title.
        polar: (n_azimuths, n_bins) uint8.
        azimuths_rad: (n_azimuths,) CCW azimuths [rad].
        range_resolution_m: bin size [m].
    """

    title: str
    polar: NDArray[np.uint8]
    azimuths_rad: NDArray[np.float64]
    range_resolution_m: float


def cartesian(panel: ScanPanel) -> NDArray[np.float32]:
    """The panel's scan warped to +-SCAN_HALF_EXTENT_M, forward up, left to the left."""
    warper = CartesianWarper(CartesianGrid.covering(SCAN_HALF_EXTENT_M, SCAN_CELL_M))
    return warper(panel.polar, panel.azimuths_rad, panel.range_resolution_m)


def _draw_town(ax: plt.Axes, scene: Scene, shown: list[int]) -> None:
    town, origin = scene.town, np.asarray(scene.scenario.origin_xy)
    for road in town.roads:
        ax.plot(
            *road.polyline.T,
            color="0.8",
            lw=2.0 * road.half_width_m / 4,
            zorder=1,
            solid_capstyle="round",
        )
    for b in town.buildings:
        ax.add_patch(Polygon(b.corners, closed=True, fc="#d9822b", ec="#7a4410", lw=0.4, zorder=2))
    for park in town.parks:
        ax.add_patch(
            Ellipse(
                park[:2],
                2 * park[2],
                2 * park[3],
                angle=np.rad2deg(park[4]),
                fc="#9fd49f",
                ec="none",
                zorder=1,
            )
        )
    for points, colour, size in (
        (town.street_trees, "green", 3),
        (town.poles, "black", 2),
        (town.parking[:, :2], "#5555aa", 1),
    ):
        if len(points):
            ax.scatter(points[:, 0], points[:, 1], s=size, c=colour, lw=0, zorder=3)
    ends = scene.scan_end_offsets_ns(scene.n_frames)
    radar = scene.radar_poses(ends)[:, :2] - origin
    ax.scatter(radar[:, 0], radar[:, 1], c=np.arange(len(radar)), cmap="viridis", s=3, zorder=4)
    for k in shown:
        ax.annotate(
            f"#{k}",
            radar[k],
            color="blue",
            fontsize=8,
            zorder=5,
            xytext=(4, 4),
            textcoords="offset points",
        )
        ax.plot(*radar[k], "o", mfc="none", mec="blue", ms=8, zorder=5)
    ax.set_aspect("equal")
    ax.set_title(
        f"{scene.scenario.name} (seed {scene.seed}): {len(town.buildings)} buildings, "
        f"{scene.trajectory.length_m:.0f} m route, {scene.n_frames} scans"
    )
    ax.set_xlabel("x [m] (town frame)")
    ax.set_ylabel("y [m]")


def _draw_scan(ax: plt.Axes, panel: ScanPanel) -> None:
    image = np.clip(cartesian(panel) * DISPLAY_GAIN, 0, 255)
    extent = (SCAN_HALF_EXTENT_M, -SCAN_HALF_EXTENT_M, -SCAN_HALF_EXTENT_M, SCAN_HALF_EXTENT_M)
    ax.imshow(image, cmap="gray", vmin=0, vmax=255, extent=extent)
    ax.set_title(panel.title, fontsize=9)
    ax.set_xlabel("y [m] (left)")
    ax.set_ylabel("x [m] (forward)")


def save_overview(
    scene: Scene,
    path: Path,
    n_frames: int | None = None,
    shown: list[int] | None = None,
    real: list[ScanPanel] | None = None,
) -> Path:
    """Write the overview PNG: map on the left, simulated (and real) scans on the right.

    Args:
        scene: the simulated scene.
        path: output PNG.
        n_frames: scans generated (default: all the route provides).
        shown: frame indices of the simulated scans to show (default: three spread out).
        real: real scans to show next to them, same scale and display gain.
    """
    n = scene.n_frames if n_frames is None else n_frames
    shown = shown or [int(k) for k in np.linspace(0, n - 1, DEFAULT_SHOWN_FRAMES + 2)[1:-1]]
    renderer = make_renderer(scene)
    sensor = scene.scenario.sensor
    panels = [
        ScanPanel(
            f"simulated #{k} (t = {(k + 1) / sensor.scan_rate_hz:.2f} s)",
            render_frame(scene, renderer, k),
            sensor.azimuths_ccw_rad(),
            sensor.range_resolution_m,
        )
        for k in shown
    ] + list(real or [])
    n_cols = 2 if len(panels) <= 4 else 3
    n_rows = -(-len(panels) // n_cols)
    fig = plt.figure(figsize=(7 + 3.6 * n_cols, max(7.0, 3.6 * n_rows)))
    grid = fig.add_gridspec(n_rows, 2 + n_cols, width_ratios=[1.0, 1.0] + [1.0] * n_cols)
    _draw_town(fig.add_subplot(grid[:, :2]), scene, shown)
    for i, panel in enumerate(panels):
        _draw_scan(fig.add_subplot(grid[i // n_cols, 2 + i % n_cols]), panel)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=FIGURE_DPI)
    plt.close(fig)
    return path
