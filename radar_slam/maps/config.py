"""Settings of map building and localisation (the `maps` section of a radar-slam config)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from raplace import checks
from raplace.config_io import replaced_by_constant, replaced_by_constants


@dataclass(frozen=True)
class LocalizerConfig:
    """Relocalisation and tracking in a map (`radar_slam.maps.localizer`; how fixes are checked
    and weighted is constants there).

    Attributes:
        candidates: RaPlace candidates verified per global relocalisation attempt. More finds
            the place sooner in a large map, at one verification each.
        max_descriptor_distance: candidates at or above this RaPlace distance are not verified.
            Raise it when a map made in other conditions (season, traffic) is not recognised.
        fix_every_m: while tracking, a map fix is attempted after this much travel [m]. Lower
            means a tighter track and more work per metre.
        lost_after_m: tracking without a successful fix for this much travel is lost [m];
            longer trusts the odometry for longer (a better odometry, a sparser map).
    """

    REMOVED_KEYS: ClassVar[dict[str, str]] = replaced_by_constants(
        "radar_slam.maps.localizer",
        "relocalise_every_m",
        "confirm_max_error_m",
        "confirm_max_error_deg",
        "search_radius_m",
        "fix_keyframes",
        "max_innovation_m",
        "max_innovation_deg",
        "window_fixes",
        "map_sigma_xy_m",
        "map_sigma_yaw_deg",
    )
    candidates: int = 3
    max_descriptor_distance: float = 0.25
    fix_every_m: float = 10.0
    lost_after_m: float = 40.0

    def __post_init__(self) -> None:
        checks.at_least("candidates", self.candidates, 1)
        checks.positive("max_descriptor_distance", self.max_descriptor_distance)
        checks.positive("fix_every_m", self.fix_every_m)
        checks.positive("lost_after_m", self.lost_after_m)


@dataclass(frozen=True)
class MapsConfig:
    """Map building and use.

    Attributes:
        keyframe_spacing_m: a scan becomes a map keyframe after this much odometry path [m].
            Lower makes a denser map (more bytes, easier relocalisation); higher a smaller one.
        localization: relocalisation and tracking (`LocalizerConfig`).
    """

    REMOVED_KEYS: ClassVar[dict[str, str]] = {
        "image": replaced_by_constant(
            "radar_slam.maps.images.KEYFRAME_IMAGE; a map records its own"
        ),
    }
    keyframe_spacing_m: float = 4.0
    localization: LocalizerConfig = field(default_factory=LocalizerConfig)

    def __post_init__(self) -> None:
        checks.positive("keyframe_spacing_m", self.keyframe_spacing_m)
