"""YAML config files: read, merge onto the dataclass defaults (strictly), write.

Every stage owns a dataclass of its settings (`raplace.config.RaPlaceConfig`, ...). A YAML file is
merged on top of the defaults by the one strict reader, `raplace.config_io.merge`; an unknown key
or a value of the wrong type is a `ConfigError` naming the file and the key path.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, TypeVar

import yaml

from radar_slam.errors import ConfigError
from raplace import config_io
from raplace.config_io import ConfigReadError, to_dict

T = TypeVar("T")

_PACKAGE_CONFIGS = Path(__file__).resolve().parent / "configs"  # installed wheel
_SOURCE_CONFIGS = Path(__file__).resolve().parents[1] / "configs"  # source checkout


def configs_dir() -> Path:
    """The folder holding the shipped per-family YAML defaults."""
    return _PACKAGE_CONFIGS if _PACKAGE_CONFIGS.is_dir() else _SOURCE_CONFIGS


def read_yaml(path: Path) -> dict[str, Any]:
    """Read a YAML mapping; an empty file is an empty mapping."""
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config ({exc.strerror})") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML ({exc})") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(
            f"{path}: top level must be a mapping of sections, got {type(data).__name__}"
        )
    return data


def merge(
    cls: type[T], base: T, overrides: dict[str, Any], where: str, keys: tuple[str, ...] = ()
) -> T:
    """`raplace.config_io.merge`, raising `ConfigError` (a `RadarSlamError`)."""
    try:
        return config_io.merge(cls, base, overrides, where, keys)
    except ConfigReadError as exc:
        raise ConfigError(str(exc)) from None


def write_yaml(config: Any, path: Path) -> None:
    """Write a config dataclass as YAML (the file `merge` can read back)."""
    Path(path).write_text(yaml.safe_dump(to_dict(config), sort_keys=False))
