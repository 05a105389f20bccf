"""Real radar samples written in the layout of another dataset (tests of loaders and commands)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from radar_slam.datasets.oxford import OxfordSequence

ENU_OFFSET = np.array([623000.0, 4848000.0, 0.0])
"""Where the written Boreas sequence starts in its ENU frame (near Toronto in UTM)."""
MID_SCAN_ROW = 199
"""Boreas stamps a scan with the time of azimuth floor(400 / 2) - 1."""
POSES_HEADER = (
    "GPSTime,easting,northing,altitude,vel_east,vel_north,vel_up,roll,pitch,heading,"
    "angvel_z,angvel_y,angvel_x"
)


def write_boreas(oxford_dir: Path, folder: Path) -> tuple[OxfordSequence, np.ndarray]:
    """Write the Oxford scans as a Boreas sequence: PNG bytes unchanged, named by the mid-sweep
    azimuth time; radar_poses.csv from the Oxford GT moved into an ENU frame (radar frame
    z-down, so roll = pi). Returns the Oxford sequence and the GT written (N, 3)."""
    oxford = OxfordSequence(oxford_dir)
    radar = folder / "radar"
    radar.mkdir(parents=True)
    gt = oxford.ground_truth
    assert gt is not None
    poses = gt + ENU_OFFSET
    rows = [POSES_HEADER]
    for index, stamp_us in enumerate(oxford.scan_file_times_us):
        source = oxford_dir / "radar" / f"{stamp_us}.png"
        mid_us = int(oxford[index].azimuth_times_ns[MID_SCAN_ROW] // 1000)  # type: ignore[index]
        shutil.copyfile(source, radar / f"{mid_us}.png")
        x, y, yaw = poses[index]
        rows.append(
            f"{mid_us},{float(x)!r},{float(y)!r},150.0,0,0,0,{np.pi!r},0.0,{float(yaw)!r},0,0,0"
        )
    (folder / "applanix").mkdir()
    (folder / "applanix" / "radar_poses.csv").write_text("\n".join(rows) + "\n")
    return oxford, poses
