"""Maps that last: save a SLAM run as a map, relocalise in it, extend it with new sessions.

    from radar_slam.maps import Localizer, Map
    m = Map.load("results/synthetic_multisession_a/latest/map")
    localizer = Localizer(m, config)
    for frame in sequence: fix = localizer.localize(frame)

The on-disk format is specified in docs/map_format.md. The map I/O (`format`, `images`,
`config`) does not import GTSAM; the names built on the pose graph (`build_map`, `Localizer`,
`join_session`, `InterSessionQueries`) are imported on first use (PEP 562), so
`import radar_slam.maps` stays light.
"""

from __future__ import annotations

from radar_slam.lazy import lazy_exports
from radar_slam.maps.config import LocalizerConfig, MapsConfig
from radar_slam.maps.format import Map, MapError, Session, read_map, write_map
from radar_slam.maps.images import ImageGeometry, KeyframeImager

_LAZY = {
    "build_map": "radar_slam.maps.build",
    "Localization": "radar_slam.maps.localizer",
    "Localizer": "radar_slam.maps.localizer",
    "InterSessionQueries": "radar_slam.maps.session",
    "JoinedSession": "radar_slam.maps.session",
    "join_session": "radar_slam.maps.session",
}

__all__ = [
    "ImageGeometry",
    "InterSessionQueries",
    "JoinedSession",
    "KeyframeImager",
    "Localization",
    "Localizer",
    "LocalizerConfig",
    "Map",
    "MapError",
    "MapsConfig",
    "Session",
    "build_map",
    "join_session",
    "read_map",
    "write_map",
]


__getattr__, __dir__ = lazy_exports(__name__, _LAZY)
