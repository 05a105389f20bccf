"""Localisation in a map: global relocalisation, then tracking fused in a sliding window.

`Localizer(map, config).localize(frame)` places each scan in the map frame:

- **lost -> relocalised.** Every `RELOCALISE_EVERY_M` of travel the scan's RaPlace descriptor is
  looked up in the whole map (no exclusion window) and the best candidates are verified as loops
  are (`radar_slam.loops.GeometricVerifier`, both pi hypotheses of the rotation, against the
  keyframe's stored image made back into a scan); each that verifies gives a pose hypothesis
  T_map_scan = T_map_keyframe * z^-1, best registration quality first. Hypotheses are only
  believed once they make a chain (attempted at every scan once one is held), each agreeing with
  the previous one carried forward by the odometry (`CONFIRM_MAX_ERROR_M/_DEG`), from
  `CONFIRM_KEYFRAMES` distinct keyframes over `CONFIRM_SCANS` scans or more: the keyframes' own
  map poses must then agree with each other and with the path driven, which a wrong match, or a
  run of them on a repetitive street, rarely does. The last keyframe may come from a tracking
  fix (below) against the keyframes nearest the chain's pose: entering the map's route, the
  vehicle matches the first keyframes long before a third is among the global candidates.
- **tracked.** Our odometry predicts the pose; every `fix_every_m` the scan is registered by
  phase correlation (`odometry.registration`, the loop verifier's refinement stage, with the
  predicted relative yaw in place of its sinogram stage) against the nearest map keyframes to
  the prediction (within `SEARCH_RADIUS_M`). A fix with a strong peak that agrees with
  the prediction (`MAX_INNOVATION_M/_DEG`) enters a small pose graph (`radar_slam.graph`): the
  scans of the latest `WINDOW_FIXES` fixes joined by the odometry between them, each fix a loop
  factor (robust kernel) to its keyframe, the keyframes held by tight priors at their map poses.
  The fused pose of the newest scan is the new anchor of the prediction.
- **lost.** A failed tracking fix is tried again at the next scan; once `FAILED_FIXES_LOST` in
  a row have failed, the registration to the map has weakened: the scans are reported lost (the
  odometry still carries the prediction, and a fix that agrees with it resumes tracking).
  After `lost_after_m` of travel without an accepted fix, tracking has lost the map: back to
  global relocalisation.

Each localised scan comes with the covariance of its pose (`Localization.covariance`): the
latest fix's registration and map keyframe uncertainty, carried forward through the odometry's
covariance since. `Localization.relative` is the pose relative to that fix's map keyframe, the
form of the Boreas localisation benchmark.
"""

from __future__ import annotations

import dataclasses
import logging
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import NDArray

from odometry import (
    Odometry,
    OdometryResult,
    PreparedScan,
    RadarFrame,
    Scan,
    register,
    twist_from_motion,
)
from radar_slam.config import merge
from radar_slam.errors import ConfigError, GraphError
from radar_slam.graph import GraphConfig, PoseGraph
from radar_slam.loops import (
    GeometricVerifier,
    KeyScan,
    Verification,
    loop_covariance,
)
from radar_slam.loops.config import LOOP_RAPLACE
from radar_slam.loops.records import raplace_input
from radar_slam.loops.verification import LOOP_COVARIANCE
from radar_slam.maps.format import Map, MapError
from radar_slam.maps.images import ImageGeometry, KeyframeImager
from raplace import (
    NS_PER_S,
    DescriptorConfig,
    DescriptorExtractor,
    ExclusionConfig,
    PlaceRecognizer,
    adjoint,
    between,
    compose,
    inverse,
    rotate_covariance,
    wrap_angle,
)

if TYPE_CHECKING:
    from radar_slam.pipeline import PipelineConfig

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
Status = Literal["relocalised", "tracked", "lost"]
MAP_KEY_BASE = 1 << 40
"""Graph keys of map keyframes in the window graph (scan keys are scan indices)."""
IMAGE_CACHE_SIZE = 64
"""Map keyframes kept as ready-made scans."""
_WINDOW_GRAPH = GraphConfig(final_pass="lm")
CONFIRM_KEYFRAMES = 3
"""Distinct map keyframes a chain of agreeing global hypotheses must come from before a fix is
believed: matches to one keyframe agree with each other whatever its map pose, and two
neighbouring keyframes of a wrong street, repeated facades for instance, can agree with each
other and with a short drive; a third rarely does (`Localizer._complete_chain`)."""
CONFIRM_SCANS = 2
"""Scans the chain must span: the odometry between them checks the keyframes' relative poses
against the path driven, which one scan's matches alone cannot."""
RELOCALISE_EVERY_M = 4.0
"""While lost with no hypothesis held, a global attempt after this much travel [m]; once one is
held, every scan is an attempt."""
CONFIRM_MAX_ERROR_M = 1.5
"""A global fix is only believed once further hypotheses agree, each with the previous one carried
forward by the odometry, within this distance [m] ..."""
CONFIRM_MAX_ERROR_DEG = 3.0
"""... and this rotation [deg]."""
SEARCH_RADIUS_M = 12.0
"""Tracking fixes use the map keyframes within this distance of the predicted pose [m], nearest
first."""
FIX_KEYFRAMES = 2
"""At most this many keyframes are tried per tracking fix (and per attempt to complete a
relocalisation's agreeing hypotheses with one)."""
MAX_INNOVATION_M = 2.0
"""A tracking fix farther than this from the prediction is refused [m] ..."""
MAX_INNOVATION_DEG = 4.0
"""... or turned more than this from it [deg]."""
WINDOW_FIXES = 6
"""The sliding window keeps the scans of this many latest fixes."""
MAP_SIGMA_XY_M = 0.05
"""Standard deviation of the map keyframe poses in the window graph and in a joined session's
graph [m] ..."""
MAP_SIGMA_YAW_DEG = 0.1
"""... and of their rotation [deg]."""
FAILED_FIXES_LOST = 2
"""Tracking fix attempts failing in a row after which the scans are reported lost: one can fail
on a passing truck; two in a row mean the map no longer supports the pose, which is then only
the odometry's extrapolation. After a failed attempt the next scan tries again (not
`fix_every_m` later), so a track that leaves the map is reported lost one scan after its first
failed fix rather than a fix spacing later."""


@dataclass(frozen=True)
class Localization:
    """Where one scan is in the map (a row of localization.csv).

    Attributes:
        timestamp_ns: the scan's time [ns].
        status: "relocalised" (placed by global relocalisation now), "tracked" or "lost".
        pose: (3,) T_map_radar (x, y [m], yaw [rad]); NaN when lost.
        map_key: index of the map keyframe of the latest accepted fix (-1 when lost).
        quality: peak-to-noise ratio of that fix's phase-correlation registration to the map
            (dimensionless, 0 when lost); no fix is accepted below
            `loop_closure.verification.min_refined_quality`, and higher is a sharper match.
        relative: (3,) the pose relative to the map keyframe `map_key`, T_keyframe_radar
            (x, y [m], yaw [rad]); NaN when lost.
        covariance: (3, 3) covariance of the pose (and of `relative`) in the radar's own frame,
            GTSAM's right perturbation (x, y [m], yaw [rad]); NaN when lost.
    """

    timestamp_ns: int
    status: Status
    pose: FloatArray
    map_key: int
    quality: float
    relative: FloatArray = field(default_factory=lambda: np.full(3, np.nan))
    covariance: FloatArray = field(default_factory=lambda: np.full((3, 3), np.nan))

    @property
    def sigma_m(self) -> float:
        """Standard deviation of the position along its least certain axis [m] (NaN when lost)."""
        if not self.localised:
            return float("nan")
        return float(np.sqrt(max(0.0, float(np.linalg.eigvalsh(self.covariance[:2, :2])[-1]))))

    @property
    def localised(self) -> bool:
        return self.status != "lost"


@dataclass
class _Fix:
    """A verified match of a scan to a map keyframe."""

    scan: int
    keyframe: int
    measurement: FloatArray  # T_scan_keyframe
    covariance: FloatArray
    quality: float
    pose: FloatArray  # the scan's pose hypothesis T_map_scan


@dataclass
class _Node:
    """A scan in the sliding window: its odometry from the previous node and its fix."""

    scan: int
    motion: FloatArray  # T_previous_node_scan (zeros for the first)
    covariance: FloatArray
    fix: _Fix
    pose: FloatArray


@dataclass
class _State:
    tracking: bool = False
    anchor: FloatArray = field(default_factory=lambda: np.zeros(3))  # T_map_anchor_scan
    since: FloatArray = field(default_factory=lambda: np.zeros(3))  # T_anchor_scan
    since_cov: FloatArray = field(default_factory=lambda: np.zeros((3, 3)))
    pose_cov: FloatArray = field(default_factory=lambda: np.zeros((3, 3)))  # radar frame
    path_since_fix_m: float = 0.0
    path_since_attempt_m: float = np.inf
    failed_fixes: int = 0
    chain: list[tuple[_Fix, FloatArray, FloatArray]] = field(default_factory=list)
    pending_since: FloatArray = field(default_factory=lambda: np.zeros(3))
    pending_cov: FloatArray = field(default_factory=lambda: np.zeros((3, 3)))
    pending_path_m: float = 0.0
    window: list[_Node] = field(default_factory=list)
    last_fix: _Fix | None = None


def symmetric(matrix: FloatArray) -> FloatArray:
    """The symmetric part of a square matrix (covariances stay exactly symmetric)."""
    return 0.5 * (matrix + matrix.T)


def descriptor_config_of(m: Map) -> DescriptorConfig:
    """The descriptor settings the map was made with (queries must use the same; a map that
    records none was made with the loop closer's, `LOOP_RAPLACE`)."""
    fallback = LOOP_RAPLACE.descriptor
    stored = m.settings.get("descriptor")
    if not stored:
        return fallback
    try:
        return merge(DescriptorConfig, fallback, stored, "map.json: settings.descriptor")
    except ConfigError as exc:
        raise MapError(str(exc)) from None


def image_geometry_of(m: Map) -> ImageGeometry:
    """The keyframe image geometry recorded in the map."""
    try:
        return merge(ImageGeometry, ImageGeometry(), m.settings.get("image", {}), "map.json")
    except ConfigError as exc:
        raise MapError(str(exc)) from None


class MapKeyframes:
    """A map's keyframes as the verifier sees them: ready-made scans (cached) and a place
    database over all of them."""

    def __init__(self, m: Map, config: PipelineConfig) -> None:
        if len(m) == 0:
            raise MapError("the map has no keyframes")
        self.map = m
        self.poses = m.poses
        self.imager = KeyframeImager(image_geometry_of(m), config.odometry)
        retrieval = dataclasses.replace(LOOP_RAPLACE.retrieval, exclusion=ExclusionConfig(0, 0.0))
        self.recognizer = PlaceRecognizer(retrieval)
        self.recognizer.add_batch(
            np.asarray(m.descriptors, dtype=np.float32), np.arange(len(m), dtype=np.int64)
        )
        self._scans: OrderedDict[int, RadarFrame] = OrderedDict()

    def scan(self, index: int) -> KeyScan:
        """Keyframe `index` as a `KeyScan` (key MAP_KEY_BASE + index, no twist: de-skewed)."""
        frame = self._scans.get(index)
        if frame is None:
            row = self.map.keyframes[index]
            frame = self.imager.pseudo_scan(self.map.images[index], int(row["timestamp_ns"]))
            self._scans[index] = frame
            if len(self._scans) > IMAGE_CACHE_SIZE:
                self._scans.popitem(last=False)
        else:
            self._scans.move_to_end(index)
        return KeyScan(MAP_KEY_BASE + index, frame.timestamp_ns, frame, None)

    def near(self, pose: FloatArray, radius_m: float, count: int) -> list[int]:
        """Up to `count` keyframes within `radius_m` of `pose`, nearest first."""
        d = np.hypot(*(self.poses[:, :2] - pose[:2]).T)
        order = np.argsort(d, kind="stable")[:count]
        return [int(k) for k in order if d[k] <= radius_m]


class Localizer:
    """Places each scan of a sequence in a map's frame (see the module docstring).

    Args:
        m: the map.
        config: settings; uses its `odometry`, `loop_closure` (verification) and
            `maps.localization` sections.
    """

    def __init__(self, m: Map, config: PipelineConfig) -> None:
        self.config = config
        self.cfg = config.maps.localization
        self.keyframes = MapKeyframes(m, config)
        self.describe = DescriptorExtractor(descriptor_config_of(m))
        self.odometry = Odometry(config.odometry)
        self.verifier = GeometricVerifier(config.loop_closure, config.odometry)
        self.state = _State()
        self._prepared: PreparedScan | None = None
        self._prepared_key: int | None = None
        self.global_attempts = 0
        self.relocalisations = 0

    # -- the per-scan step ------------------------------------------------------------------
    def localize(self, frame: Scan) -> Localization:
        """Register the next scan (time order) and place it in the map."""
        result = self.odometry.register(frame)
        self._advance(result)
        prepared = self.odometry.prepared
        polar = None if prepared is None else prepared.polar
        query = KeyScan(result.index, result.timestamp_ns, frame, self._twist(result), polar=polar)
        state = self.state
        status: Status = "lost"
        if state.tracking:
            status = self._track(query)
        if not state.tracking:
            status = "relocalised" if self._relocalise(query) else "lost"
        if status == "lost":
            return Localization(result.timestamp_ns, "lost", np.full(3, np.nan), -1, 0.0)
        fix = state.last_fix
        assert fix is not None
        pose = compose(state.anchor, state.since)
        relative = between(self.keyframes.poses[fix.keyframe], pose)
        return Localization(
            result.timestamp_ns, status, pose, fix.keyframe, fix.quality, relative, state.pose_cov
        )

    # -- odometry bookkeeping ---------------------------------------------------------------
    def _twist(self, result: OdometryResult) -> FloatArray | None:
        results = self.odometry.results
        if result.index == 0 or len(results) < 2:
            return None
        dt_s = (result.timestamp_ns - results[-2].timestamp_ns) / NS_PER_S
        return twist_from_motion(result.motion, dt_s) if dt_s > 0 else None

    def _advance(self, result: OdometryResult) -> None:
        state = self.state
        if result.index == 0:
            return
        motion = result.motion
        step = float(np.hypot(motion[0], motion[1]))
        step_cov = rotate_covariance(result.covariance, -float(motion[2]))
        state.since_cov = rotate_covariance(state.since_cov, -float(motion[2])) + step_cov
        carry = adjoint(inverse(motion))
        state.pose_cov = symmetric(carry @ state.pose_cov @ carry.T + step_cov)
        state.pending_cov = rotate_covariance(state.pending_cov, -float(motion[2])) + step_cov
        state.since = compose(state.since, motion)
        state.pending_since = compose(state.pending_since, motion)
        state.path_since_fix_m += step
        state.path_since_attempt_m += step
        state.pending_path_m += step

    # -- global relocalisation --------------------------------------------------------------
    def _relocalise(self, query: KeyScan) -> bool:
        cfg, state = self.cfg, self.state
        if state.chain and state.pending_path_m > cfg.lost_after_m:
            state.chain = []
        if not state.chain and state.path_since_attempt_m < RELOCALISE_EVERY_M:
            return False  # while a chain is open, every scan may add to it
        state.path_since_attempt_m = 0.0
        self.global_attempts += 1
        descriptor = self.describe(*raplace_input(self.verifier.polar(query)))
        candidates = [
            c.key
            for c in self.keyframes.recognizer.query(descriptor, cfg.candidates)
            if c.distance < cfg.max_descriptor_distance
        ]
        for fix in self._verified(query, candidates):
            self._extend_chain(fix)
        keyframes, scans = self._chain_span()
        if len(keyframes) == CONFIRM_KEYFRAMES - 1 and len(scans) >= CONFIRM_SCANS:
            self._complete_chain(query, keyframes)
            keyframes, scans = self._chain_span()
        if len(keyframes) < CONFIRM_KEYFRAMES or len(scans) < CONFIRM_SCANS:
            return False
        self._start_tracking()
        self.relocalisations += 1
        return True

    def _chain_span(self) -> tuple[set[int], set[int]]:
        """The distinct map keyframes and scans of the chain's hypotheses."""
        chain = self.state.chain
        return {f.keyframe for f, _, _ in chain}, {f.scan for f, _, _ in chain}

    def _complete_chain(self, query: KeyScan, keyframes: set[int]) -> None:
        """A chain one keyframe short of `CONFIRM_KEYFRAMES` may take its last one from a
        tracking fix: the scan registered, as while tracking, against the map keyframes nearest
        the chain's pose that are not in it, `FIX_KEYFRAMES` of them whatever their distance
        (a vehicle entering the map's route sees the keyframes beyond the two it matched from
        farther than `SEARCH_RADIUS_M`; one too far to share its view fails the registration or
        the innovation gate). A fix that does not agree with the chain is dropped: it comes from
        the chain's own prediction, so it never starts one."""
        state = self.state
        predicted = compose(state.chain[-1][0].pose, state.pending_since)
        nearest = self.keyframes.near(predicted, np.inf, FIX_KEYFRAMES + len(keyframes))
        for kf in [k for k in nearest if k not in keyframes][:FIX_KEYFRAMES]:
            fix = self._tracking_fix(query, kf, predicted)
            if fix is not None and self._joins_chain(fix):
                return

    def _extend_chain(self, fix: _Fix) -> None:
        """Add a hypothesis to the chain when it agrees with it; else it starts a new chain
        (unless it is a weaker one of the same scan)."""
        chain = self.state.chain
        if self._joins_chain(fix) or (chain and chain[-1][0].scan == fix.scan):
            return
        self._hold(fix)

    def _joins_chain(self, fix: _Fix) -> bool:
        """Append `fix` to the chain if it agrees with the latest hypothesis carried forward by
        the odometry (`CONFIRM_MAX_ERROR_M/_DEG`)."""
        _cfg, state = self.cfg, self.state
        if not state.chain:
            return False
        carried = compose(state.chain[-1][0].pose, state.pending_since)
        if not self._agrees(carried, fix.pose, CONFIRM_MAX_ERROR_M, CONFIRM_MAX_ERROR_DEG):
            return False
        state.chain.append((fix, state.pending_since.copy(), state.pending_cov.copy()))
        self._restart_pending()
        return True

    def _hold(self, fix: _Fix) -> None:
        """Start a chain of agreeing hypotheses with `fix`."""
        self.state.chain = [(fix, np.zeros(3), np.zeros((3, 3)))]
        self._restart_pending()

    def _restart_pending(self) -> None:
        state = self.state
        state.pending_since = np.zeros(3)
        state.pending_cov = np.zeros((3, 3))
        state.pending_path_m = 0.0

    def _start_tracking(self) -> None:
        """Track from the agreeing chain: its fixes, joined by the odometry, fill the window."""
        state = self.state
        chain, state.chain = state.chain, []
        state.window = []
        state.tracking = True
        state.failed_fixes = 0
        for fix, motion, covariance in chain:
            if not state.window or fix.scan != state.window[-1].scan:  # one fix per scan
                self._add_node(fix, motion, covariance)

    # -- tracking -----------------------------------------------------------------------------
    def _track(self, query: KeyScan) -> Status:
        cfg, state = self.cfg, self.state
        if state.path_since_attempt_m >= cfg.fix_every_m or state.failed_fixes:
            state.path_since_attempt_m = 0.0
            predicted = compose(state.anchor, state.since)
            near = self.keyframes.near(predicted, SEARCH_RADIUS_M, FIX_KEYFRAMES)
            fix = next(
                (f for kf in near if (f := self._tracking_fix(query, kf, predicted)) is not None),
                None,
            )
            if fix is not None:
                self._add_node(fix, state.since, state.since_cov)
                state.failed_fixes = 0
            else:
                state.failed_fixes += 1
        if state.path_since_fix_m > cfg.lost_after_m:
            log.info("scan %d: no map fix for %.0f m: lost", query.key, state.path_since_fix_m)
            state.tracking = False
            state.window = []
            state.path_since_attempt_m = np.inf
            return "lost"
        return "lost" if state.failed_fixes >= FAILED_FIXES_LOST else "tracked"

    def _add_node(self, fix: _Fix, motion: FloatArray, covariance: FloatArray) -> None:
        """Append the fix's scan to the window, re-solve it, re-anchor the prediction."""
        state = self.state
        state.window.append(_Node(fix.scan, motion.copy(), covariance.copy(), fix, fix.pose))
        state.window = state.window[-WINDOW_FIXES:]
        try:
            fused = self._solve_window()
        except GraphError as exc:  # keep the fix's own pose rather than stop
            log.warning("window graph failed (%s): using the fix alone", exc)
            fused = fix.pose
        state.anchor = fused
        state.since = np.zeros(3)
        state.since_cov = np.zeros((3, 3))
        state.pose_cov = self._fix_covariance(fix)
        state.path_since_fix_m = 0.0
        state.last_fix = fix

    def _solve_window(self) -> FloatArray:
        """The window graph's estimate of the newest node (T_map_scan)."""
        graph = PoseGraph(_WINDOW_GRAPH)
        prior = self._map_prior()
        added: set[int] = set()
        previous: _Node | None = None
        for node in self.state.window:
            guess = node.pose if previous is None else compose(previous.pose, node.motion)
            graph.add_keyframe(node.scan, guess)
            if previous is not None:
                graph.add_odometry(previous.scan, node.scan, node.motion, node.covariance)
            kf = node.fix.keyframe
            if kf not in added:
                graph.add_keyframe(MAP_KEY_BASE + kf, self.keyframes.poses[kf])
                graph.add_prior(MAP_KEY_BASE + kf, self.keyframes.poses[kf], prior)
                added.add(kf)
            graph.add_loop(node.scan, MAP_KEY_BASE + kf, node.fix.measurement, node.fix.covariance)
            previous = node
        graph.update()
        graph.optimize_final()
        for node in self.state.window:
            node.pose = graph.estimate(node.scan)
        return self.state.window[-1].pose

    # -- verification -------------------------------------------------------------------------
    def _tracking_fix(self, query: KeyScan, kf: int, predicted: FloatArray) -> _Fix | None:
        """Phase correlation of the scan and keyframe `kf` turned by the predicted relative yaw
        (the prediction replaces the sinogram stage of the loop verifier); accepted when the
        peak is strong and the fix agrees with the prediction."""
        lcfg, odometry = self.config.loop_closure, self.config.odometry
        expected = between(predicted, self.keyframes.poses[kf])  # T_scan_keyframe
        turn = float(expected[2])
        if self._prepared_key != query.key or self._prepared is None:
            self._prepared = self.verifier.prepared(query)
            self._prepared_key = query.key
        aligned = self.verifier.prepared(self.keyframes.scan(kf), turn)
        estimate = register(self._prepared, aligned, odometry)
        if not estimate.ok or estimate.quality < lcfg.verification.min_refined_quality:
            return None
        measurement = compose(estimate.motion, np.array([0.0, 0.0, turn]))
        pose = compose(self.keyframes.poses[kf], inverse(measurement))
        if not self._agrees(predicted, pose, MAX_INNOVATION_M, MAX_INNOVATION_DEG):
            return None
        covariance = loop_covariance(
            estimate.covariance, np.zeros(3), float(measurement[2]), LOOP_COVARIANCE
        )
        return _Fix(query.key, kf, measurement, covariance, float(estimate.quality), pose)

    def _verified(self, query: KeyScan, keyframes: list[int]) -> list[_Fix]:
        """The keyframes that verify as a loop does, as fixes, highest registration quality
        first."""
        fixes: list[_Fix] = []
        for kf in keyframes:
            result: Verification = self.verifier(query, self.keyframes.scan(kf))
            if result.ok:
                pose = compose(self.keyframes.poses[kf], inverse(result.measurement))
                fixes.append(
                    _Fix(query.key, kf, result.measurement, result.covariance,
                         result.refined_quality, pose)
                )  # fmt: skip
        return sorted(fixes, key=lambda f: -f.quality)

    def _fix_covariance(self, fix: _Fix) -> FloatArray:
        """(3, 3) covariance of the pose a fix gives, in the scan's frame: the measurement's and
        the keyframe's (its window prior), carried through T_map_scan = T_map_keyframe * z^-1."""
        carry = adjoint(fix.measurement)
        return symmetric(carry @ (fix.covariance + self._map_prior()) @ carry.T)

    def _map_prior(self) -> FloatArray:
        """(3, 3) covariance of a map keyframe's pose (its prior in the window graph)."""
        return np.diag([MAP_SIGMA_XY_M**2, MAP_SIGMA_XY_M**2, np.deg2rad(MAP_SIGMA_YAW_DEG) ** 2])

    @staticmethod
    def _agrees(a: FloatArray, b: FloatArray, max_m: float, max_deg: float) -> bool:
        d = between(a, b)
        return bool(
            np.hypot(d[0], d[1]) <= max_m and abs(float(wrap_angle(d[2]))) <= np.deg2rad(max_deg)
        )
