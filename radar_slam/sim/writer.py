"""Files of a simulated sequence, in the exact MulRan layout plus a description and a marker.

```
<seq>/sensor_data/radar/polar/<t_ns>.png    n_bins rows x n_azimuths columns, uint8
<seq>/sensor_data/navtech_top_stamp.csv     one t_ns per line (end of each sweep)
<seq>/global_pose.csv                       t_ns, 3x4 row-major [R|t] of the vehicle BASE
<seq>/world.json                            seed, scenario, every parameter
<seq>/sim_complete.json                     written first with "complete": false, rewritten
                                            last with "complete": true
```

`simulator_files` tells the files the simulator writes from any others (a user's), so a
sequence can be replaced without deleting anything it did not write.
"""

from __future__ import annotations

import json
import os
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import asdict, is_dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from radar_slam.errors import ResultsError

POLAR_DIR = Path("sensor_data/radar/polar")
STAMP_FILE = Path("sensor_data/navtech_top_stamp.csv")
GLOBAL_POSE_FILE = Path("global_pose.csv")
WORLD_FILE = Path("world.json")
COMPLETE_MARKER = Path("sim_complete.json")
PNG_PARAMS = [cv2.IMWRITE_PNG_COMPRESSION, 1]
"""zlib level 1; with the strategy and filter below (when this OpenCV has them) writing a full
scan takes about 27 ms and 0.4-0.6 MB, versus 45 ms with the defaults."""
if hasattr(cv2, "IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY"):
    PNG_PARAMS += [cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY]
if hasattr(cv2, "IMWRITE_PNG_FILTER"):
    PNG_PARAMS += [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_UP]
MAX_PENDING_WRITES = 4
"""Scans queued for the background PNG writer before rendering waits."""


def write_polar_png(path: Path, polar: NDArray[np.uint8]) -> None:
    """Write a scan (n_azimuths, n_bins) as a MulRan polar PNG (n_bins rows, azimuth columns)."""
    if not cv2.imwrite(str(path), np.ascontiguousarray(polar.T), PNG_PARAMS):
        raise ResultsError(f"{path}: cannot write PNG")


class ScanWriter:
    """Writes scans to `<seq>/sensor_data/radar/polar/` on a background thread (zlib releases
    the GIL, so PNG compression overlaps the next scan's rendering); `workers=0` writes inline."""

    def __init__(self, folder: Path, workers: int = 1) -> None:
        self.folder = folder / POLAR_DIR
        self.folder.mkdir(parents=True, exist_ok=True)
        self._pool = ThreadPoolExecutor(max_workers=workers) if workers > 0 else None
        self._pending: list[Future[None]] = []

    def write(self, stamp_ns: int, polar: NDArray[np.uint8]) -> None:
        path = self.folder / f"{stamp_ns}.png"
        if self._pool is None:
            write_polar_png(path, polar)
            return
        while len(self._pending) >= MAX_PENDING_WRITES:
            self._pending.pop(0).result()
        self._pending.append(self._pool.submit(write_polar_png, path, polar))

    def close(self) -> None:
        """Wait for every queued scan (re-raising a write error) and stop the thread."""
        try:
            for future in self._pending:
                future.result()
        finally:
            self._pending.clear()
            if self._pool is not None:
                self._pool.shutdown(wait=True)

    def __enter__(self) -> ScanWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_stamps(folder: Path, stamps_ns: NDArray[np.int64]) -> None:
    """`sensor_data/navtech_top_stamp.csv`: one end-of-sweep time [ns] per line."""
    path = folder / STAMP_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("".join(f"{int(t)}\n" for t in stamps_ns))


def write_global_pose(
    folder: Path, times_ns: NDArray[np.int64], base_poses: NDArray[np.float64]
) -> None:
    """`global_pose.csv`: t_ns then the 3x4 row-major [R|t] of the base (rotation about z, z = 0).

    Args:
        times_ns: (N,) increasing times [ns].
        base_poses: (N, 3) T_world_base (x [m], y [m], yaw [rad]) in the dataset world frame.
    """
    c, s = np.cos(base_poses[:, 2]), np.sin(base_poses[:, 2])
    zeros, ones = np.zeros(len(c)), np.ones(len(c))
    matrix = np.stack(
        [c, -s, zeros, base_poses[:, 0], s, c, zeros, base_poses[:, 1], zeros, zeros, ones, zeros],
        1,
    )
    rows = [
        f"{int(t)}," + ",".join(f"{v:.9f}" for v in m)
        for t, m in zip(times_ns, matrix, strict=True)
    ]
    (folder / GLOBAL_POSE_FILE).write_text("\n".join(rows) + "\n")


def _jsonable(value: Any) -> Any:
    if is_dataclass(value) and not isinstance(value, type):
        return {k: _jsonable(v) for k, v in asdict(value).items()}
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    return value


def write_json(path: Path, content: dict[str, Any]) -> None:
    """Write a JSON description (dataclasses and numpy scalars converted), atomically: a
    temporary sibling renamed over `path`, so a marker is never half written."""
    temporary = path.parent / f".{path.name}.partial-{os.getpid()}"
    temporary.write_text(json.dumps(_jsonable(content), indent=2) + "\n")
    os.replace(temporary, path)


FIGURE_FILE = Path("sim_figure.png")
"""The optional overview figure of `radar-slam simulate --plot`."""
_SIMULATOR_FILES = (STAMP_FILE, GLOBAL_POSE_FILE, WORLD_FILE, COMPLETE_MARKER, FIGURE_FILE)


def simulator_files(folder: Path) -> tuple[list[Path], list[Path]]:
    """The files under `folder` split into (written by the simulator, anything else).

    The simulator's are `<digits>.png` scans in the polar folder, the fixed files of the
    layout (the stamp list, global_pose.csv, world.json, the marker, the figure) and the
    temporary `.<name>.partial-<pid>` a killed `write_json` may leave.
    """
    ours: list[Path] = []
    others: list[Path] = []
    own = {folder / relative for relative in _SIMULATOR_FILES}
    scans = folder / POLAR_DIR
    for path in sorted(folder.rglob("*")):
        if path.is_dir() and not path.is_symlink():
            continue
        scan = path.parent == scans and path.suffix == ".png" and path.stem.isdigit()
        temporary = path.parent == folder and path.name.startswith(".") and ".partial-" in path.name
        (ours if path in own or scan or temporary else others).append(path)
    return ours, others


def remove_simulated(folder: Path) -> None:
    """Delete a simulated sequence's files from `folder`, and folders left empty.

    Raises:
        ResultsError: `folder` holds a file the simulator did not write (nothing is deleted).
    """
    ours, others = simulator_files(folder)
    if others:
        raise ResultsError(
            f"{folder}: holds {len(others)} file(s) the simulator did not write "
            f"(first: {others[0].relative_to(folder)}); not replacing it"
        )
    for path in ours:
        path.unlink()
    for sub in sorted((p for p in folder.rglob("*") if p.is_dir()), key=lambda p: -len(p.parts)):
        if not any(sub.iterdir()):
            sub.rmdir()


def read_json(path: Path) -> dict[str, Any] | None:
    """A JSON file's content, or None when it is missing or unreadable."""
    try:
        content = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return content if isinstance(content, dict) else None
