"""Multi-session SLAM: tie a new session to a map by verified inter-session loops.

`join_session(results, map, queries)` takes a finished SLAM run of the new session (its own
frame), made with `Pipeline(on_keyframe=queries)` where `queries` is the map's
`InterSessionQueries`, and

1. looks for inter-session loops: as the run makes each of its map keyframes (every
   `maps.keyframe_spacing_m` of its odometry path), `queries` looks the keyframe's RaPlace
   descriptor up among all map keyframes and verifies the best candidates as loops are
   (`radar_slam.loops.GeometricVerifier`, the scan's conditioned form against the map keyframe's
   stored image), so that no scan is read or described again after the run; after the run, the
   verified ones, in scan order, pass the same pairwise consistency gate as intra-session loops
   (`ConsistencyGate` with the session's optimised path: two loops must close the cycle through
   the session's trajectory and the map's), so a loop is accepted only once another one agrees
   with it;
2. if any is accepted, solves one pose graph: the map keyframes the loops touch, held by tight
   priors at their map poses; the session's scans joined by their odometry factors and accepted
   intra-session loops; the inter-session loops as robust loop factors. The initial guess places
   the session with the median transform its accepted loops imply. The final GNC pass may still
   reject an inter-session loop (weight below `BACKEND_REJECT_WEIGHT`);
3. returns the session's trajectory in the map's frame and the map extended by the session
   (its keyframes, descriptors, images, its graph and the inter-session edges).

A session without an accepted inter-session loop is reported as never meeting the map: nothing
is forced in, its trajectory stays in its own frame.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from odometry import PolarScan, Scan
from radar_slam.evaluation.truth import is_true_loop
from radar_slam.graph import PoseGraph
from radar_slam.loops import (
    ConsistencyGate,
    GeometricVerifier,
    KeyScan,
    LoopDecision,
    LoopStatus,
    VerifiedLoop,
)
from radar_slam.loops.config import LOOP_RAPLACE
from radar_slam.maps.build import (
    EDGE_KINDS,
    build_map,
    edge_rows,
    information_upper,
    keyframe_content,
    keyframe_rows,
)
from radar_slam.maps.format import EDGE_DTYPE, META_FILE, Map, MapError, Session
from radar_slam.maps.localizer import (
    MAP_KEY_BASE,
    MAP_SIGMA_XY_M,
    MAP_SIGMA_YAW_DEG,
    MapKeyframes,
    descriptor_config_of,
    image_geometry_of,
)
from radar_slam.pipeline import BACKEND_REJECT_WEIGHT, PipelineConfig, Results, odometry_factor
from radar_slam.trajectory import Trajectory
from raplace import between, compose, inverse

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
SESSION_GAP_M = 1e6
"""Path offset between the map's sessions, so the consistency window never joins two of them."""


@dataclass(frozen=True)
class JoinedSession:
    """The outcome of `join_session`.

    Attributes:
        met_map: at least one inter-session loop was accepted (the session is in the map frame).
        loops: every verified inter-session proposal (query_key = scan index, match_key = map
            keyframe index), with status and reason.
        true_loops: per loop, whether it is true (`is_true_loop` with the session's GT and the
            keyframe's GT), None without both.
        results: the run with `slam` (and `graph`) in the map frame when met_map, else as given.
        map: the map extended by the session when met_map, else the session's own map.
        ate_map_frame_m: RMS position error of the trajectory in the map frame against the
            session's GT through the map's GT alignment only (no re-alignment) [m], or None.
    """

    met_map: bool
    loops: list[LoopDecision]
    true_loops: list[bool | None]
    results: Results
    map: Map
    ate_map_frame_m: float | None

    @property
    def accepted(self) -> list[LoopDecision]:
        return [d for d in self.loops if d.accepted]


def map_paths(m: Map) -> FloatArray:
    """(K,) path length along the map keyframes of each session [m], sessions
    `SESSION_GAP_M` apart."""
    poses, sessions = m.poses, m.keyframes["session"]
    steps = np.r_[0.0, np.hypot(*np.diff(poses[:, :2], axis=0).T)]
    new_session = np.r_[True, sessions[1:] != sessions[:-1]]
    steps[new_session] = SESSION_GAP_M
    return np.cumsum(steps)


def check_descriptor_settings(m: Map, source: Path | str) -> None:
    """Refuse a map whose descriptors are not made as a run makes them (`LOOP_RAPLACE`).

    Raises:
        MapError: names the map file, the key and the first differing setting.
    """
    stored = descriptor_config_of(m)
    made = LOOP_RAPLACE.descriptor
    if stored == made:
        return
    ours, theirs = dataclasses.asdict(made), dataclasses.asdict(stored)
    key = ""
    while isinstance(ours, dict):  # down to the first differing setting
        name = next(k for k in ours if ours[k] != theirs[k])
        key, ours, theirs = f"{key}.{name}", ours[name], theirs[name]
    raise MapError(
        f"{source}: {META_FILE}: settings.descriptor{key} is {theirs!r}, a run describes scans "
        f"with {ours!r}: a session joins only a map described as it is (make the map again "
        "with `radar-slam run`)"
    )


class InterSessionQueries:
    """A session's map keyframes looked up among a map's keyframes and verified as the run makes
    them (a `radar_slam.maps.keyframes.KeyframeListener` for `Pipeline(on_keyframe=...)`).

    Per keyframe, the candidates below `max_descriptor_distance` are verified best first until
    one passes (one verified loop per query, as the intra-session detector); the decisions wait
    in `verified` for `join_session`, which judges them with the session's optimised path.
    Called from one thread at a time (the run's loop thread or its main thread).

    Each keyframe is described once, by the run: the map's descriptors must be made with the
    same settings (`LOOP_RAPLACE`, those of every map `radar-slam run` writes), else its
    keyframes could neither be compared with the session's nor joined by them.

    Args:
        m: the map.
        config: the run's settings.
        source: the map's folder (for the error message).

    Raises:
        MapError: the map's descriptors are made with other settings.
    """

    def __init__(self, m: Map, config: PipelineConfig, source: Path | str = "map") -> None:
        check_descriptor_settings(m, source)
        self.cfg = config.loop_closure
        self.keyframes = MapKeyframes(m, config)
        self.verifier = GeometricVerifier(self.cfg, config.odometry)
        self.verified: dict[int, list[LoopDecision]] = {}
        """Scan index -> its decisions, in the order verified (query_key = scan index,
        match_key = map keyframe index; status "pending" when verified, else "rejected")."""

    def __call__(
        self,
        scan_index: int,
        frame: Scan,
        polar: PolarScan,
        twist: FloatArray | None,
        descriptor: NDArray[np.float32],
    ) -> None:
        """Look one keyframe of the session up in the map and verify its candidates.

        Args:
            scan_index: its index in the session.
            frame: the raw scan.
            polar: its conditioned form (`odometry.preprocess_polar`, the run's settings).
            twist: (3,) its sweep twist (vx, vy [m/s], yaw rate [rad/s]), or None.
            descriptor: its RaPlace descriptor made by the run (`LOOP_RAPLACE`, as the map's).
        """
        cfg = self.cfg
        candidates = [
            c
            for c in self.keyframes.recognizer.query(descriptor, cfg.candidates)
            if c.distance < cfg.max_descriptor_distance
        ]
        query = KeyScan(scan_index, frame.timestamp_ns, frame, twist, polar=polar)
        decisions = self.verified.setdefault(scan_index, [])
        for candidate in candidates:
            kf = int(candidate.key)
            match = self.keyframes.scan(kf)
            result = self.verifier(query, match)
            decisions.append(LoopDecision.of(query, match, kf, candidate.distance, result))
            if result.ok:
                break


class InterSessionDetector:
    """Pairwise-consistent loops from a session's verified inter-session proposals
    (`InterSessionQueries`) to a map's keyframes."""

    def __init__(self, m: Map, config: PipelineConfig) -> None:
        self.cfg = config.loop_closure
        self.poses = m.poses
        self.gate = ConsistencyGate(self.cfg.consistency)
        self.map_path_m = map_paths(m)
        self.decisions: list[LoopDecision] = []

    def detect(self, results: Results, queries: InterSessionQueries) -> list[LoopDecision]:
        """Judge the proposals of each queried scan, in scan order, along the session's
        optimised path."""
        poses = results.slam.poses
        steps = np.r_[0.0, np.hypot(*np.diff(poses[:, :2], axis=0).T)]
        path = np.cumsum(steps)
        for n in range(len(poses)):
            self._apply(self.gate.expire(float(path[n])))
            for proposal in queries.verified.get(n, []):
                self._add(proposal, poses[n], float(path[n]))
        self._apply(self.gate.finish())
        return self.decisions

    def _add(self, proposal: LoopDecision, pose: FloatArray, path_m: float) -> None:
        decision = len(self.decisions)
        self.decisions.append(proposal)
        if proposal.status == "rejected":  # failed verification
            return
        kf = proposal.match_key
        verified = VerifiedLoop(
            decision=decision,
            query_key=proposal.query_key,
            match_key=MAP_KEY_BASE + kf,
            measurement=proposal.measurement,
            covariance=proposal.covariance,
            query_pose=pose,
            match_pose=self.poses[kf],
            query_path_m=path_m,
            match_path_m=float(self.map_path_m[kf]),
        )
        self._apply(self.gate.add(verified))

    def _apply(self, changes: dict[int, LoopStatus]) -> None:
        for decision, status in changes.items():
            self.decisions[decision] = dataclasses.replace(
                self.decisions[decision], status=status, reason=self.gate.reasons[decision]
            )


def session_transform(loops: list[LoopDecision], session: FloatArray, m: Map) -> FloatArray:
    """T_map_session implied by the accepted loops: per loop T_map_kf z^-1 T_session_scan^-1;
    the median of x and y and the circular mean of yaw."""
    transforms = np.array(
        [
            compose(
                compose(m.poses[d.match_key], inverse(d.measurement)),
                inverse(session[d.query_key]),
            )
            for d in loops
        ]
    )
    yaw = float(np.arctan2(np.sin(transforms[:, 2]).mean(), np.cos(transforms[:, 2]).mean()))
    return np.array([np.median(transforms[:, 0]), np.median(transforms[:, 1]), yaw])


def joint_graph(
    results: Results, loops: list[LoopDecision], m: Map, initial: FloatArray
) -> tuple[PoseGraph, dict[int, int]]:
    """The session + map graph (see the module docstring) optimised; returns it and
    {decision index: loop id} of the inter-session loops."""
    config = results.config
    graph = PoseGraph(config.graph)
    odometry = results.odometry_results
    for n, result in enumerate(odometry):
        graph.add_keyframe(n, initial[n])
        if n:
            graph.add_odometry(n - 1, n, *odometry_factor(result))
    for d in results.loops:
        if d.accepted:
            graph.add_loop(d.query_key, d.match_key, d.measurement, d.covariance)
    prior = np.diag([MAP_SIGMA_XY_M**2, MAP_SIGMA_XY_M**2, np.deg2rad(MAP_SIGMA_YAW_DEG) ** 2])
    ids = {}
    for n, d in enumerate(loops):
        if not d.accepted:
            continue
        key = MAP_KEY_BASE + d.match_key
        if key not in graph.keys():
            graph.add_keyframe(key, m.poses[d.match_key])
            graph.add_prior(key, m.poses[d.match_key], prior)
        ids[n] = graph.add_loop(d.query_key, key, d.measurement, d.covariance)
    graph.update()
    graph.optimize_final()
    return graph, ids


def extended_map(m: Map, results: Results, poses: FloatArray, loops: list[LoopDecision]) -> Map:
    """`m` with the session appended (the keyframes the run recorded, every `keyframe_spacing_m`
    of the odometry path, as in the run's own map, at `poses`: the session's poses in the map
    frame).

    Raises:
        RadarSlamError: the run recorded no keyframes with the map's image and descriptor
            settings.
    """
    scans, descriptors, images, scales = keyframe_content(
        results, None, image_geometry_of(m), descriptor_config_of(m)
    )
    stamps = results.slam.timestamps_ns
    session_index = len(m.sessions)
    rows = keyframe_rows(session_index, scans, stamps, poses, results.ground_truth_poses, scales)
    offset = len(m)
    edges = [m.edges, edge_rows(scans, poses, results.odometry_results, results.loops, offset)]
    owner = np.searchsorted(scans, np.arange(len(poses)), side="right") - 1
    inter = []
    for d in loops:
        if d.accepted:
            lead = between(poses[scans[owner[d.query_key]]], poses[d.query_key])
            measurement = compose(lead, d.measurement)
            kind = EDGE_KINDS.index("intersession")
            i = offset + int(owner[d.query_key])
            inter.append((i, d.match_key, kind, measurement, information_upper(d.covariance)))
    edges.append(np.array(inter, dtype=EDGE_DTYPE) if inter else np.zeros(0, dtype=EDGE_DTYPE))
    session = Session(results.sequence, len(poses), int(stamps[0]), int(stamps[-1]), "loops")
    return Map(
        keyframes=np.concatenate([m.keyframes, rows]),
        descriptors=np.concatenate([m.descriptors, descriptors]),
        images=m.images + tuple(images),
        edges=np.concatenate(edges),
        sessions=(*m.sessions, session),
        settings=m.settings,
        gt_alignment=m.gt_alignment,
    )


def ate_in_map_frame(poses: FloatArray, gt_poses: FloatArray | None, m: Map) -> float | None:
    """RMS position error [m] of map-frame poses against GT through the map's alignment."""
    if gt_poses is None or m.gt_alignment is None:
        return None
    placed = compose(m.gt_alignment, poses)
    known = np.all(np.isfinite(gt_poses), axis=1)
    if not known.any():
        return None
    error = placed[known, :2] - gt_poses[known, :2]
    return float(np.sqrt(np.mean(np.sum(error**2, axis=1))))


def _review(loops: list[LoopDecision], graph: PoseGraph, ids: dict[int, int]) -> None:
    weights = graph.loop_weights()
    for n, loop_id in ids.items():
        weight = weights.get(loop_id, 1.0)
        if weight < BACKEND_REJECT_WEIGHT:
            reason = f"rejected by the final {graph.config.final_pass} pass (weight {weight:.2f})"
            loops[n] = dataclasses.replace(loops[n], status="rejected", reason=reason)


def join_session(results: Results, m: Map, queries: InterSessionQueries) -> JoinedSession:
    """Tie a finished run to map `m` (see the module docstring): the run was made with
    `Pipeline(on_keyframe=queries)`, `queries` being `InterSessionQueries(m, config)`.

    Raises:
        RadarSlamError: the run recorded no keyframes with the map's image and descriptor
            settings.
    """
    loops = InterSessionDetector(m, results.config).detect(results, queries)
    gt = results.ground_truth_poses
    accepted = [d for d in loops if d.accepted]
    if not accepted:
        log.warning("%s never met the map: no inter-session loop accepted", results.sequence)
        own = build_map(results)
        return JoinedSession(False, loops, _truth(loops, gt, m), results, own, None)
    session = results.slam.poses
    transform = session_transform(accepted, session, m)
    graph, ids = joint_graph(results, loops, m, compose(transform, session))
    _review(loops, graph, ids)
    poses = np.array([graph.estimate(n) for n in range(len(session))])
    joined = dataclasses.replace(
        results, slam=Trajectory(results.slam.timestamps_ns, poses), graph=graph
    )
    return JoinedSession(
        met_map=any(d.accepted for d in loops),
        loops=loops,
        true_loops=_truth(loops, gt, m),
        results=joined,
        map=extended_map(m, results, poses, loops),
        ate_map_frame_m=ate_in_map_frame(poses, gt, m),
    )


def _truth(loops: list[LoopDecision], gt: FloatArray | None, m: Map) -> list[bool | None]:
    if gt is None:
        return [None] * len(loops)
    kf_gt = m.gt_poses
    return [is_true_loop(d.measurement, gt[d.query_key], kf_gt[d.match_key]) for d in loops]


def summary(joined: JoinedSession) -> dict[str, Any]:
    """multisession.json content."""
    accepted = [n for n, d in enumerate(joined.loops) if d.accepted]
    truths = [joined.true_loops[n] for n in accepted]
    return {
        "met_map": joined.met_map,
        "intersession_proposed": len(joined.loops),
        "intersession_accepted": len(accepted),
        "intersession_accepted_true": None
        if any(t is None for t in truths)
        else sum(bool(t) for t in truths),
        "ate_map_frame_m": joined.ate_map_frame_m,
        "map_sessions": len(joined.map.sessions),
        "map_keyframes": len(joined.map),
    }
