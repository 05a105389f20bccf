"""The one strict reader of config dataclasses (every package's settings), and its writer.

Defaults live in the dataclasses; a mapping (from YAML, JSON, a saved database) only overrides
them. An unknown key or a value of the wrong type raises `ConfigReadError` naming the source and
the key path, never silently dropped. Ints are accepted for floats; lists for tuples.
"""

from __future__ import annotations

import dataclasses
import sys
import types
import typing
from typing import Any, TypeVar

from raplace import RaPlaceError

T = TypeVar("T")


class ConfigReadError(RaPlaceError):
    """A settings mapping has an unknown key or a value of the wrong type."""


def replaced_by_constant(where: str) -> str:
    """The `REMOVED_KEYS` message of a key that became the named constant `where` (its dotted
    name, maybe with a note)."""
    return f"now a constant of the method ({where})"


def replaced_by_constants(module: str, *keys: str) -> dict[str, str]:
    """`REMOVED_KEYS` entries of keys that each became the upper-case constant of the same name
    in `module` (a dotted module name)."""
    return {key: replaced_by_constant(f"{module}.{key.upper()}") for key in keys}


def from_dict(cls: type[T], data: dict[str, Any], where: str = "") -> T:
    """Build `cls` from a nested mapping on top of its defaults (see `merge`)."""
    return merge(cls, cls(), data, where or cls.__name__)


def merge(
    cls: type[T], base: T, overrides: dict[str, Any], where: str, keys: tuple[str, ...] = ()
) -> T:
    """Return `base` with `overrides` applied, recursively for nested dataclasses.

    Raises ConfigReadError for keys that `cls` does not have (for a key listed in the class's
    `REMOVED_KEYS` mapping, the message says what replaced it), values of the wrong type, or
    values out of range (the ValueError of a dataclass's `__post_init__` checks, see
    `raplace.checks`); the message names the source `where` (a file path) and the key path, e.g.
    "my.yaml: odometry.keyframe: unknown key 'max_distanc'" or
    "my.yaml: odometry.keyframe.max_translation_m: must be a positive number, got -1.0".
    """
    if not isinstance(overrides, dict):
        raise ConfigReadError(
            f"{_at(where, keys)}: expected a mapping, got {type(overrides).__name__}"
        )
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    hints = typing.get_type_hints(cls, globalns=vars(sys.modules[cls.__module__]))
    changes: dict[str, Any] = {}
    for key, value in overrides.items():
        if key not in fields:
            removed = getattr(cls, "REMOVED_KEYS", {}).get(key)
            if removed:
                raise ConfigReadError(f"{_at(where, keys)}: key {key!r} is gone: {removed}")
            known = ", ".join(sorted(fields))
            raise ConfigReadError(f"{_at(where, keys)}: unknown key {key!r} (known: {known})")
        hint = hints[key]
        current = getattr(base, key)
        if dataclasses.is_dataclass(hint):
            changes[key] = merge(hint, current, value, where, (*keys, key))  # type: ignore[arg-type]
        else:
            changes[key] = _coerce(value, hint, _at(where, (*keys, key)))
    try:
        return dataclasses.replace(base, **changes)  # type: ignore[type-var]
    except ConfigReadError:
        raise
    except ValueError as exc:  # a range check of the dataclass's __post_init__: "field: ..."
        raise ConfigReadError(f"{_at(where, keys)}{'.' if keys else ': '}{exc}") from None


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
            except ConfigReadError as exc:
                errors.append(str(exc))
        raise ConfigReadError(errors[0] if errors else f"{where}: bad value {value!r}")
    if origin is typing.Literal:
        if value not in args:
            raise ConfigReadError(f"{where}: {value!r} is not one of {list(args)}")
        return value
    if origin in (tuple, list):
        if not isinstance(value, (list, tuple)):
            raise ConfigReadError(f"{where}: expected a list, got {value!r}")
        item = args[0] if args else Any
        items = [_coerce(v, item, where) for v in value]
        return tuple(items) if origin is tuple else items
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigReadError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigReadError(f"{where}: expected an integer, got {value!r}")
        return value
    if hint is bool:
        if isinstance(value, dict):  # a former section of which only the switch is left
            key = where.replace(": ", ".").rsplit(".", 1)[-1]
            raise ConfigReadError(
                f"{where}: is now a bool, not a mapping: write `{key}: true` or `{key}: false`"
            )
        if not isinstance(value, bool):
            raise ConfigReadError(f"{where}: expected true or false, got {value!r}")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise ConfigReadError(f"{where}: expected a string, got {value!r}")
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
