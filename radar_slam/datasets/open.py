"""Resolve a sequence spec (`family/sequence` or a folder path) to an opened RadarSequence."""

from __future__ import annotations

import difflib
import os
from pathlib import Path

from radar_slam.datasets import registry
from radar_slam.datasets.frame import RadarSequence
from radar_slam.datasets.registry import (
    DatasetConfig,
    Family,
    detect_family,
    families,
    family_folder,
)
from radar_slam.errors import ConfigError, DatasetNotFoundError

SPEC_SEPARATOR = "/"


def _split_family_spec(spec: str) -> tuple[Family, str] | None:
    """(family, sequence) when `spec` reads `family/sequence` with a registered family."""
    head, separator, tail = spec.partition(SPEC_SEPARATOR)
    family = families().get(head.lower())
    if not separator or not tail or family is None:
        return None
    return family, tail.strip(SPEC_SEPARATOR)


def _layouts_and_sources(selected: list[Family]) -> str:
    """Expected layout and download address of each family, on one line (error messages)."""
    return "; ".join(
        f"{family.name}: expected {family.layout}, obtained from {family.obtain}"
        for family in selected
    )


def _open_with(family: Family, path: Path, options: dict[str, object]) -> RadarSequence:
    """`family.open(path, **options)`, refusing options the family does not take."""
    foreign = sorted(set(options) - set(family.options))
    if foreign:
        raise ConfigError(
            f"dataset.{foreign[0]} does not apply to the {family.name} family (it takes: "
            f"{', '.join(family.options)})"
        )
    return family.open(path, **options)


def sequence_folder(root: Path, family: Family, sequence: str) -> Path:
    """The folder of `family/sequence` under `root` (the family's own resolver when it has one)."""
    if family.resolve is not None:
        return family.resolve(root, sequence)
    return family_folder(root, family.name) / sequence


def open_sequence(
    spec: str | os.PathLike[str],
    data_root: str | os.PathLike[str] | None = None,
    options: DatasetConfig | None = None,
) -> RadarSequence:
    """Open a sequence named `family/sequence` or given as a path to its folder
    (`locate_sequence` finds it).

    `options` (the `dataset:` config section) overrides loader settings such as the range
    resolution.

    Raises:
        DatasetNotFoundError: nothing found; the message names every place looked in, the
            expected layouts and where to obtain the data.
        DatasetFormatError: the folder was found but its content is malformed.
        ConfigError: `options` sets a loader setting the family does not take.
    """
    family, path = locate_sequence(spec, data_root)
    return open_located(family, path, options)


def open_located(family: Family, path: Path, options: DatasetConfig | None = None) -> RadarSequence:
    """Open the sequence at `path` (found by `locate_sequence`) with the loader settings of
    `options`.

    Raises:
        DatasetFormatError: the content is malformed.
        ConfigError: `options` sets a loader setting the family does not take.
    """
    return _open_with(family, path, (options or DatasetConfig()).loader_options())


def locate_sequence(
    spec: str | os.PathLike[str], data_root: str | os.PathLike[str] | None = None
) -> tuple[Family, Path]:
    """The family and the folder (or recording file) of a sequence, without opening it, so
    that its family's settings can be known before it is opened.

    `family/sequence` resolves to `<root>/<family>/<sequence>` (family folder matched
    case-insensitively), where root is `data_root`, else $RADAR_SLAM_DATA, else ./data. A
    family with a resolver (e.g. generated data) supplies the folder itself. Any other spec is a
    folder path whose family is detected from its layout; a bare name that is not a folder is
    also looked for as `<root>/<family>/<name>` in every family without a resolver.

    Raises:
        DatasetNotFoundError: nothing found; the message names every place looked in, the
            expected layouts and where to obtain the data.
    """
    root = registry.data_root(data_root)
    candidates: list[Family] = list(families().values())
    named = _split_family_spec(spec) if isinstance(spec, str) else None
    if named is not None:
        family, sequence = named
        candidates = [family]
        folder = sequence_folder(root, family, sequence)
        if folder.is_dir() or (folder.is_file() and family.detect(folder)):  # file: a ROS 1 bag
            return family, folder
    path = Path(spec).expanduser()
    if path.is_dir() or path.is_file():  # a file: a recording such as a ROS 1 bag
        detected = detect_family(path)
        if detected is not None:
            return detected, path
        raise DatasetNotFoundError(
            f"{path} exists but matches no known dataset layout; expected one of: "
            f"{_layouts_and_sources(candidates)}"
        )
    if isinstance(spec, str) and SPEC_SEPARATOR not in spec.strip(SPEC_SEPARATOR):
        for family in candidates:
            if family.resolve is not None:
                continue
            folder = family_folder(root, family.name) / spec.strip(SPEC_SEPARATOR)
            if folder.is_dir() and family.detect(folder):
                return family, folder
    family_named = None if named is None else named[0]
    raise DatasetNotFoundError(_not_found(str(spec), root, family_named))


MAX_SUGGESTIONS = 3
SUGGESTION_CUTOFF = 0.5
"""`difflib` similarity above which a sequence name under the data root is suggested."""


def closest(word: str, names: list[str]) -> list[str]:
    """The few `names` most like `word` (a mistyped name), best first; maybe none."""
    return difflib.get_close_matches(word, names, MAX_SUGGESTIONS, SUGGESTION_CUTOFF)


def _names_under(root: Path) -> list[str]:
    """`family/name` of every folder or file in a family folder under `root` (nothing opened)."""
    names = []
    for family in families().values():
        folder = family_folder(root, family.name)
        if folder.is_dir():
            names += [f"{family.name}/{entry.name}" for entry in sorted(folder.iterdir())]
    return names


def _not_found(spec: str, root: Path, family: Family | None) -> str:
    """One short line: what was not found where, the closest names there, how to list them,
    and for a named family its layout and where to obtain it."""
    names = _names_under(root) if root.is_dir() else []
    pool = {name: name for name in names}
    if family is None:  # a bare name: compare with the names without their family
        pool.update({name.split("/", 1)[1]: name for name in names})
    close = closest(spec, list(pool))
    if "/" in spec and family is None:
        known = ", ".join(sorted(families()))
        text = f"sequence {spec!r}: unknown family {spec.split('/')[0]!r} (families: {known})"
    elif family is not None:
        folder = sequence_folder(root, family, spec.split("/", 1)[1])
        text = f"sequence {spec!r} not found: no folder {folder.absolute()}"
    else:
        text = f"sequence {spec!r} not found under the data root {root}"
    if close:
        text += f" (closest: {', '.join(dict.fromkeys(pool[c] for c in close))})"
    text += "; `radar-slam list` shows what is there"
    if family is not None:
        text += f"; {_layouts_and_sources([family])}"
    return text
