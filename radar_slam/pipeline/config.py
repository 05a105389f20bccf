"""Settings of a SLAM run: defaults in code, then the family's shipped YAML, then the user's."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from odometry import OdometryConfig
from radar_slam.config import configs_dir, merge, read_yaml
from radar_slam.datasets import DatasetConfig, locate_sequence, open_located
from radar_slam.datasets.frame import RadarSequence
from radar_slam.errors import ConfigError
from radar_slam.graph import GraphConfig
from radar_slam.loops import (
    LoopClosureConfig,
)
from radar_slam.maps.config import MapsConfig
from raplace import checks


@dataclass(frozen=True)
class ConcurrencyConfig:
    """How a run uses threads (results do not depend on it, see `radar_slam.pipeline.concurrency`).

    Attributes:
        loop_thread: run the loop detector (RaPlace query, verification) on a worker thread
            while the odometry goes on; False runs it in the main thread (same results).
        loop_lag_scans: the loops found for scan k enter the pose graph when the run reaches
            scan k + this (also without the thread, so that both give the same results); the
            main thread waits for the worker when it is later than that.
        read_ahead_scans: scans read ahead on a reader thread (0: read in the main thread).

    The threads start only when the process may run on more than one CPU
    (`radar_slam.pipeline.concurrency.usable_cpus`): on one they would only contend.
    """

    loop_thread: bool = True
    loop_lag_scans: int = 8
    read_ahead_scans: int = 4

    def __post_init__(self) -> None:
        checks.at_least("loop_lag_scans", self.loop_lag_scans, 0)
        checks.at_least("read_ahead_scans", self.read_ahead_scans, 0)


@dataclass(frozen=True)
class PipelineConfig:
    """All settings of a SLAM run, one section per stage (each stage gets only its own)."""

    dataset: DatasetConfig = field(default_factory=DatasetConfig)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    loop_closure: LoopClosureConfig = field(default_factory=LoopClosureConfig)
    graph: GraphConfig = field(default_factory=GraphConfig)
    maps: MapsConfig = field(default_factory=MapsConfig)  # map building, localisation
    concurrency: ConcurrencyConfig = field(default_factory=ConcurrencyConfig)


def family_config_path(family: str) -> Path:
    """The shipped YAML overrides of a dataset family (may not exist)."""
    return configs_dir() / f"{family}.yaml"


def load_config(
    family: str | None = None,
    path: Path | None = None,
    overrides: dict[str, Any] | None = None,
) -> PipelineConfig:
    """Defaults in code, then `configs/<family>.yaml` (when shipped), then the file `path`, then
    `overrides` (a nested mapping). Unknown keys and wrong types are `ConfigError`s."""
    return _merged(_family_layers(family) + _user_layers(path, overrides))


_Layer = tuple[dict[str, Any], str]
"""A mapping of config keys and where it came from (for error messages)."""


def _user_layers(path: Path | None, overrides: dict[str, Any] | None) -> list[_Layer]:
    """The user's layers: the file `path` (read once here), then `overrides`."""
    layers: list[_Layer] = []
    if path is not None:
        path = Path(path)
        if not path.is_file():
            raise ConfigError(f"{path}: config file not found")
        layers.append((read_yaml(path), str(path)))
    if overrides:
        layers.append((overrides, "overrides"))
    return layers


def _family_layers(family: str | None) -> list[_Layer]:
    """The family's shipped YAML as a layer (read once here), or none."""
    if family is None:
        return []
    shipped = family_config_path(family)
    return [(read_yaml(shipped), str(shipped))] if shipped.is_file() else []


def _merged(layers: list[_Layer]) -> PipelineConfig:
    """Defaults, then `layers` in order."""
    config = PipelineConfig()
    for values, source in layers:
        config = merge(PipelineConfig, config, values, source)
    return config


def open_configured(
    spec: str,
    data_root: Path | None = None,
    path: Path | None = None,
    overrides: dict[str, Any] | None = None,
) -> tuple[RadarSequence, PipelineConfig]:
    """Open a sequence and load its configuration (defaults, `configs/<family>.yaml`, `path`,
    then `overrides`).

    Each file is read once and the sequence is opened once. The user's layers are checked
    first, so that a mistake fails before any data is generated; the sequence is then located
    (not opened) to know its family, which selects the shipped overrides, and opened with the
    loader settings of the whole configuration. The ground truth is then read, so that a
    malformed file fails before any work rather than after it; a malformed scan fails when the
    run reads it (the first scan is the run's first step: reading it here would decode it twice).
    """
    ((sequence, config),) = open_configurations(spec, data_root, path, [overrides or {}])
    return sequence, config


def open_configurations(
    spec: str,
    data_root: Path | None,
    path: Path | None,
    overrides: list[dict[str, Any]],
) -> list[tuple[RadarSequence, PipelineConfig]]:
    """`open_configured` for several configurations of one sequence (e.g. the grid of a
    `radar-slam batch`): one (sequence, configuration) per entry of `overrides`, in order.

    Each file is read once, and the sequence is opened once per distinct `dataset:` section (the
    loader settings): configurations that share it share the opened sequence.
    """
    user = _user_layers(path, None)
    every = [user + ([(extra, "overrides")] if extra else []) for extra in overrides]
    for layers in every:
        _merged(layers)  # a mistake fails before any data is generated
    family, location = locate_sequence(spec, data_root)
    shipped = _family_layers(family.name)
    configs = [_merged(shipped + layers) for layers in every]
    opened: list[tuple[DatasetConfig, RadarSequence]] = []
    for config in configs:
        if not any(loader == config.dataset for loader, _ in opened):
            sequence = open_located(family, location, config.dataset)
            _ = sequence.ground_truth  # a malformed GT file fails now, not after the run
            opened.append((config.dataset, sequence))
    return [
        (next(seq for loader, seq in opened if loader == config.dataset), config)
        for config in configs
    ]
