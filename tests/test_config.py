"""Strict config merging: defaults in code, YAML overrides, unknown keys rejected."""

from __future__ import annotations

import importlib
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import pytest

from radar_slam.config import configs_dir, merge, read_yaml, write_yaml
from radar_slam.errors import ConfigError
from radar_slam.graph import GraphConfig
from radar_slam.loops.config import (
    ConsistencyConfig,
    LoopClosureConfig,
    ThrottleConfig,
    VerificationConfig,
)
from radar_slam.maps.config import LocalizerConfig, MapsConfig
from radar_slam.pipeline.config import PipelineConfig, load_config
from raplace.config_io import to_dict


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


ACCEPTED_KEYS = {
    "dataset": (
        "range_resolution_m azimuth_offset_rad scan_rate_hz gt_time_offset_s lever_arm_m topic "
        "gt_topic layout rows azimuth_direction"
    ),
    "odometry": (
        "preprocess.bin_size_m preprocess.min_range_m preprocess.max_range_m "
        "preprocess.ring_noise_removal preprocess.noise_floor_sigmas coarse.cell_m fine.cell_m "
        "quality.min_peak_quality quality.max_speed_mps quality.max_yaw_rate_dps "
        "quality.sigma_scale keyframe.max_translation_m keyframe.max_rotation_deg "
        "keyframe.max_frames deskew"
    ),
    "loop_closure": (
        "enabled candidates max_descriptor_distance query_spacing_m recent_path_m "
        "odometry_drift_fraction verification.max_translation_m "
        "verification.min_refined_quality consistency.min_support throttle.closed_spacing_m"
    ),
    "graph": "loop_kernel loop_kernel_width final_pass",
    "maps": (
        "keyframe_spacing_m localization.candidates localization.max_descriptor_distance "
        "localization.fix_every_m localization.lost_after_m"
    ),
    "concurrency": "loop_thread loop_lag_scans read_ahead_scans",
}


def leaf_keys(tree: dict[str, Any], prefix: str = "") -> set[str]:
    keys = set()
    for key, value in tree.items():
        path = f"{prefix}{key}"
        keys |= leaf_keys(value, f"{path}.") if isinstance(value, dict) else {path}
    return keys


def test_the_reader_accepts_exactly_the_documented_keys() -> None:
    """Every key a user can set, and no other: each one set to its default reads back."""
    expected = {f"{section}.{k}" for section, keys in ACCEPTED_KEYS.items() for k in keys.split()}
    assert len(expected) <= 50
    defaults = to_dict(PipelineConfig())
    assert leaf_keys(defaults) == expected
    assert merge(PipelineConfig, PipelineConfig(), defaults, "all.yaml") == PipelineConfig()
    readme = (configs_dir() / "README.md").read_text()
    assert [key for key in sorted(expected) if f"`{key}`" not in readme] == []


@pytest.mark.parametrize(
    ("overrides", "replacement"),
    [
        ({"odometry": {"quality": {"min_sigma_xy_m": 0.1}}}, "odometry.registration.MIN_SIGMA"),
        ({"odometry": {"deskew": {"enabled": True}}}, "odometry.deskew: is now a bool"),
        ({"loop_closure": {"refinement": {"deskew": False}}}, "uses the odometry: section"),
        ({"loop_closure": {"raplace": {"pose": {"n_theta": 90}}}}, "config.LOOP_RAPLACE"),
        ({"loop_closure": {"covariance": {"sigma_scale": 2}}}, "verification.LOOP_COVARIANCE"),
        ({"loop_closure": {"scan_cache_mb": 64}}, "verifies a database scan from its record"),
        (
            {"loop_closure": {"verification": {"max_disagreement_m": 2}}},
            "loops.verification.MAX_DISAGREEMENT_M",
        ),
        ({"loop_closure": {"consistency": {"window_m": 30}}}, "loops.consistency.WINDOW_M"),
        ({"loop_closure": {"throttle": {"max_gap_m": 50}}}, "loops.throttle.MAX_GAP_M"),
        ({"graph": {"settled_chi2": 5}}, "pipeline.slam.SETTLED_CHI2"),
        ({"graph": {"isam2_relinearize_skip": 3}}, "graph.REFINED_ISAM2_RELINEARIZATION"),
        ({"maps": {"image": {"size_px": 200}}}, "maps.images.KEYFRAME_IMAGE"),
        ({"maps": {"localization": {"window_fixes": 3}}}, "maps.localizer.WINDOW_FIXES"),
    ],
)
def test_a_removed_key_names_what_replaced_it(overrides: dict[str, Any], replacement: str) -> None:
    with pytest.raises(ConfigError, match="old.yaml: ") as info:
        merge(PipelineConfig, PipelineConfig(), overrides, "old.yaml")
    assert replacement in str(info.value)
    assert "\n" not in str(info.value)


def test_every_named_replacement_exists() -> None:
    """The constants the removed keys' messages name are there, under those names."""
    classes = [
        GraphConfig,
        LoopClosureConfig,
        VerificationConfig,
        ConsistencyConfig,
        ThrottleConfig,
        MapsConfig,
        LocalizerConfig,
    ]
    names = [
        name
        for cls in classes
        for message in cls.REMOVED_KEYS.values()  # type: ignore[attr-defined]
        for name in re.findall(r"radar_slam\.[\w.]+\.[A-Z][A-Z0-9_]+", message)
    ]
    assert len(names) >= 30
    for name in names:
        module, constant = name.rsplit(".", 1)
        assert hasattr(importlib.import_module(module), constant), name


def test_shipped_configs_read() -> None:
    for path in sorted(configs_dir().glob("*.yaml")):
        load_config(path.stem)
