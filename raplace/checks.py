"""Range checks of configuration values, shared by every config dataclass's `__post_init__`.

Plain functions on plain numbers (no numpy): each raises `ValueError("<field>: <what is wrong>,
got <value>")` naming the field and the offending value. `radar_slam.config.merge` prefixes the
message with the file and the section path, so a user reads e.g.
"my.yaml: odometry.keyframe.max_translation_m: must be positive, got -1.0".
"""

from __future__ import annotations

import math
from collections.abc import Iterable


def _number(name: str, value: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{name}: expected a number, got {value!r}")
    if math.isnan(value):
        raise ValueError(f"{name}: must be a number, got NaN")
    return float(value)


def finite(name: str, value: float) -> None:
    """`value` is a finite number."""
    if not math.isfinite(_number(name, value)):
        raise ValueError(f"{name}: must be finite, got {value}")


def positive(name: str, value: float, allow_inf: bool = False) -> None:
    """`value` > 0 (and finite unless `allow_inf`: an infinite threshold disables a test)."""
    number = _number(name, value)
    if not number > 0 or (math.isinf(number) and not allow_inf):
        raise ValueError(f"{name}: must be a positive number, got {value}")


def non_negative(name: str, value: float, allow_inf: bool = False) -> None:
    """`value` >= 0 (and finite unless `allow_inf`)."""
    number = _number(name, value)
    if not number >= 0 or (math.isinf(number) and not allow_inf):
        raise ValueError(f"{name}: must be >= 0, got {value}")


def in_range(
    name: str,
    value: float,
    low: float,
    high: float,
    open_low: bool = False,
    open_high: bool = False,
) -> None:
    """low <= `value` <= high (strict at an end marked open)."""
    number = _number(name, value)
    above = number > low if open_low else number >= low
    below = number < high if open_high else number <= high
    if not (above and below):
        interval = f"{'(' if open_low else '['}{low}, {high}{')' if open_high else ']'}"
        raise ValueError(f"{name}: must be in {interval}, got {value}")


def at_least(name: str, value: int, minimum: int) -> None:
    """`value` is an integer >= `minimum`."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"{name}: expected an integer, got {value!r}")
    if value < minimum:
        raise ValueError(f"{name}: must be an integer >= {minimum}, got {value}")


def even(name: str, value: int) -> None:
    """`value` is an even integer."""
    if isinstance(value, bool) or not isinstance(value, int) or value % 2:
        raise ValueError(f"{name}: must be an even integer, got {value!r}")


def less(low_name: str, low: float, high_name: str, high: float) -> None:
    """`low` < `high` (e.g. a minimum and a maximum range)."""
    if not _number(low_name, low) < _number(high_name, high):
        raise ValueError(f"{low_name}: must be less than {high_name} ({high}), got {low}")


def one_of(name: str, value: object, choices: Iterable[object]) -> None:
    """`value` is one of `choices`."""
    options = list(choices)
    if value not in options:
        raise ValueError(f"{name}: {value!r} is not one of {options}")
