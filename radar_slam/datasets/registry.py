"""Registry of dataset families, addressed as `family/sequence` or by a plain folder path.

A loader module registers its family at import (`register(Family(...))`). Families that live
outside this package (the simulator's `synthetic`) are plug-ins: modules named by the
`radar_slam.datasets` entry-point group (pyproject.toml), imported on the first lookup.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from dataclasses import asdict, dataclass
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any, Literal

from radar_slam.datasets.frame import RadarSequence
from raplace import checks

log = logging.getLogger(__name__)

PLUGIN_GROUP = "radar_slam.datasets"
"""Entry-point group of dataset-family plug-ins: each names a module that registers a family."""
DATA_ROOT_ENV = "RADAR_SLAM_DATA"
DEFAULT_DATA_ROOT = Path("data")


@dataclass(frozen=True)
class DatasetConfig:
    """Loader settings a user may need to override: the `dataset:` section of a config file.

    Attributes:
        range_resolution_m: size of one range bin [m]; None keeps the loader's own value (Oxford:
            0.0438 from the dataset documentation, while the official SDK hard-codes 0.0432;
            MulRan: 0.05952; synthetic: the simulated sensor's).
        topic, gt_topic: ROS bags: the scan image topic (None: the only mono8 image topic) and
            an Odometry / PoseStamped ground-truth topic.
        layout: ROS bags: image layout preset ("radar-slam", "navtech", "mulran").
        rows, azimuth_direction: ROS bags: override the preset ("azimuths" or "bins" per row;
            "cw" or "ccw" seen from above).
        azimuth_offset_rad: added to every scan azimuth [rad, CCW]: an encoder zero that is
            not the vehicle's forward axis (or the ground truth's). None is 0 (no correction);
            see the README for what the Oxford samples show.
        scan_rate_hz: revolutions per second of a radar whose files carry no azimuth times
            (MulRan layout), which the azimuth times are spread over; None keeps the loader's
            own (MulRan: 4; synthetic: the simulated sensor's).
        gt_time_offset_s: ground-truth clock minus radar clock [s]: a scan stamped t takes the
            GT pose of time t + offset. `radar-slam eval` estimates it. None is 0.
        lever_arm_m: RADIATE: the radar's (x forward, y left) position relative to the GNSS
            antenna [m]; None is (0, 0).
    """

    range_resolution_m: float | None = None
    azimuth_offset_rad: float | None = None
    scan_rate_hz: float | None = None
    gt_time_offset_s: float | None = None
    lever_arm_m: tuple[float, float] | None = None
    # ROS bags only (radar_slam.datasets.rosbag): scan and GT topics, image layout.
    topic: str | None = None
    gt_topic: str | None = None
    layout: str | None = None
    rows: Literal["azimuths", "bins"] | None = None
    azimuth_direction: Literal["cw", "ccw"] | None = None

    def __post_init__(self) -> None:
        if self.range_resolution_m is not None:
            checks.positive("range_resolution_m", self.range_resolution_m)
        if self.azimuth_offset_rad is not None:
            checks.finite("azimuth_offset_rad", self.azimuth_offset_rad)
        if self.scan_rate_hz is not None:
            checks.positive("scan_rate_hz", self.scan_rate_hz)
        if self.gt_time_offset_s is not None:
            checks.finite("gt_time_offset_s", self.gt_time_offset_s)
        if self.lever_arm_m is not None:
            if len(self.lever_arm_m) != 2:
                raise ValueError(f"lever_arm_m must be [x, y] in metres, got {self.lever_arm_m}")
            for value in self.lever_arm_m:
                checks.finite("lever_arm_m", value)

    def loader_options(self) -> dict[str, Any]:
        """The keyword arguments to pass to a family's `open` (only the values that are set)."""
        return {key: value for key, value in asdict(self).items() if value is not None}


@dataclass(frozen=True)
class Family:
    """A dataset family.

    Attributes:
        name: family key, e.g. "mulran".
        open: builds a RadarSequence from a sequence folder; accepts the keyword arguments of
            `DatasetConfig.loader_options()`.
        detect: True when a folder looks like a sequence of this family.
        layout: human description of the expected folder layout (for error messages).
        obtain: where the dataset can be obtained (for error messages).
        resolve: optional hook turning (root, sequence name) into a folder, creating it if the
            family generates its data (synthetic); None means `<root>/<family>/<sequence>`.
        detect_priority: families with a higher priority are tried first when detecting a
            folder's format, so a specialised layout (synthetic, a MulRan layout plus a marker
            file) wins over the general one it extends.
        options: the `DatasetConfig` keys `open` accepts.
    """

    name: str
    open: Callable[..., RadarSequence]
    detect: Callable[[Path], bool]
    layout: str
    obtain: str
    resolve: Callable[[Path, str], Path] | None = None
    detect_priority: int = 0
    options: tuple[str, ...] = ("range_resolution_m", "azimuth_offset_rad", "gt_time_offset_s")


_FAMILIES: dict[str, Family] = {}
_plugins_loaded = False


def register(family: Family) -> Family:
    """Add a family to the registry (called once at import of its loader module)."""
    if family.name in _FAMILIES:
        raise ValueError(f"dataset family {family.name!r} registered twice")
    _FAMILIES[family.name] = family
    return family


def load_plugins() -> None:
    """Import the plug-in modules of the `radar_slam.datasets` entry points (once)."""
    global _plugins_loaded
    if _plugins_loaded:
        return
    _plugins_loaded = True
    for plugin in entry_points(group=PLUGIN_GROUP):
        plugin.load()
        log.debug("dataset plug-in %s loaded from %s", plugin.name, plugin.value)


def families() -> dict[str, Family]:
    """All registered families by name (plug-ins included)."""
    load_plugins()
    return dict(_FAMILIES)


def data_root(explicit: str | os.PathLike[str] | None = None) -> Path:
    """The data root: `explicit`, else $RADAR_SLAM_DATA, else ./data."""
    if explicit is not None:
        return Path(explicit).expanduser()
    env = os.environ.get(DATA_ROOT_ENV)
    return Path(env).expanduser() if env else DEFAULT_DATA_ROOT


def family_folder(root: Path, family: str) -> Path:
    """`<root>/<family>`, matching the family folder name case-insensitively (e.g. `MulRan/`)."""
    exact = root / family
    if exact.is_dir() or not root.is_dir():
        return exact
    for child in root.iterdir():
        if child.is_dir() and child.name.lower() == family.lower():
            return child
    return exact


def detect_family(folder: Path) -> Family | None:
    """The family whose layout `folder` matches (highest detect_priority first), or None."""
    for family in sorted(families().values(), key=lambda f: -f.detect_priority):
        if family.detect(folder):
            return family
    return None
