"""Maps that last: save a SLAM run as a map, relocalise in it, extend it with new sessions.

    from radar_slam.maps import Map, Localizer
    m = Map.load("results/synthetic_multisession_a/latest/map")
    localizer = Localizer(m, config)
    for frame in sequence: fix = localizer.localize(frame)

The on-disk format is specified in docs/map_format.md.
"""

from radar_slam.maps.build import build_map
from radar_slam.maps.config import LocalizerConfig, MapsConfig
from radar_slam.maps.format import Map, MapError, Session, read_map, write_map
from radar_slam.maps.images import ImageGeometry, KeyframeImager

__all__ = [
    "ImageGeometry",
    "KeyframeImager",
    "LocalizerConfig",
    "Map",
    "MapError",
    "MapsConfig",
    "Session",
    "build_map",
    "read_map",
    "write_map",
]
