"""The loop detector: RaPlace candidates, geometric verification, pairwise consistency.

For every database scan (one every `query_spacing_m` of travel when poses are given, else every
scan) the `LoopDetector` queries the place database for `candidates` matches and proposes those
below `max_descriptor_distance`, verifies each proposal, best first, until one passes
(`radar_slam.loops.verification`), and, with poses, accepts a verified loop once another loop
nearby agrees with it (`radar_slam.loops.consistency`); with poses too, a query on a stretch
already closed by consecutive accepted loops is verified only once per
`throttle.closed_spacing_m` of travel (`radar_slam.loops.throttle`), and a candidate on such a
stretch is checked from the loop its latest one predicts (`radar_slam.loops.tracking`; in full
when that check fails). Each scan is handled once
the next one is in (or at `finish`): its de-skew twist is the odometry's velocity interpolated to
the middle of its sweep from the steps before and after it (`radar_slam.loops.sweep_twist`).
A scan joins the place database once the vehicle has driven `recent_path_m` past it, and a
candidate the odometry places out of the verifier's reach is not verified
(`radar_slam.loops.recent`). Every verified proposal becomes a `LoopDecision` with its reason.
`NullLoopDetector` has the same interface and does nothing.
"""

from __future__ import annotations

import dataclasses
import logging
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from odometry import OdometryConfig, PolarScan, Scan, Velocity, preprocess_polar
from radar_slam.loops.config import LOOP_RAPLACE, LoopClosureConfig
from radar_slam.loops.consistency import ConsistencyGate
from radar_slam.loops.recent import HeldBackDatabase, held_back_retrieval, within_reach
from radar_slam.loops.records import (
    KeyScan,
    LoopClosureError,
    LoopConstraint,
    LoopDecision,
    LoopStatus,
    Verification,
    VerifiedLoop,
    raplace_input,
)
from radar_slam.loops.sweep_twist import (
    mean_acquisition_time_ns,
    step_twist,
    sweep_twist,
    twist_change,
)
from radar_slam.loops.throttle import StretchThrottle
from radar_slam.loops.tracking import Refiner, predicted_loop
from radar_slam.loops.verification import GeometricVerifier, Verifier, sweep_s
from raplace import NS_PER_S, Candidate, DescriptorExtractor, PlaceRecognizer, Recognizer, between

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
POSE_DIM = 3
LOOPS_PER_QUERY = 1
"""Verification of a query's candidates stops once this many passed (the rest would close loops
to the same place)."""
PREDICTED_CHECKS = True
"""A candidate on a closed stretch is checked by the phase-correlation refinement alone, from the
loop the stretch's latest one predicts (`radar_slam.loops.tracking`; verified in full when that
fails): about half a verification's cost per candidate on a revisit."""
DescriptorListener = Callable[[int, NDArray[np.float32]], None]
"""Takes a scan's key and its RaPlace descriptor (`LoopDetector`'s `on_describe`)."""


class LoopDetectorProtocol(Protocol):
    """What the pipeline needs from a loop detector (`LoopDetector` or `NullLoopDetector`)."""

    def add(
        self,
        scan: Scan,
        pose: ArrayLike | None = None,
        key: int | None = None,
        polar: PolarScan | None = None,
    ) -> list[LoopConstraint]: ...

    def finish(self) -> list[LoopConstraint]: ...

    def reject(self, decision: int, reason: str) -> None: ...

    def tally(self) -> tuple[int, int]: ...

    @property
    def decisions(self) -> list[LoopDecision]: ...

    @property
    def proposed(self) -> int: ...


@dataclass(frozen=True)
class _Held:
    """The last scan fed, held until the next one is in (its velocity needs the step after it).

    Attributes:
        scan, pose, key, polar: as given to `LoopDetector.add` (pose (3,) or None).
        before: the velocity of the odometry step into this scan (None: first scan, no poses,
            or a step beyond the vehicle's limits).
        path_m: odometry path length up to this scan [m].
        segment: odometry steps up to this scan faster than a vehicle moves or turns.
    """

    scan: Scan
    pose: FloatArray | None
    key: int
    before: Velocity | None
    path_m: float
    segment: int
    polar: PolarScan | None


@dataclass
class _Track:
    """The detector's running state over the scans fed so far."""

    count: int = 0
    last_key: int | None = None
    last_time_ns: int | None = None
    last_pose: FloatArray | None = None
    path_m: float = 0.0
    path_at_last_entry_m: float = -np.inf
    with_poses: bool | None = None
    segment: int = 0  # odometry steps so far faster than a vehicle moves or turns
    held: _Held | None = None


@dataclass(frozen=True)
class _Entry:
    """What the detector keeps per database scan (the scan itself only without a loader)."""

    key: int
    timestamp_ns: int
    pose: FloatArray | None
    path_m: float
    twist: FloatArray | None
    scan: Scan | None
    segment: int = 0
    twist_change: FloatArray | None = None  # across the scan: the loop covariance's de-skew term
    sweep_s: float | None = None  # the scan's sweep duration [s], for the same terms


class LoopDetector:
    """Verified radar loop closures from a stream of scans (and optionally their poses).

    Usable on its own (no radar_slam graph needed): feed every scan in time order with `add`;
    each call returns the loop constraints accepted by it (T_query_match with covariance, keys
    = the scans' keys), ready for `radar_slam.graph.add_loop_factors` or any back end. With
    poses, a scan is queried when the next one is added (its velocity is then known on both
    sides), so its loops come from that call at the earliest. Call `finish()` after the last
    scan: it queries the last scan and returns the loops accepted then.

    Args:
        config: loop-closing settings (defaults when None).
        scan_loader: returns what a database scan's key is verified against, each time it is a
            candidate (the pipeline: the scan's record image, `radar_slam.maps.keyframes`, so
            that no scan is read twice); without it the detector keeps every database scan in
            memory (about 1.3 MB per MulRan scan).
        recognizer: the place database (default: RaPlace `PlaceRecognizer`).
        verifier: the geometric verifier (default: `GeometricVerifier` with `odometry`).
        odometry: the odometry settings of the poses given (their vehicle limits) and of the
            verifier's phase-correlation refinement (None: the defaults).
        on_describe: called with (key, descriptor) each time a scan is described (in the
            thread that calls `add` or `finish`), so that another stage need not describe it
            again; the descriptor must not be changed.

    Poses are the caller's odometry T_world_scan (3,) of each scan: with them, database entries
    are spaced by travelled distance, scans are de-skewed with the velocity they imply, and
    verified loops must be consistent with each other (`ConsistencyGate`); without them every
    verified loop is accepted. Give poses for every scan or for none.
    """

    def __init__(
        self,
        config: LoopClosureConfig | None = None,
        scan_loader: Callable[[int], Scan] | None = None,
        *,
        recognizer: Recognizer | None = None,
        verifier: Verifier | None = None,
        on_describe: DescriptorListener | None = None,
        odometry: OdometryConfig | None = None,
    ) -> None:
        self.config = LoopClosureConfig() if config is None else config
        cfg = self.config
        self.odometry = OdometryConfig() if odometry is None else odometry
        self.scan_loader = scan_loader
        self.on_describe = on_describe
        self.describe = DescriptorExtractor(LOOP_RAPLACE.descriptor)
        self.recognizer: Recognizer = (
            PlaceRecognizer(held_back_retrieval(LOOP_RAPLACE.retrieval, cfg.recent_path_m))
            if recognizer is None
            else recognizer
        )
        # scans held back from the database until the vehicle is past them (own database only:
        # a recognizer given is used with its own exclusion window, as it comes)
        self._held_back: HeldBackDatabase | None = None
        if recognizer is None and cfg.recent_path_m > 0:
            exclusion = LOOP_RAPLACE.retrieval.exclusion
            self._held_back = HeldBackDatabase(self.recognizer, cfg.recent_path_m, exclusion)
        self.verifier: Verifier = (
            GeometricVerifier(cfg, self.odometry) if verifier is None else verifier
        )
        self.gate = ConsistencyGate(cfg.consistency)
        self.throttle = StretchThrottle(cfg.throttle)
        self._entries: dict[int, _Entry] = {}
        self._decisions: list[LoopDecision] = []
        self._tally: Counter[str] = Counter()
        self._track = _Track()
        self.proposed = 0
        self.out_of_reach = 0  # candidates the odometry placed out of the verifier's reach
        self.predicted = 0  # candidates on a closed stretch checked from their prediction ...
        self.predicted_failed = 0  # ... of which verified in full again

    # -- results ------------------------------------------------------------------------------
    @property
    def decisions(self) -> list[LoopDecision]:
        """Every verified proposal so far, in the order verified, with its current status."""
        return list(self._decisions)

    def tally(self) -> tuple[int, int]:
        """(accepted, rejected) decisions so far (cheap: kept up to date)."""
        return self._tally["accepted"], self._tally["rejected"]

    @property
    def accepted_constraints(self) -> list[LoopConstraint]:
        """The accepted loops as constraints."""
        return [d.constraint() for d in self._decisions if d.accepted]

    def __len__(self) -> int:
        """Number of database scans."""
        return len(self._entries)

    # -- the per-scan step --------------------------------------------------------------------
    def add(
        self,
        scan: Scan,
        pose: ArrayLike | None = None,
        key: int | None = None,
        polar: PolarScan | None = None,
    ) -> list[LoopConstraint]:
        """Feed the next scan (time order); returns the loops accepted by this call.

        Args:
            scan: the scan (any object with the `odometry.Scan` attributes).
            pose: (3,) odometry pose T_world_scan, or None (then for every scan).
            key: the scan's key in the loop constraints (default: number of scans fed before).
            polar: the scan's conditioned form with the detector's odometry settings (a run's
                odometry's), else made here; the scan is described and verified from it.

        Raises:
            LoopClosureError: poses given for some scans only, a key reused, or time going back.
        """
        track = self._track
        key = track.count if key is None else int(key)
        pose_arr = self._check(scan, pose, key)
        before = self._advance(scan, pose_arr, key)
        accepted = self._handle_held(after=before)
        track.held = _Held(scan, pose_arr, key, before, track.path_m, track.segment, polar)
        if pose_arr is None:  # no velocity to wait for
            accepted += self._handle_held(after=None)
        return accepted

    def finish(self) -> list[LoopConstraint]:
        """Query the last scan, then resolve the loops still pending (rejected: no support);
        returns the loops accepted by this call."""
        accepted = self._handle_held(after=None)
        if self._held_back is not None:
            self._held_back.flush()
        changes = self.gate.finish()
        self.throttle.resolved(changes)
        return accepted + self._apply(changes)

    @property
    def skipped_queries(self) -> int:
        """Queries with candidates left unverified because they lay on a closed stretch."""
        return self.throttle.skipped

    def reject(self, decision: int, reason: str) -> None:
        """Mark an accepted loop as rejected afterwards (e.g. by the back end's GNC pass)."""
        self._record(decision, status="rejected", reason=reason)

    def _append(self, new: LoopDecision) -> None:
        """Record a new decision, keeping the tally."""
        self._decisions.append(new)
        self._tally[new.status] += 1

    def _record(self, decision: int, **changes: object) -> LoopDecision:
        """Replace fields of decision `decision`, keeping the tally."""
        self._tally[self._decisions[decision].status] -= 1
        new = dataclasses.replace(self._decisions[decision], **changes)  # type: ignore[arg-type]
        self._decisions[decision] = new
        self._tally[new.status] += 1
        return new

    # -- helpers ------------------------------------------------------------------------------
    def _check(self, scan: Scan, pose: ArrayLike | None, key: int) -> FloatArray | None:
        track = self._track
        with_pose = pose is not None
        if track.with_poses is not None and with_pose != track.with_poses:
            raise LoopClosureError(
                f"scan {key}: give a pose for every scan or for none (the first scan "
                f"{'had' if track.with_poses else 'had no'} pose)"
            )
        if track.last_key is not None and key <= track.last_key:
            raise LoopClosureError(
                f"scan key {key} does not follow the previous key {track.last_key} (keys increase)"
            )
        if track.last_time_ns is not None and int(scan.timestamp_ns) <= track.last_time_ns:
            raise LoopClosureError(
                f"scan {key} at {scan.timestamp_ns} ns is not later than the previous scan"
            )
        if pose is None:
            return None
        arr = np.asarray(pose, dtype=np.float64).reshape(-1)
        if arr.shape != (POSE_DIM,) or not np.all(np.isfinite(arr)):
            raise LoopClosureError(f"scan {key}: pose must be 3 finite numbers, got {pose!r}")
        return arr

    def _advance(self, scan: Scan, pose: FloatArray | None, key: int) -> Velocity | None:
        """Update the running path; return the velocity of the odometry step into this scan
        (None without poses, for the first scan, or when implausible)."""
        track = self._track
        velocity = None
        if pose is not None and track.last_pose is not None and track.last_time_ns is not None:
            motion = between(track.last_pose, pose)
            track.path_m += float(np.hypot(motion[0], motion[1]))
            step = step_twist(motion, track.last_time_ns, int(scan.timestamp_ns), self.odometry)
            velocity = step.velocity
            if not step.plausible:
                track.segment += 1  # the odometry is not trusted across this step
        track.with_poses = pose is not None
        track.last_pose = pose
        track.last_time_ns = int(scan.timestamp_ns)
        track.last_key = key
        track.count += 1
        return velocity

    def _handle_held(self, after: Velocity | None) -> list[LoopConstraint]:
        """Query the held scan (if any) with the velocity of the step after it, `after`."""
        held, self._track.held = self._track.held, None
        if held is None:
            return []
        track = self._track
        twist = change = span_s = None
        if held.pose is not None:
            twist = sweep_twist(held.before, after, mean_acquisition_time_ns(held.scan))
            change = twist_change(held.before, after)
            if held.before is not None and after is not None:
                span_s = (after.time_ns - held.before.time_ns) / NS_PER_S
        changes: dict[int, LoopStatus] = {}
        if held.pose is not None:
            changes.update(self.gate.expire(held.path_m))
        if held.path_m - track.path_at_last_entry_m >= self.config.query_spacing_m or (
            held.pose is None
        ):
            track.path_at_last_entry_m = held.path_m
            changes.update(self._query_and_insert(held, twist, change, span_s))
        self.throttle.resolved(changes)
        return self._apply(changes)

    def _reachable(self, held: _Held, candidates: list[Candidate]) -> list[Candidate]:
        """The candidates the odometry does not place out of the verifier's reach (all of them
        without poses, and those across an odometry step not trusted)."""
        if held.pose is None or not candidates:
            return candidates
        matches = [self._entries[c.key] for c in candidates]
        checked = [m.pose is not None and m.segment == held.segment for m in matches]
        if not any(checked):
            return candidates
        poses = np.array([m.pose if m.pose is not None else held.pose for m in matches])
        gaps = np.array([held.path_m - m.path_m for m in matches])
        reach = within_reach(
            held.pose,
            poses,
            gaps,
            self.config.verification.max_translation_m,
            self.config.odometry_drift_fraction,
        )
        keep = reach | ~np.array(checked)
        kept = [c for c, ok in zip(candidates, keep, strict=True) if ok]
        self.out_of_reach += len(candidates) - len(kept)
        return kept

    def _scan_of(self, entry: _Entry) -> Scan:
        if entry.scan is not None:
            return entry.scan
        assert self.scan_loader is not None
        return self.scan_loader(entry.key)

    def _query_and_insert(
        self,
        held: _Held,
        twist: FloatArray | None,
        change: FloatArray | None = None,
        span_s: float | None = None,
    ) -> dict[int, LoopStatus]:
        """Describe the held scan, enter it in the database and verify its candidates (when the
        throttle lets them through); the loop statuses that changed, by decision index."""
        if held.polar is None:
            polar = preprocess_polar(held.scan, self.odometry.preprocess)
            held = dataclasses.replace(held, polar=polar)
        entry, candidates = self._enter(held, twist, change)
        self.proposed += len(candidates)
        if held.pose is not None and not self.throttle.due(
            entry.path_m, [self._entries[c.key].path_m for c in candidates]
        ):
            return {}
        query = KeyScan(
            entry.key, entry.timestamp_ns, held.scan, twist, change, span_s, polar=held.polar
        )
        return self._verify_candidates(entry, query, candidates)

    def _enter(
        self, held: _Held, twist: FloatArray | None, change: FloatArray | None
    ) -> tuple[_Entry, list[Candidate]]:
        """The held scan's database entry and its reachable candidates, best first (queried
        before the scan itself is added)."""
        cfg = self.config
        scan, pose, key = held.scan, held.pose, held.key
        time_s = int(scan.timestamp_ns) / NS_PER_S
        assert held.polar is not None
        descriptor = self.describe(*raplace_input(held.polar))
        if self.on_describe is not None:
            self.on_describe(key, descriptor)
        path_m = held.path_m if pose is not None else None
        if self._held_back is not None:
            self._held_back.release(time_s, path_m)
        candidates = self._reachable(
            held,
            [
                c
                for c in self.recognizer.query(descriptor, cfg.candidates, time_s)
                if c.distance < cfg.max_descriptor_distance and c.key in self._entries
            ],
        )
        if self._held_back is not None:
            self._held_back.hold(descriptor, key, time_s, path_m)
        else:
            self.recognizer.add(descriptor, key, time_s)
        entry = _Entry(
            key=key,
            timestamp_ns=int(scan.timestamp_ns),
            pose=pose,
            path_m=held.path_m,
            twist=twist,
            scan=None if self.scan_loader is not None else scan,
            segment=held.segment,
            twist_change=change,
            sweep_s=sweep_s(scan),
        )
        self._entries[key] = entry
        return entry, candidates

    def _verify_candidates(
        self, entry: _Entry, query: KeyScan, candidates: list[Candidate]
    ) -> dict[int, LoopStatus]:
        """Verify `candidates` (at most `candidates` of them, best first) until
        `LOOPS_PER_QUERY` pass; each verified loop goes to the consistency gate when both ends
        have odometry poses."""
        changes: dict[int, LoopStatus] = {}
        passed = 0
        for candidate in candidates:
            match = self._entries[candidate.key]
            match_scan = KeyScan(
                match.key,
                match.timestamp_ns,
                self._scan_of(match),
                match.twist,
                match.twist_change,
                sweep_s=match.sweep_s,
            )
            result = self._verify(entry, match, query, match_scan)
            decision = len(self._decisions)
            self._append(LoopDecision.of(query, match_scan, match.key, candidate.distance, result))
            log.debug(
                "loop %d -> %d (distance %.3f): %s",
                entry.key,
                match.key,
                candidate.distance,
                result.reason or "verified",
            )
            if entry.pose is not None:
                yaw = float(result.measurement[2])
                self.throttle.verified(decision, entry.path_m, match.path_m, yaw, result.ok)
            if not result.ok:
                continue
            passed += 1
            if entry.pose is None or match.pose is None:
                changes[decision] = "accepted"
                self.gate.reasons[decision] = "accepted (no poses: consistency not checked)"
            else:
                changes.update(self.gate.add(self._verified_loop(decision, entry, match, result)))
            if passed >= LOOPS_PER_QUERY:
                break
        return changes

    @staticmethod
    def _verified_loop(
        decision: int, entry: _Entry, match: _Entry, result: Verification
    ) -> VerifiedLoop:
        assert entry.pose is not None and match.pose is not None
        return VerifiedLoop(
            decision=decision,
            query_key=entry.key,
            match_key=match.key,
            measurement=result.measurement,
            covariance=result.covariance,
            query_pose=entry.pose,
            match_pose=match.pose,
            query_path_m=entry.path_m,
            match_path_m=match.path_m,
            query_segment=entry.segment,
            match_segment=match.segment,
        )

    def _verify(self, entry: _Entry, match: _Entry, query: KeyScan, scan: KeyScan) -> Verification:
        """Verify a candidate: from its prediction when it lies on a closed stretch (in full
        when that fails), else in full (`radar_slam.loops.tracking`)."""
        initial = self._prediction(entry, match)
        if initial is not None and isinstance(self.verifier, Refiner):
            self.predicted += 1
            result = self.verifier.refine(query, scan, initial, float("nan"))
            if result.ok:
                return result
            self.predicted_failed += 1
        return self.verifier(query, scan)

    def _prediction(self, entry: _Entry, match: _Entry) -> FloatArray | None:
        """T_query_match predicted by the latest loop of the closed stretch the match lies on,
        or None (no such stretch, the odometry not trusted in between, or out of reach)."""
        cfg = self.config
        if not PREDICTED_CHECKS or entry.pose is None or match.pose is None:
            return None
        decision = self.throttle.anchor(entry.path_m, match.path_m)
        if decision is None or not self._decisions[decision].accepted:
            return None
        anchor = self._decisions[decision]
        anchor_query = self._entries.get(anchor.query_key)
        anchor_match = self._entries.get(anchor.match_key)
        if anchor_query is None or anchor_match is None:
            return None
        if anchor_query.pose is None or anchor_match.pose is None:
            return None
        if (anchor_query.segment, anchor_match.segment) != (entry.segment, match.segment):
            return None
        initial = predicted_loop(
            entry.pose, match.pose, anchor_query.pose, anchor_match.pose, anchor.measurement
        )
        if np.hypot(initial[0], initial[1]) > cfg.verification.max_translation_m:
            return None
        return initial

    def _apply(self, changes: dict[int, LoopStatus]) -> list[LoopConstraint]:
        """Record status changes; return the newly accepted loops as constraints."""
        accepted = []
        for decision, status in sorted(changes.items()):
            new = self._record(decision, status=status, reason=self.gate.reasons[decision])
            if status == "accepted":
                accepted.append(new.constraint())
        return accepted


class NullLoopDetector:
    """A loop detector that never finds a loop (loop closing disabled)."""

    def __init__(self, config: LoopClosureConfig | None = None) -> None:
        self.config = LoopClosureConfig(enabled=False) if config is None else config
        self.proposed = 0

    @property
    def decisions(self) -> list[LoopDecision]:
        return []

    def tally(self) -> tuple[int, int]:
        return 0, 0

    def add(
        self,
        scan: Scan,
        pose: ArrayLike | None = None,
        key: int | None = None,
        polar: PolarScan | None = None,
    ) -> list[LoopConstraint]:
        return []

    def finish(self) -> list[LoopConstraint]:
        return []

    def reject(self, decision: int, reason: str) -> None:
        raise LoopClosureError(f"no loop decision {decision}: loop closing is disabled")


def make_loop_detector(
    config: LoopClosureConfig,
    scan_loader: Callable[[int], Scan] | None = None,
    on_describe: DescriptorListener | None = None,
    odometry: OdometryConfig | None = None,
) -> LoopDetector | NullLoopDetector:
    """The configured detector: `LoopDetector` (with the run's `odometry` settings), or
    `NullLoopDetector` when disabled."""
    if not config.enabled:
        return NullLoopDetector(config)
    return LoopDetector(config, scan_loader, on_describe=on_describe, odometry=odometry)
