"""Pairwise consistency of verified loops: two loops nearby must close a cycle with the odometry.

Two loops (qa, ma, za) and (qb, mb, zb) agree when za * T_ma_mb = T_qa_qb * zb within the
covariance of the two loops and of the odometry segments between their queries and between their
matches (which grows with the segments' length). A loop is accepted once `min_support` other loops
agree with it; until then it is pending; it is rejected when it contradicts every accepted loop
nearby, or when the query has moved `WINDOW_M` on without support. Two loops judge each other
only when no odometry step between their queries, nor between their matches, moved or turned
faster than a vehicle can (`odometry.plausible_twist`; `VerifiedLoop.query_segment` /
`match_segment`): across such a step the odometry poses are not trusted, and a loop measured
there can share their error (a scan swept while spinning), which the cycle would then confirm
instead of catching.
"""

from __future__ import annotations

from bisect import bisect_left

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radar_slam.loops.config import CHI2_3DOF_99, ConsistencyConfig
from radar_slam.loops.records import LoopStatus, VerifiedLoop
from raplace import adjoint, between, compose, wrap_angle

FloatArray = NDArray[np.float64]
POSE_DIM = 3
WINDOW_M = 60.0
"""Loops support each other when their queries and their matches each lie within this path
distance [m]; a pending loop is rejected once the query has travelled this far past it without
support (a loop every `query_spacing_m` on a revisit finds its support well inside it)."""
CHI2_THRESHOLD = CHI2_3DOF_99
"""Two loops agree when the squared Mahalanobis distance of their cycle is below this (3 dof,
99 %: one true pair in a hundred is refused)."""
DRIFT_FRACTION = 0.02
"""Odometry translation error per metre travelled of the segments between two loops (2 %: twice
a typical radar odometry drift; 5 % let pairs of random false loops agree by chance)."""
DRIFT_DEG_PER_M = 0.05
"""Odometry rotation error per metre travelled [deg/m]."""
MIN_SIGMA_XY_M = 0.1
"""Translation standard deviation of a zero-length segment [m]."""
MIN_SIGMA_YAW_DEG = 0.2
"""Rotation standard deviation of a zero-length segment [deg]."""


def odometry_segment_covariance(path_m: ArrayLike) -> FloatArray:
    """(..., 3, 3) diagonal covariance of odometry segments `path_m` (...) metres long: standard
    deviations `DRIFT_FRACTION` * length + `MIN_SIGMA_XY_M` (x and y) and `DRIFT_DEG_PER_M` *
    length + `MIN_SIGMA_YAW_DEG` (yaw)."""
    length = np.abs(np.asarray(path_m, dtype=np.float64))
    sigma_xy = DRIFT_FRACTION * length + MIN_SIGMA_XY_M
    sigma_yaw = np.deg2rad(DRIFT_DEG_PER_M * length + MIN_SIGMA_YAW_DEG)
    cov = np.zeros(length.shape + (POSE_DIM, POSE_DIM))
    cov[..., 0, 0] = cov[..., 1, 1] = sigma_xy**2
    cov[..., 2, 2] = sigma_yaw**2
    return cov


def cycle_mahalanobis(loop: VerifiedLoop, others: list[VerifiedLoop]) -> FloatArray:
    """Squared Mahalanobis distances (n,) of the cycles closed by `loop` with each of `others`.

    For loops a (qa, ma, za) and b (qb, mb, zb) the cycle error is
    e = Log((za T_ma_mb)^-1 (T_qa_qb zb)) with T_ma_mb, T_qa_qb from the odometry poses. To first
    order its covariance is Ad(T_ma_mb^-1) S_za Ad^T + S_ma_mb + Ad(zb^-1) S_qa_qb Ad^T + S_zb,
    the odometry segments' covariances from `odometry_segment_covariance`. Vectorised over
    `others`; Log is taken as (x, y, wrapped yaw) (the cycle is near the identity when it
    matters).
    """
    if not others:
        return np.zeros(0)
    za = np.stack([o.measurement for o in others])  # (n, 3)
    sa = np.stack([o.covariance for o in others])
    qa = np.stack([o.query_pose for o in others])
    ma = np.stack([o.match_pose for o in others])
    path_q = loop.query_path_m - np.array([o.query_path_m for o in others])
    path_m = loop.match_path_m - np.array([o.match_path_m for o in others])
    zb = np.asarray(loop.measurement, dtype=np.float64)
    sb = np.asarray(loop.covariance, dtype=np.float64)
    t_ma_mb = between(ma, loop.match_pose)  # (n, 3)
    t_qa_qb = between(qa, loop.query_pose)
    error = between(compose(za, t_ma_mb), compose(t_qa_qb, zb))  # (n, 3)
    error[:, 2] = wrap_angle(error[:, 2])
    ad_m = adjoint(between(t_ma_mb, np.zeros(3)))  # Ad(T_ma_mb^-1)
    ad_zb = adjoint(between(zb, np.zeros(3)))  # Ad(zb^-1)
    cov = (
        ad_m @ sa @ np.swapaxes(ad_m, -1, -2)
        + odometry_segment_covariance(path_m)
        + ad_zb @ odometry_segment_covariance(path_q) @ ad_zb.T
        + sb
    )
    solved = np.linalg.solve(cov, error[..., None])[..., 0]
    return np.einsum("ni,ni->n", error, solved)


class ConsistencyGate:
    """Accepts verified loops once enough nearby loops agree with them (see the module docstring).

    `add(loop)` returns the decisions (indices) resolved by that loop: accepted (it and any
    pending loop it supports) or rejected; `expire(path_m)` rejects pending loops left behind;
    `finish()` rejects every pending loop.
    """

    def __init__(self, cfg: ConsistencyConfig) -> None:
        self.cfg = cfg
        self._loops: list[VerifiedLoop] = []
        self._status: list[LoopStatus] = []
        self._support: list[set[int]] = []  # per loop: decisions of the loops agreeing with it
        self._pending: list[int] = []  # positions of the pending loops
        self._query_paths: list[float] = []  # per loop: query path [m], to find the window
        self._in_path_order = True  # loops added in order of query path (the detector's case)
        self.reasons: dict[int, str] = {}  # decision -> reason of its latest status

    def __len__(self) -> int:
        return len(self._loops)

    def add(self, loop: VerifiedLoop) -> dict[int, LoopStatus]:
        """Check a verified loop against the pending and accepted ones nearby.

        Returns:
            decision -> new status of every loop whose status this call set (`loop` included).
        """
        cfg = self.cfg
        first = 0
        if self._in_path_order:  # only the loops whose query lies within the window
            first = bisect_left(self._query_paths, loop.query_path_m - WINDOW_M)
        live = [
            n
            for n, other in enumerate(self._loops[first:], start=first)
            if self._status[n] != "rejected"
            and other.query_key != loop.query_key
            and other.query_segment == loop.query_segment
            and other.match_segment == loop.match_segment
            and abs(loop.query_path_m - other.query_path_m) <= WINDOW_M
            and abs(loop.match_path_m - other.match_path_m) <= WINDOW_M
        ]
        d2 = cycle_mahalanobis(loop, [self._loops[n] for n in live])
        agree = [n for n, d in zip(live, d2, strict=True) if d <= CHI2_THRESHOLD]
        accepted_near = [n for n in live if self._status[n] == "accepted"]
        accepted_agree = [n for n in agree if self._status[n] == "accepted"]

        index = len(self._loops)
        if self._query_paths and loop.query_path_m < self._query_paths[-1]:
            self._in_path_order = False
        self._loops.append(loop)
        self._query_paths.append(loop.query_path_m)
        self._support.append({self._loops[n].decision for n in agree})
        changes: dict[int, LoopStatus] = {}
        if accepted_near and not accepted_agree:
            worst = float(np.min(d2[[live.index(n) for n in accepted_near]]))
            self._set(
                index,
                "rejected",
                f"inconsistent with {len(accepted_near)} accepted loop(s) nearby "
                f"(best cycle d2 {worst:.1f} > {CHI2_THRESHOLD:.1f})",
                changes,
            )
            return changes
        if len(agree) >= cfg.min_support:
            self._set(index, "accepted", f"consistent with {len(agree)} loop(s)", changes)
            for n in agree:
                self._support[n].add(loop.decision)
                if self._status[n] == "pending" and len(self._support[n]) >= cfg.min_support:
                    self._set(
                        n, "accepted", f"consistent with {len(self._support[n])} loop(s)", changes
                    )
        else:
            self._set(
                index,
                "pending",
                f"waiting for support ({len(agree)} of {cfg.min_support} consistent loops)",
                changes,
            )
            for n in agree:
                self._support[n].add(loop.decision)
        return changes

    def expire(self, path_m: float) -> dict[int, LoopStatus]:
        """Reject the pending loops whose query lies more than `WINDOW_M` behind `path_m`."""
        changes: dict[int, LoopStatus] = {}
        for n in list(self._pending):
            if path_m - self._loops[n].query_path_m > WINDOW_M:
                self._set(n, "rejected", self._unsupported(n), changes)
        return changes

    def finish(self) -> dict[int, LoopStatus]:
        """Reject every loop still pending (end of the sequence)."""
        changes: dict[int, LoopStatus] = {}
        for n in list(self._pending):
            self._set(n, "rejected", self._unsupported(n) + " by the end", changes)
        return changes

    def _unsupported(self, n: int) -> str:
        return (
            f"unsupported: {len(self._support[n])} of {self.cfg.min_support} consistent loops "
            f"within {WINDOW_M:.0f} m"
        )

    def _set(self, n: int, status: LoopStatus, reason: str, changes: dict[int, LoopStatus]) -> None:
        if n == len(self._status):
            self._status.append(status)
        else:
            if self._status[n] == "pending":
                self._pending.remove(n)
            self._status[n] = status
        if status == "pending":
            self._pending.append(n)
        decision = self._loops[n].decision
        self.reasons[decision] = reason
        changes[decision] = status
