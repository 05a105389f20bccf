"""Result folders: `results/<family>_<sequence>/<timestamp>/` with a `latest` link."""

from __future__ import annotations

import os
from datetime import datetime
from pathlib import Path

from radar_slam.errors import ResultsError

DEFAULT_RESULTS_ROOT = Path("results")


def result_dir(
    family: str, sequence: str, out: Path | None = None, now: datetime | None = None
) -> Path:
    """Create and return a fresh result folder.

    With `out`, that folder is used; it must be absent or empty, since nothing a user had may be
    overwritten. Otherwise `results/<family>_<sequence>/<YYYYmmdd_HHMMSS>/` is created and
    `results/<family>_<sequence>/latest` is pointed at it.
    """
    if out is not None:
        out = Path(out)
        if out.exists() and (not out.is_dir() or any(out.iterdir())):
            raise ResultsError(
                f"{out}: output folder exists and is not empty; choose another --out"
            )
        out.mkdir(parents=True, exist_ok=True)
        return out
    safe = f"{family}_{sequence}".replace("/", "_").replace(os.sep, "_")
    parent = DEFAULT_RESULTS_ROOT / safe
    stamp = (now or datetime.now()).strftime("%Y%m%d_%H%M%S")
    folder = parent / stamp
    suffix = 1
    while folder.exists():
        folder = parent / f"{stamp}_{suffix}"
        suffix += 1
    folder.mkdir(parents=True)
    latest = parent / "latest"
    if latest.is_symlink() or not latest.exists():
        if latest.is_symlink():
            latest.unlink()
        latest.symlink_to(folder.name)
    return folder
