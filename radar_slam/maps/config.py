"""Settings of map building and localisation (the `maps` section of a radar-slam config)."""

from __future__ import annotations

from dataclasses import dataclass, field

from radar_slam.maps.images import ImageGeometry
from raplace import checks


@dataclass(frozen=True)
class LocalizerConfig:
    """Relocalisation and tracking in a map (`radar_slam.maps.localizer`).

    Attributes:
        candidates: RaPlace candidates verified per global relocalisation attempt.
        max_descriptor_distance: candidates at or above this RaPlace distance are not verified.
        relocalise_every_m: while lost with no hypothesis held, a global attempt after this much
            travel [m] (0: every scan); once one is held, every scan is an attempt.
        confirm_max_error_m: a global fix is only believed once further hypotheses agree, each
            with the previous one carried forward by the odometry, within this distance [m]
            (from how many keyframes: `radar_slam.maps.localizer.CONFIRM_KEYFRAMES`) ...
        confirm_max_error_deg: ... and this rotation [deg].
        fix_every_m: while tracking, a map fix is attempted after this much travel [m].
        search_radius_m: tracking fixes use the map keyframes within this distance of the
            predicted pose [m], nearest first.
        fix_keyframes: at most this many keyframes are tried per tracking fix (and per
            attempt to complete a relocalisation's agreeing hypotheses with one).
        max_innovation_m: a tracking fix farther than this from the prediction is refused [m] ...
        max_innovation_deg: ... or turned more than this from it [deg].
        lost_after_m: tracking without a successful fix for this much travel is lost [m].
        window_fixes: the sliding window keeps the scans of this many latest fixes.
        map_sigma_xy_m: standard deviation of the map keyframe poses in the window graph [m].
        map_sigma_yaw_deg: the same for their rotation [deg].
    """

    candidates: int = 3
    max_descriptor_distance: float = 0.25
    relocalise_every_m: float = 4.0
    confirm_max_error_m: float = 1.5
    confirm_max_error_deg: float = 3.0
    fix_every_m: float = 10.0
    search_radius_m: float = 12.0
    fix_keyframes: int = 2
    max_innovation_m: float = 2.0
    max_innovation_deg: float = 4.0
    lost_after_m: float = 40.0
    window_fixes: int = 6
    map_sigma_xy_m: float = 0.05
    map_sigma_yaw_deg: float = 0.1

    def __post_init__(self) -> None:
        checks.at_least("candidates", self.candidates, 1)
        checks.positive("max_descriptor_distance", self.max_descriptor_distance)
        checks.non_negative("relocalise_every_m", self.relocalise_every_m)
        for name in ("confirm_max_error_m", "confirm_max_error_deg", "fix_every_m"):
            checks.positive(name, getattr(self, name))
        checks.positive("search_radius_m", self.search_radius_m)
        checks.at_least("fix_keyframes", self.fix_keyframes, 1)
        checks.positive("max_innovation_m", self.max_innovation_m)
        checks.positive("max_innovation_deg", self.max_innovation_deg)
        checks.positive("lost_after_m", self.lost_after_m)
        checks.at_least("window_fixes", self.window_fixes, 1)
        checks.positive("map_sigma_xy_m", self.map_sigma_xy_m)
        checks.positive("map_sigma_yaw_deg", self.map_sigma_yaw_deg)


@dataclass(frozen=True)
class MapsConfig:
    """Map building and use.

    Attributes:
        keyframe_spacing_m: a scan becomes a map keyframe after this much odometry path [m].
        image: the stored keyframe images (`radar_slam.maps.images.ImageGeometry`).
        localization: relocalisation and tracking (`LocalizerConfig`).
    """

    keyframe_spacing_m: float = 4.0
    image: ImageGeometry = field(default_factory=ImageGeometry)
    localization: LocalizerConfig = field(default_factory=LocalizerConfig)

    def __post_init__(self) -> None:
        checks.positive("keyframe_spacing_m", self.keyframe_spacing_m)
