"""Strict config merging: defaults in code, YAML overrides, unknown keys rejected."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import pytest

from radar_slam.config import merge, read_yaml, write_yaml
from radar_slam.errors import ConfigError


@dataclass(frozen=True)
class Inner:
    sigma: float = 0.1
    kernel: Literal["cauchy", "huber"] = "cauchy"


@dataclass(frozen=True)
class Outer:
    frames: int | None = None
    name: str = "x"
    scales: tuple[float, ...] = (1.0, 2.0)
    inner: Inner = field(default_factory=Inner)


def test_override_nested_and_coerce(tmp_path: Path) -> None:
    path = tmp_path / "c.yaml"
    path.write_text("frames: 5\nscales: [3, 4.5]\ninner:\n  sigma: 2\n  kernel: huber\n")
    cfg = merge(Outer, Outer(), read_yaml(path), str(path))
    assert cfg.frames == 5 and cfg.scales == (3.0, 4.5)
    assert cfg.inner == Inner(sigma=2.0, kernel="huber")
    assert cfg.name == "x"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("inner:\n  sigmaa: 1\n", "bad.yaml: inner: unknown key 'sigmaa'"),
        ("framez: 1\n", "unknown key 'framez'"),
        ("frames: abc\n", "bad.yaml: frames: expected an integer"),
        ("inner:\n  kernel: tukey\n", "not one of"),
        ("inner: 3\n", "expected a mapping"),
        ("- a\n- b\n", "must be a mapping"),
        ("a: [1, 2\n", "not valid YAML"),
    ],
)
def test_bad_config_names_file_and_key(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message) as info:
        merge(Outer, Outer(), read_yaml(path), str(path))
    assert str(path) in str(info.value)


def test_write_then_read_round_trip(tmp_path: Path) -> None:
    cfg = Outer(frames=3, scales=(0.5,), inner=Inner(sigma=0.2))
    write_yaml(cfg, tmp_path / "used.yaml")
    again = merge(Outer, Outer(), read_yaml(tmp_path / "used.yaml"), "used.yaml")
    assert again == cfg


def test_missing_file_is_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        read_yaml(tmp_path / "nope.yaml")
