"""YAML config files: read, merge onto the dataclass defaults (strictly), write.

Every stage owns a dataclass of its settings (`raplace.config.RaPlaceConfig`, ...). A YAML file is
merged on top of the defaults by the one strict reader, `raplace.config_io.merge`; an unknown key
or a value of the wrong type is a `ConfigError` naming the file and the key path.
"""

from __future__ import annotations

import typing
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


class _UniqueKeyLoader(yaml.SafeLoader):
    """A SafeLoader that rejects a key given twice in one mapping (YAML would keep the last)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)  # type: ignore[no-untyped-call]
            if isinstance(key, typing.Hashable) and key in seen:
                line = key_node.start_mark.line + 1
                raise ConfigError(f"line {line}: key {key!r} is given twice")
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


def read_yaml(path: Path) -> dict[str, Any]:
    """Read a YAML mapping (UTF-8, no key given twice); an empty file is an empty mapping."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"{path}: not a UTF-8 text file (byte {exc.start}); a config is YAML text"
        ) from None
    try:
        data = yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 (a SafeLoader subclass)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML ({_one_line(exc)})") from None
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


def _one_line(exc: Exception) -> str:
    """An exception's text on one line (PyYAML messages span several)."""
    return " ".join(str(exc).split())


def write_yaml(config: Any, path: Path) -> None:
    """Write a config dataclass as YAML (the file `merge` can read back)."""
    Path(path).write_text(yaml.safe_dump(to_dict(config), sort_keys=False))
