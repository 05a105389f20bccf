"""Figure of the simulator for the README: town map with the trajectory, simulated Cartesian
scans, and real MulRan / Oxford scans at the same scale and display gain.

    python scripts/sim_figure.py [--scenario loop] [--out docs/sim_figure.png]
                                 [--shared-data ../shared/data]

The real scans are taken from the shared samples when present (see ../shared/data/README.md).
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import cv2
import numpy as np

from radar_slam.datasets.mulran import column_azimuths_rad
from radar_slam.datasets.navtech import (
    MULRAN_RANGE_RESOLUTION_M,
    OXFORD_HEADER_BYTES,
    OXFORD_RANGE_RESOLUTION_M,
    encoder_to_azimuth_ccw,
)
from radar_slam.sim.figure import ScanPanel, save_overview
from radar_slam.sim.generate import build_scene
from radar_slam.sim.scenarios import DEFAULT_SCENARIO, get_scenario

logger = logging.getLogger("sim_figure")

DEFAULT_OUT = Path("docs/sim_figure.png")
DEFAULT_SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
SHOWN_FRACTIONS = (0.12, 0.33, 0.62)
"""Where along the sequence the simulated scans are taken (0.12 and 0.62: one place, two laps)."""


def real_panels(shared: Path) -> list[ScanPanel]:
    """One real MulRan scan and one real Oxford scan, when the samples are there."""
    panels = []
    mulran = sorted((shared / "mulran" / "raw_scan" / "polar").glob("*.png"))
    if mulran:
        polar = cv2.imread(str(mulran[0]), cv2.IMREAD_UNCHANGED).T
        panels.append(
            ScanPanel(
                "real MulRan (CIR204-H)",
                polar,
                column_azimuths_rad(polar.shape[0]),
                MULRAN_RANGE_RESOLUTION_M,
            )
        )
    oxford = sorted((shared / "oxford").glob("*/radar/*.png"))
    if oxford:
        image = cv2.imread(str(oxford[0]), cv2.IMREAD_UNCHANGED)
        encoders = image[:, 8:10].copy().view("<u2").ravel()
        panels.append(
            ScanPanel(
                "real Oxford (CTS350-X)",
                np.ascontiguousarray(image[:, OXFORD_HEADER_BYTES:]),
                encoder_to_azimuth_ccw(encoders),
                OXFORD_RANGE_RESOLUTION_M,
            )
        )
    if not panels:
        logger.warning("no real scans under %s: the figure shows simulated scans only", shared)
    return panels


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default=DEFAULT_SCENARIO)
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--shared-data", type=Path, default=DEFAULT_SHARED)
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    scene = build_scene(get_scenario(args.scenario), args.seed)
    shown = [int(f * (scene.n_frames - 1)) for f in SHOWN_FRACTIONS]
    path = save_overview(scene, args.out, shown=shown, real=real_panels(args.shared_data))
    logger.info("wrote %s", path)


if __name__ == "__main__":
    main()
