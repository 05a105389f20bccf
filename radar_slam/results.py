"""Result folders: `results/<family>_<sequence>/<timestamp>/` with a `latest` link.

A result folder appears complete or not at all: its files are written into a hidden temporary
sibling (`.<name>.partial-<pid>`) that is renamed to its final name once every file is written,
and only then is `latest` moved to it (by atomically replacing the link). An interrupted run
leaves at most a hidden partial folder, removed by the next run once its process is gone.
"""

from __future__ import annotations

import logging
import os
import shutil
from collections.abc import Callable
from datetime import datetime
from pathlib import Path

from radar_slam.errors import ResultsError

logger = logging.getLogger(__name__)

DEFAULT_RESULTS_ROOT = Path("results")
LATEST_LINK = "latest"
PARTIAL_SUFFIX = ".partial-"
"""A folder being written is `.<final name>.partial-<pid>` next to its final place."""


def check_writable(path: Path, what: str = "output") -> None:
    """Fail before any work unless `path` (a file or folder to be created) could be created.

    Its nearest existing ancestor must be a writable folder. Nothing is created.

    Raises:
        ResultsError: naming `path` and the ancestor that stands in the way.
    """
    path = Path(path)
    ancestor = path.parent if path.exists() else path
    while not ancestor.exists():
        if ancestor.is_symlink():  # a dangling link
            raise ResultsError(f"{path}: cannot create {what}: {ancestor} is a broken link")
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise ResultsError(f"{path}: cannot create {what}: {ancestor} is not a folder")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise ResultsError(f"{path}: cannot create {what}: {ancestor} is not writable")


def check_out_folder(out: Path, option: str = "--out") -> None:
    """`out` must be absent or an empty folder, and creatable (before any work starts)."""
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise ResultsError(f"{out}: output folder exists and is not empty; choose another {option}")
    check_writable(out, "the output folder")


def results_parent(family: str, sequence: str) -> Path:
    """`results/<family>_<sequence>/`, the parent of a sequence's timestamped result folders."""
    safe = f"{family}_{sequence}".replace("/", "_").replace(os.sep, "_")
    return DEFAULT_RESULTS_ROOT / safe


def check_output_root(out: Path | None) -> None:
    """Before a sequence is even opened (which may generate it): `out` must be usable, or the
    default results root creatable. `check_result_location` completes the check once the
    sequence's name is known."""
    if out is not None:
        check_out_folder(out)
    else:
        check_writable(DEFAULT_RESULTS_ROOT, "the results folder")


def check_result_location(family: str, sequence: str, out: Path | None = None) -> None:
    """Fail before any work when the result folder could not be written (see `write_result_dir`)."""
    if out is not None:
        check_out_folder(out)
    else:
        check_writable(results_parent(family, sequence), "the results folder")


def _free_name(parent: Path, now: datetime | None) -> Path:
    stamp = (now or datetime.now()).strftime("%Y%m%d_%H%M%S")
    folder = parent / stamp
    suffix = 1
    while folder.exists():
        folder = parent / f"{stamp}_{suffix}"
        suffix += 1
    return folder


def pid_alive(pid: int) -> bool:
    """True while process `pid` exists (a temporary folder named after it is still in use)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_partials(parent: Path, name: str | None = None) -> None:
    """Delete `.<name>.partial-<pid>` folders, files and links in `parent` whose writing process
    has died (of the given `name` only, or any)."""
    if not parent.is_dir():
        return
    for partial in parent.glob(f".{name or '*'}{PARTIAL_SUFFIX}*"):
        pid_text = partial.name.rsplit(PARTIAL_SUFFIX, 1)[-1]
        if not pid_text.isdigit() or pid_alive(int(pid_text)):
            continue
        logger.info("removing %s, left by an interrupted run", partial)
        if partial.is_symlink() or not partial.is_dir():  # a `latest` link being replaced
            partial.unlink(missing_ok=True)
        else:
            shutil.rmtree(partial, ignore_errors=True)


def point_latest(folder: Path) -> None:
    """Make `<parent>/latest` a link to `folder` by atomic replacement (a real file or folder
    named `latest` is a user's and is left alone)."""
    latest = folder.parent / LATEST_LINK
    if latest.exists() and not latest.is_symlink():
        logger.warning("%s is not a link; not moving it", latest)
        return
    temporary = folder.parent / f".{LATEST_LINK}{PARTIAL_SUFFIX}{os.getpid()}"
    if temporary.is_symlink():
        temporary.unlink()
    temporary.symlink_to(folder.name)
    os.replace(temporary, latest)


def final_of_staging(staging: Path) -> Path:
    """The final path of a hidden staging folder `.<name>.partial-<pid>` (`write_result_dir`
    renames it there), for writers that record paths inside the folder they fill."""
    staging = Path(staging)
    name = staging.name.removeprefix(".").rsplit(PARTIAL_SUFFIX, 1)[0]
    return staging.parent / name


def write_result_dir(
    family: str,
    sequence: str,
    write: Callable[[Path], object],
    out: Path | None = None,
    now: datetime | None = None,
) -> Path:
    """Write a result folder atomically and return its final path.

    `write(folder)` fills a hidden temporary folder; when it returns, the folder is renamed to
    `out` (which must be absent or empty) or to `results/<family>_<sequence>/<YYYYmmdd_HHMMSS>/`,
    and in the latter case `latest` is then pointed at it. If `write` raises (Ctrl-C included),
    the temporary folder is removed and nothing else has changed.
    """
    if out is not None:
        check_out_folder(out)
        final = Path(out)
    else:
        parent = results_parent(family, sequence)
        check_writable(parent, "the results folder")
        final = _free_name(parent, now)
    final.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_partials(final.parent)
    staging = final.parent / f".{final.name}{PARTIAL_SUFFIX}{os.getpid()}"
    staging.mkdir()
    try:
        write(staging)
        if final.is_dir():
            final.rmdir()  # an empty --out folder (checked above; rmdir refuses a non-empty one)
        staging.rename(final)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    if out is None:
        point_latest(final)
    return final


def result_dir(
    family: str, sequence: str, out: Path | None = None, now: datetime | None = None
) -> Path:
    """Create and return a fresh, empty result folder (for writers that fill it in place).

    With `out`, that folder is used; it must be absent or empty, since nothing a user had may be
    overwritten. Otherwise `results/<family>_<sequence>/<YYYYmmdd_HHMMSS>/` is created and
    `results/<family>_<sequence>/latest` is pointed at it. Prefer `write_result_dir`, which
    shows the folder only once it is complete.
    """
    if out is not None:
        check_out_folder(out)
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        return out
    parent = results_parent(family, sequence)
    check_writable(parent, "the results folder")
    folder = _free_name(parent, now)
    folder.mkdir(parents=True)
    point_latest(folder)
    return folder


def check_output_file(path: Path, option: str, force: bool = False) -> None:
    """Fail before any work unless the file `path` can be written: its folder exists and is
    writable, and the file itself is absent (or `force`)."""
    path = Path(path)
    if path.is_dir():
        raise ResultsError(f"{path}: is a folder; {option} needs a file name")
    if path.exists() and not force:
        raise ResultsError(f"{path}: file exists; pass --force to overwrite it")
    folder = path.parent
    if not folder.is_dir():
        raise ResultsError(f"{path}: folder {folder} does not exist ({option})")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ResultsError(f"{path}: folder {folder} is not writable ({option})")


def write_text_atomically(path: Path, text: str) -> None:
    """Write `text` to a temporary sibling, then rename it over `path` (never half a file); the
    leftovers of a writer of `path` killed earlier are removed first."""
    path = Path(path)
    remove_stale_partials(path.parent, path.name)  # what a killed writer of it left
    temporary = path.parent / f".{path.name}{PARTIAL_SUFFIX}{os.getpid()}"
    try:
        temporary.write_text(text)
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise
