"""Grids of configuration overrides for `radar-slam batch --grid FILE`.

A grid file is YAML with one or both of two sections:

    configs:                      # named override sets (any sections of a --config file)
      baseline: {}
      short_keyframes:
        odometry: {keyframe: {max_translation_m: 2.0}}
    product:                      # every combination of these values (dotted key paths)
      loop_closure.max_descriptor_distance: [0.30, 0.40]
      graph.final_pass: [gnc, none]

`configs` alone gives its named sets; `product` alone gives one set per combination, named
`max_descriptor_distance=0.3+final_pass=gnc` (the last key of each path); with both, every named
set is crossed with every combination (`short_keyframes+max_descriptor_distance=0.3+...`, the
product's values overriding the named set's). Without `--grid` a batch has one configuration,
`default` (no overrides). Every set is checked against the configuration dataclasses before any
task starts; a mistake is a `ConfigError` naming the file and the key path.
"""

from __future__ import annotations

import itertools
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from radar_slam.config import merge, read_yaml
from radar_slam.errors import ConfigError
from radar_slam.pipeline import PipelineConfig

CONFIGS_SECTION = "configs"
PRODUCT_SECTION = "product"
DEFAULT_NAME = "default"
NAME_SEPARATOR = "+"
SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.=+-]*$")
"""Configuration names become folder names: letters, digits and `_ . = + -` only."""


@dataclass(frozen=True)
class GridPoint:
    """One configuration of a batch: a name (also its result sub-folder) and nested overrides
    applied on top of the family defaults and `--config` (same sections as a config file)."""

    name: str
    overrides: dict[str, Any] = field(default_factory=dict)


DEFAULT_GRID = (GridPoint(DEFAULT_NAME),)


def nested(path: str, value: Any) -> dict[str, Any]:
    """`"a.b.c", v` -> `{"a": {"b": {"c": v}}}`."""
    result: Any = value
    for key in reversed(path.split(".")):
        result = {key: result}
    return dict(result)


def deep_merge(base: dict[str, Any], extra: dict[str, Any]) -> dict[str, Any]:
    """A copy of `base` with `extra` merged in recursively (`extra` wins on leaves)."""
    merged = dict(base)
    for key, value in extra.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = deep_merge(merged[key], value)
        else:
            merged[key] = value
    return merged


def _format_value(value: Any) -> str:
    return str(value).replace(" ", "")


def _named_sets(section: Any, where: str) -> list[GridPoint]:
    if not isinstance(section, dict) or not section:
        raise ConfigError(f"{where}: {CONFIGS_SECTION}: expected a non-empty mapping of names")
    points = []
    for name, overrides in section.items():
        overrides = {} if overrides is None else overrides
        if not isinstance(overrides, dict):
            raise ConfigError(
                f"{where}: {CONFIGS_SECTION}.{name}: expected a mapping of config sections, "
                f"got {type(overrides).__name__}"
            )
        points.append(GridPoint(str(name), overrides))
    return points


def _product_sets(section: Any, where: str) -> list[GridPoint]:
    if not isinstance(section, dict) or not section:
        raise ConfigError(f"{where}: {PRODUCT_SECTION}: expected a mapping of key paths to lists")
    axes: list[list[tuple[str, Any]]] = []
    for path, values in section.items():
        if not isinstance(values, list) or not values:
            raise ConfigError(
                f"{where}: {PRODUCT_SECTION}.{path}: expected a non-empty list of values"
            )
        axes.append([(str(path), value) for value in values])
    points = []
    for combination in itertools.product(*axes):
        overrides: dict[str, Any] = {}
        for path, value in combination:
            overrides = deep_merge(overrides, nested(path, value))
        name = NAME_SEPARATOR.join(
            f"{path.rsplit('.', 1)[-1]}={_format_value(value)}" for path, value in combination
        )
        points.append(GridPoint(name, overrides))
    return points


def _check(points: list[GridPoint], where: str) -> None:
    """Names usable as folders and unique; overrides valid for `PipelineConfig`."""
    seen: set[str] = set()
    for point in points:
        if not SAFE_NAME.match(point.name):
            raise ConfigError(
                f"{where}: configuration name {point.name!r}: use letters, digits and _ . = + -"
            )
        if point.name in seen:
            raise ConfigError(f"{where}: configuration name {point.name!r} appears twice")
        seen.add(point.name)
        merge(PipelineConfig, PipelineConfig(), point.overrides, f"{where}: {point.name}")


def parse_grid(data: dict[str, Any], where: str) -> list[GridPoint]:
    """The configurations of a grid mapping (see the module docstring); `where` names its source
    in error messages. Raises `ConfigError`."""
    unknown = sorted(set(data) - {CONFIGS_SECTION, PRODUCT_SECTION})
    if unknown:
        raise ConfigError(
            f"{where}: unknown section {unknown[0]!r} (known: {CONFIGS_SECTION}, {PRODUCT_SECTION})"
        )
    if not data:
        raise ConfigError(f"{where}: empty grid; give {CONFIGS_SECTION} and/or {PRODUCT_SECTION}")
    named = _named_sets(data[CONFIGS_SECTION], where) if CONFIGS_SECTION in data else None
    product = _product_sets(data[PRODUCT_SECTION], where) if PRODUCT_SECTION in data else None
    if named is None:
        points = product or []
    elif product is None:
        points = named
    else:
        points = [
            GridPoint(
                f"{base.name}{NAME_SEPARATOR}{point.name}",
                deep_merge(base.overrides, point.overrides),
            )
            for base in named
            for point in product
        ]
    _check(points, where)
    return points


def read_grid(path: Path | None) -> list[GridPoint]:
    """The configurations of the grid file `path`, or the single `default` one when None."""
    if path is None:
        return list(DEFAULT_GRID)
    if not Path(path).is_file():
        raise ConfigError(f"{path}: grid file not found")
    return parse_grid(read_yaml(Path(path)), str(path))
