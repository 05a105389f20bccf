"""Strict configuration loading: dataclass defaults in code, YAML files only override.

Every stage owns a dataclass of its settings (`raplace.config.RaPlaceConfig`, ...). A YAML file is
merged on top of the defaults; an unknown key or a value of the wrong type is a `ConfigError`
naming the file and the key path, never silently dropped.
"""

from __future__ import annotations

import dataclasses
import sys
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml

from radar_slam.errors import ConfigError

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
    """Return `base` with `overrides` applied, recursively for nested dataclasses.

    Raises ConfigError for keys that `cls` does not have, values of the wrong type, or values
    out of range (the ValueError of a dataclass's `__post_init__` checks); the message names the
    source `where` (a file path) and the key path, e.g.
    "my.yaml: odometry.keyframe: unknown key 'max_distanc'" or
    "my.yaml: odometry.keyframe.max_translation_m: must be a positive number, got -1.0".
    """
    if not isinstance(overrides, dict):
        raise ConfigError(f"{_at(where, keys)}: expected a mapping, got {type(overrides).__name__}")
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    hints = typing.get_type_hints(cls, globalns=vars(sys.modules[cls.__module__]))
    changes: dict[str, Any] = {}
    for key, value in overrides.items():
        if key not in fields:
            known = ", ".join(sorted(fields))
            raise ConfigError(f"{_at(where, keys)}: unknown key {key!r} (known: {known})")
        hint = hints[key]
        current = getattr(base, key)
        if dataclasses.is_dataclass(hint):
            changes[key] = merge(hint, current, value, where, (*keys, key))  # type: ignore[arg-type]
        else:
            changes[key] = _coerce(value, hint, _at(where, (*keys, key)))
    try:
        return dataclasses.replace(base, **changes)  # type: ignore[type-var]
    except ValueError as exc:  # a range check of the dataclass's __post_init__: "field: ..."
        raise ConfigError(f"{_at(where, keys)}{'.' if keys else ': '}{exc}") from None


def _one_line(exc: Exception) -> str:
    """An exception's text on one line (PyYAML messages span several)."""
    return " ".join(str(exc).split())


def _at(where: str, keys: tuple[str, ...]) -> str:
    """`where` followed by the dotted key path, for error messages."""
    return f"{where}: {'.'.join(keys)}" if keys else where


def _coerce(value: Any, hint: Any, where: str) -> Any:
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _coerce(value, arg, where)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(errors[0] if errors else f"{where}: bad value {value!r}")
    if origin is typing.Literal:
        if value not in args:
            raise ConfigError(f"{where}: {value!r} is not one of {list(args)}")
        return value
    if origin in (tuple, list):
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where}: expected a list, got {value!r}")
        item = args[0] if args else Any
        items = [_coerce(v, item, where) for v in value]
        return tuple(items) if origin is tuple else items
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        return value
    if hint is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    return value


def to_dict(config: Any) -> dict[str, Any]:
    """A plain dict of a config dataclass, tuples turned into lists (for YAML/JSON output)."""

    def plain(v: Any) -> Any:
        if isinstance(v, dict):
            return {k: plain(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [plain(x) for x in v]
        return v

    return plain(dataclasses.asdict(config))


def write_yaml(config: Any, path: Path) -> None:
    """Write a config dataclass as YAML (the file `merge` can read back)."""
    Path(path).write_text(yaml.safe_dump(to_dict(config), sort_keys=False))
