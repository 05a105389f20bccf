"""SE(2) pose graph: a thin wrapper over GTSAM Pose2 with ISAM2 and a final batch pass.

Conventions (the whole project's):
- A pose is a (3,) float array `(x [m], y [m], yaw [rad])`, T_world_keyframe.
- A relative measurement between keyframes i and j is the pose of j in the frame of i,
  `T_i^-1 T_j` (`raplace.between(T_i, T_j)`), exactly what `gtsam.BetweenFactorPose2(i, j)`
  expects.
- A covariance is (3, 3) in GTSAM's Pose2 tangent space, order `(x [m], y [m], yaw [rad])`,
  expressed in the frame of the measurement itself (right perturbation: `z * Exp(delta)`). It
  must be symmetric positive definite; there is no identity default.

Anchoring: a graph must be tied to the world. If no prior has been added when the graph is first
optimised (`update()` or `optimize_final()`), a prior on the *first keyframe added*, at its initial
guess, with covariance `diag(PRIOR_SIGMAS ** 2)` is added automatically. An explicit
`add_prior` before that replaces the automatic one.

Loop factors carry the robust kernel of `GraphConfig.loop_kernel`; odometry and priors are plain
Gaussian. `update()` feeds ISAM2 only what is new since the last call; `optimize_final()` is a batch
Levenberg-Marquardt or GNC (odometry and priors as known inliers) over the whole graph.

Pure math: no files, no printing (g2o I/O lives in `radar_slam.g2o`; noise models, validation and
`add_loop_factors` for a user's own GTSAM graph in `radar_slam.factors`).
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import ClassVar, Literal

import gtsam
import numpy as np
from numpy.typing import ArrayLike, NDArray

from radar_slam.errors import GraphError
from radar_slam.factors import (
    DEFAULT_LOOP_KERNEL_WIDTH,
    POSE_DIM,
    LoopKernel,
    add_loop_factors,
    as_covariance,
    as_pose,
    gaussian_noise,
    loop_noise,
    m_estimator,
    pose2,
    relative_pose_covariance,
)
from radar_slam.loops.records import LoopConstraint
from raplace import between, checks, compose, wrap_angle
from raplace.config_io import replaced_by_constant

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]

FinalPass = Literal["lm", "gnc", "none"]
GncLoss = Literal["tls", "gm"]
ConstraintKind = Literal["odometry", "loop"]


PRIOR_SIGMAS: tuple[float, float, float] = (1e-3, 1e-3, 1e-4)
"""Standard deviations (x [m], y [m], yaw [rad]) of the prior anchoring the first keyframe (and
of the prior put on `FIX` vertices read from g2o): tight enough to pin the graph, loose enough
to keep it well conditioned."""

ONLINE_ISAM2_RELINEARIZATION = (0.01, 1)
"""ISAM2 relinearisation threshold (m / rad) and check interval (updates) when the online estimate
is the output (`final_pass: none`): a variable is relinearised once it moves 1 cm / 10 mrad."""

REFINED_ISAM2_RELINEARIZATION = (0.1, 10)
"""... and when a batch final pass refines the result (GTSAM's own defaults): the online estimate
then only serves the loop gates and the live view, and relinearising less keeps the cost of each
update from growing with the graph on long drives."""

ISAM2_ITERATIONS = 1
"""ISAM2 update steps per `PoseGraph.update()`: the first carries the new factors, any others
relinearise once more (helps the online estimate after a large loop-closure correction)."""

LM_MAX_ITERATIONS = 100
"""Levenberg-Marquardt iteration cap of the final pass (also inside GNC)."""
LM_RELATIVE_ERROR_TOL = 1e-10
"""Levenberg-Marquardt relative error decrease to stop at."""
LM_ABSOLUTE_ERROR_TOL = 1e-10
"""... and absolute error decrease."""

GNC_LOSS: GncLoss = "tls"
"""GNC surrogate loss: truncated least squares (rather than Geman-McClure): a loop is either an
inlier with its full weight or an outlier with none."""

GNC_INLIER_PROBABILITY = 0.9999
"""GNC inlier threshold: a loop whose squared Mahalanobis distance exceeds the chi-square quantile
at this probability (3 degrees of freedom: 21.1, i.e. 4.6 sigma) is treated as an outlier. 0.99
(11.3) made GNC reject true loops when the odometry covariance understates a strong drift
(tests/test_graph.py, "strong" scenario)."""

_RELINEARIZATION = (
    "graph.ONLINE_ISAM2_RELINEARIZATION or radar_slam.graph.REFINED_ISAM2_RELINEARIZATION, "
    "by final_pass"
)
_REPLACED_BY = {
    "prior_sigmas": "graph.PRIOR_SIGMAS",
    "isam2_relinearize_threshold": _RELINEARIZATION,
    "isam2_relinearize_skip": _RELINEARIZATION,
    "isam2_iterations": "graph.ISAM2_ITERATIONS",
    "loop_update_interval": "pipeline.slam.LOOP_UPDATE_INTERVAL",
    "settled_update_interval": "pipeline.slam.SETTLED_UPDATE_INTERVAL",
    "settled_chi2": "pipeline.slam.SETTLED_CHI2",
    "lm_max_iterations": "graph.LM_MAX_ITERATIONS",
    "lm_relative_error_tol": "graph.LM_RELATIVE_ERROR_TOL",
    "gnc_loss": "graph.GNC_LOSS",
    "gnc_inlier_probability": "graph.GNC_INLIER_PROBABILITY",
}
REMOVED_KEYS = {
    key: replaced_by_constant(f"radar_slam.{name}") for key, name in _REPLACED_BY.items()
}
"""Keys of the `graph` section that are gone, and what replaced them (`raplace.config_io`)."""


@dataclass(frozen=True)
class GraphConfig:
    """Settings of the pose-graph back end (the `graph` section of a radar-slam config).

    Attributes:
        loop_kernel: robust loss of loop factors in ISAM2 and the LM final pass ("cauchy",
            "huber" or "none"). "none" trusts every loop fully: only with loops known to be
            right (e.g. given by another system).
        loop_kernel_width: its parameter k, in standard deviations (whitened units). Lower it
            when false loops that pass verification pull the graph; raise it when true loops
            are weighted down because the odometry covariance is too tight.
        final_pass: batch pass of `optimize_final()`: "gnc", graduated non-convexity (odometry
            and priors known inliers, loops plain Gaussian under the GNC loss; the loops it
            weights down are rejected), "lm", Levenberg-Marquardt with the robust loop kernel,
            or "none": the online ISAM2 estimate is the result (live use, where no batch pass
            runs; relinearised more often, `ONLINE_ISAM2_RELINEARIZATION`).
    """

    REMOVED_KEYS: ClassVar[dict[str, str]] = REMOVED_KEYS
    loop_kernel: LoopKernel = "cauchy"
    loop_kernel_width: float = DEFAULT_LOOP_KERNEL_WIDTH
    final_pass: FinalPass = "gnc"

    def __post_init__(self) -> None:
        checks.one_of("loop_kernel", self.loop_kernel, ("cauchy", "huber", "none"))
        checks.one_of("final_pass", self.final_pass, ("lm", "gnc", "none"))
        checks.positive("loop_kernel_width", self.loop_kernel_width)

    def isam2_relinearization(self) -> tuple[float, int]:
        """The ISAM2 relinearisation threshold (m / rad) and check interval (updates) for
        `final_pass`."""
        return (
            ONLINE_ISAM2_RELINEARIZATION
            if self.final_pass == "none"
            else (REFINED_ISAM2_RELINEARIZATION)
        )


@dataclass(frozen=True)
class Constraint:
    """A relative-pose factor of the graph (odometry or loop), as stored by `PoseGraph`.

    Attributes:
        kind: "odometry" or "loop".
        i, j: keyframe keys.
        measurement: (3,) T_i^-1 T_j.
        covariance: (3, 3) measurement covariance (tangent order x, y, yaw).
    """

    kind: ConstraintKind
    i: int
    j: int
    measurement: FloatArray
    covariance: FloatArray


@dataclass(frozen=True)
class Prior:
    """A prior factor: keyframe `key` is at `pose` (3,) T_world_key with `covariance` (3, 3)."""

    key: int
    pose: FloatArray
    covariance: FloatArray


def _key(value: int, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise GraphError(f"{what}: a keyframe key is a non-negative integer, got {value!r}")
    return int(value)


def _between_factor(c: Constraint, noise: gtsam.noiseModel.Base) -> gtsam.BetweenFactorPose2:
    return gtsam.BetweenFactorPose2(c.i, c.j, pose2(c.measurement), noise)


def _prior_factor(p: Prior) -> gtsam.PriorFactorPose2:
    return gtsam.PriorFactorPose2(p.key, pose2(p.pose), gaussian_noise(p.covariance))


# --------------------------------------------------------------------------- the graph


@dataclass
class _SolverState:
    """Bookkeeping of what ISAM2 holds."""

    isam: gtsam.ISAM2
    keys: set[int] = field(default_factory=set)
    prior_slots: list[int] = field(default_factory=list)
    constraint_slots: dict[int, int] = field(default_factory=dict)  # constraint id -> slot
    cache: dict[int, FloatArray] | None = None  # key -> estimate; None = stale


class PoseGraph:
    """An SE(2) keyframe pose graph optimised incrementally by ISAM2.

    Typical use (keys increase with time):

        graph = PoseGraph(GraphConfig())
        graph.add_keyframe(0, (0, 0, 0))
        for k, (odom, odom_cov) in enumerate(motions, start=1):
            graph.add_keyframe(k, graph.predict(k - 1, odom))
            graph.add_odometry(k - 1, k, odom, odom_cov)
            graph.update()                    # k is now in ISAM2: marginals available
            for m, z, z_cov in verified_loops(k):   # e.g. from radar_slam.loops.LoopDetector
                graph.add_loop(k, m, z, z_cov)
            graph.update()                    # no-op step when no loop was added
        poses = graph.optimize_final()        # (N, 3), key order

    `estimates()` returns the latest solution: the final pass's until the graph changes, else
    ISAM2's; keyframes not yet in the solver report their initial guess.
    """

    def __init__(self, config: GraphConfig | None = None) -> None:
        self.config = config if config is not None else GraphConfig()
        self._initial: dict[int, FloatArray] = {}
        self._first_key: int | None = None
        self._priors: list[Prior] = []
        self._constraints: list[Constraint] = []
        self._active: list[bool] = []
        self._pending_priors: list[int] = []
        self._pending_constraints: list[int] = []
        self._pending_removals: list[int] = []
        self._parent: dict[int, int] = {}  # union-find over keys connected by factors
        self._final: dict[int, FloatArray] | None = None  # key -> final-pass estimate
        self._loop_weights: dict[int, float] = {}
        params = gtsam.ISAM2Params()
        threshold, skip = self.config.isam2_relinearization()
        params.setRelinearizeThreshold(threshold)
        params.relinearizeSkip = skip
        # QR, not Cholesky: a long chain of scans with a loop across a stop (simulated
        # long_city, 3,000 scans) is too ill-conditioned for Cholesky of the normal equations.
        params.setFactorization("QR")
        self._solver = _SolverState(isam=gtsam.ISAM2(params))

    # ----------------------------------------------------------------- building

    def add_keyframe(self, key: int, initial_guess: ArrayLike) -> None:
        """Add keyframe `key` with its initial guess (3,) T_world_key (the linearisation point).

        Pass a guess consistent with the current estimate, e.g. `predict(previous, odometry)`.
        """
        key = _key(key, "add_keyframe")
        if key in self._initial:
            raise GraphError(f"keyframe {key} added twice")
        self._initial[key] = as_pose(initial_guess, f"keyframe {key} initial guess")
        self._parent[key] = key
        if self._first_key is None:
            self._first_key = key
        self._final = None

    def add_prior(self, key: int, pose: ArrayLike, covariance: ArrayLike) -> None:
        """Add a prior: keyframe `key` is at `pose` (3,) T_world_key with `covariance` (3, 3)."""
        key = self._require(key, "add_prior")
        prior = Prior(key, as_pose(pose, f"prior on {key}"), as_covariance(covariance, "prior"))
        self._priors.append(prior)
        self._pending_priors.append(len(self._priors) - 1)
        self._final = None

    def add_odometry(self, i: int, j: int, measurement: ArrayLike, covariance: ArrayLike) -> int:
        """Add an odometry factor: `measurement` (3,) = T_i^-1 T_j with `covariance` (3, 3).

        Returns the constraint id.
        """
        return self._add_constraint("odometry", i, j, measurement, covariance)

    def add_loop(self, i: int, j: int, measurement: ArrayLike, covariance: ArrayLike) -> int:
        """Add a loop factor (robust kernel of the config): `measurement` (3,) = T_i^-1 T_j.

        Returns the loop's constraint id, for `remove_loop` and `loop_weights`.
        """
        return self._add_constraint("loop", i, j, measurement, covariance)

    def remove_loop(self, loop_id: int) -> None:
        """Disable a loop factor; ISAM2 drops it at the next `update()`."""
        if not 0 <= loop_id < len(self._constraints) or self._constraints[loop_id].kind != "loop":
            raise GraphError(f"no loop with id {loop_id}")
        if not self._active[loop_id]:
            return
        self._active[loop_id] = False
        slot = self._solver.constraint_slots.pop(loop_id, None)
        if slot is not None:
            self._pending_removals.append(slot)
        self._final = None

    def _add_constraint(
        self, kind: ConstraintKind, i: int, j: int, measurement: ArrayLike, covariance: ArrayLike
    ) -> int:
        i = self._require(i, f"add_{kind}")
        j = self._require(j, f"add_{kind}")
        if i == j:
            raise GraphError(f"{kind} factor from keyframe {i} to itself")
        what = f"{kind} {i} -> {j}"
        c = Constraint(
            kind,
            i,
            j,
            as_pose(measurement, f"{what} measurement"),
            as_covariance(covariance, f"{what} covariance"),
        )
        self._constraints.append(c)
        self._active.append(True)
        self._pending_constraints.append(len(self._constraints) - 1)
        self._union(i, j)
        self._final = None
        return len(self._constraints) - 1

    def _require(self, key: int, what: str) -> int:
        key = _key(key, what)
        if key not in self._initial:
            raise GraphError(f"{what}: keyframe {key} was never added")
        return key

    # ----------------------------------------------------------------- union-find (anchoring)

    def _root(self, key: int) -> int:
        root = key
        while self._parent[root] != root:
            root = self._parent[root]
        while self._parent[key] != root:  # path compression
            self._parent[key], key = root, self._parent[key]
        return root

    def _union(self, a: int, b: int) -> None:
        ra, rb = self._root(a), self._root(b)
        if ra != rb:
            self._parent[max(ra, rb)] = min(ra, rb)

    def _ensure_anchor(self) -> None:
        if not self._priors and self._first_key is not None and self._constraints:
            key = self._first_key
            sigmas = np.asarray(PRIOR_SIGMAS, dtype=np.float64)
            log.debug("anchoring keyframe %d with the default prior %s", key, sigmas)
            self.add_prior(key, self._initial[key], np.diag(sigmas**2))

    def _check_anchored(self, keys: Iterable[int]) -> None:
        anchored = {self._root(p.key) for p in self._priors}
        loose = sorted(k for k in set(keys) if self._root(k) not in anchored)
        if loose:
            shown = ", ".join(map(str, loose[:10])) + (" ..." if len(loose) > 10 else "")
            raise GraphError(
                f"keyframes {shown} are not connected to any keyframe with a prior "
                "(add the odometry that links them first)"
            )

    # ----------------------------------------------------------------- optimisation

    def update(self) -> None:
        """Run ISAM2 with only the factors and keyframes added (or loops removed) since the last
        call. With nothing new it is one more relinearisation step. Keyframes that no factor uses
        yet stay pending (their estimate is their initial guess).

        Raises GraphError when a new factor touches keyframes not connected to a prior, or when
        GTSAM fails (after the latter the ISAM2 state is undefined: rebuild the graph)."""
        self._ensure_anchor()
        priors = [self._priors[n] for n in self._pending_priors]
        constraints = [n for n in self._pending_constraints if self._active[n]]
        self._check_anchored(
            [p.key for p in priors]
            + [k for n in constraints for k in (self._constraints[n].i, self._constraints[n].j)]
        )
        factors = gtsam.NonlinearFactorGraph()
        for p in priors:
            factors.add(_prior_factor(p))
        for n in constraints:
            factors.add(self._factor(n, robust=True))
        values = gtsam.Values()
        new_keys = sorted(
            {p.key for p in priors}.union(
                *({self._constraints[n].i, self._constraints[n].j} for n in constraints)
            )
            - self._solver.keys
        )
        for key in new_keys:
            values.insert(key, pose2(self._initial[key]))
        if factors.size() == 0 and not self._pending_removals and not self._solver.keys:
            return
        isam = self._solver.isam
        try:
            result = isam.update(factors, values, list(self._pending_removals))
            for _ in range(ISAM2_ITERATIONS - 1):
                isam.update()
        except RuntimeError as exc:  # GTSAM's IndeterminantLinearSystemException and friends
            raise GraphError(f"ISAM2 update failed: {exc}") from None
        slots = list(result.getNewFactorsIndices())
        self._solver.prior_slots.extend(slots[: len(priors)])
        self._solver.constraint_slots.update(zip(constraints, slots[len(priors) :], strict=True))
        self._solver.keys.update(new_keys)
        self._pending_priors.clear()
        self._pending_constraints.clear()
        self._pending_removals.clear()
        self._solver.cache = None
        self._final = None

    def optimize_final(self) -> FloatArray:
        """Batch pass over the whole graph from the current estimate; returns (N, 3) in key order.

        "lm": Levenberg-Marquardt, loops under the robust kernel. "gnc": graduated non-convexity
        with odometry and priors as known inliers and loops plain Gaussian (GNC supplies the robust
        loss); loops whose GNC weight ends near 0 are the rejected ones (`loop_weights()`).
        "none": returns `estimates()`. ISAM2 is not modified.
        """
        cfg = self.config
        if cfg.final_pass == "none":
            return self.estimates()
        self._ensure_anchor()
        active = [n for n, on in enumerate(self._active) if on]
        keys_used = {p.key for p in self._priors}.union(
            *({self._constraints[n].i, self._constraints[n].j} for n in active)
        )
        self._check_anchored(keys_used)
        if not keys_used:
            return self.estimates()
        use_gnc = cfg.final_pass == "gnc"
        graph = gtsam.NonlinearFactorGraph()
        for p in self._priors:
            graph.add(_prior_factor(p))
        factor_of: dict[int, int] = {}
        for n in active:
            factor_of[n] = graph.size()
            graph.add(self._factor(n, robust=not use_gnc))
        current = dict(zip(self.keys(), self.estimates(), strict=True))
        initial = gtsam.Values()
        for key in sorted(keys_used):
            initial.insert(key, pose2(current[key]))
        lm = gtsam.LevenbergMarquardtParams()
        lm.setMaxIterations(LM_MAX_ITERATIONS)
        lm.setRelativeErrorTol(LM_RELATIVE_ERROR_TOL)
        lm.setAbsoluteErrorTol(LM_ABSOLUTE_ERROR_TOL)
        loops = [n for n in active if self._constraints[n].kind == "loop"]
        try:
            if use_gnc and loops:
                params = gtsam.GncLMParams(lm)
                loss = gtsam.GncLossType.TLS if GNC_LOSS == "tls" else gtsam.GncLossType.GM
                params.setLossType(loss)
                loop_factors = {factor_of[n] for n in loops}
                params.setKnownInliers([f for f in range(graph.size()) if f not in loop_factors])
                optimizer = gtsam.GncLMOptimizer(graph, initial, params)
                optimizer.setInlierCostThresholdsAtProbability(GNC_INLIER_PROBABILITY)
                result = optimizer.optimize()
                weights = np.asarray(optimizer.getWeights(), dtype=np.float64)
                self._loop_weights = {n: float(weights[factor_of[n]]) for n in loops}
            else:
                result = gtsam.LevenbergMarquardtOptimizer(graph, initial, lm).optimize()
                self._loop_weights = {n: self._kernel_weight(n, result) for n in loops}
        except RuntimeError as exc:
            raise GraphError(f"final {cfg.final_pass} pass failed: {exc}") from None
        rejected = sum(w < 0.5 for w in self._loop_weights.values())
        log.info(
            "final %s pass: %d keyframes, %d loops (%d with weight < 0.5), error %.6g -> %.6g",
            cfg.final_pass,
            len(keys_used),
            len(loops),
            rejected,
            graph.error(initial),
            graph.error(result),
        )
        for key in keys_used:
            current[key] = _pose_of(result.atPose2(key))
        self._final = current
        return self.estimates()

    def _factor(self, n: int, robust: bool) -> gtsam.BetweenFactorPose2:
        c = self._constraints[n]
        if c.kind == "loop" and robust:
            noise = loop_noise(c.covariance, self.config.loop_kernel, self.config.loop_kernel_width)
        else:
            noise = gaussian_noise(c.covariance)
        return _between_factor(c, noise)

    def _kernel_weight(self, n: int, values: gtsam.Values) -> float:
        c = self._constraints[n]
        z = pose2(c.measurement)
        error = gtsam.Pose2.Logmap(z.between(values.atPose2(c.i).between(values.atPose2(c.j))))
        distance = float(np.sqrt(error @ np.linalg.solve(c.covariance, error)))
        estimator = m_estimator(self.config.loop_kernel, self.config.loop_kernel_width)
        return 1.0 if estimator is None else float(estimator.weight(distance))

    # ----------------------------------------------------------------- queries

    def keys(self) -> list[int]:
        """Keyframe keys in increasing order (the row order of `estimates()`)."""
        return sorted(self._initial)

    def __len__(self) -> int:
        return len(self._initial)

    def initial_values(self) -> FloatArray:
        """(N, 3) initial guesses T_world_key in key order."""
        return np.array([self._initial[k] for k in self.keys()], dtype=np.float64).reshape(-1, 3)

    def _solver_estimates(self) -> dict[int, FloatArray]:
        """Key -> ISAM2 estimate (3,), computed once per update."""
        if self._solver.cache is None:
            values = self._solver.isam.calculateEstimate()
            keys = sorted(self._solver.keys)
            poses = np.asarray(gtsam.utilities.extractPose2(values), dtype=np.float64)
            self._solver.cache = dict(zip(keys, poses.reshape(-1, POSE_DIM), strict=True))
        return self._solver.cache

    def _solver_pose(self, key: int) -> FloatArray:
        """(3,) ISAM2 estimate of one key already in the solver, without a full-graph copy."""
        if self._solver.cache is not None:
            return self._solver.cache[key]
        return _pose_of(self._solver.isam.calculateEstimatePose2(key))

    def estimates(self) -> FloatArray:
        """(N, 3) latest estimates T_world_key in key order (see the class docstring)."""
        latest = self._final if self._final is not None else self._solver_estimates()
        rows = [latest.get(k, self._initial[k]) for k in self.keys()]
        return np.array(rows, dtype=np.float64).reshape(-1, POSE_DIM)

    def estimate(self, key: int) -> FloatArray:
        """(3,) latest estimate T_world_key of one keyframe (cheap: no full-graph copy)."""
        key = self._require(key, "estimate")
        if self._final is not None:
            return self._final[key].copy()
        if key in self._solver.keys:
            return self._solver_pose(key).copy()
        return self._initial[key].copy()

    def predict(self, key: int, measurement: ArrayLike) -> FloatArray:
        """(3,) estimate(key) composed with a relative `measurement` (3,): an initial guess for a
        new keyframe seen from `key`."""
        return compose(self.estimate(key), as_pose(measurement, "predict measurement"))

    def residual_chi2(self, constraint_id: int) -> float:
        """Squared Mahalanobis distance of a factor's measurement from the latest estimates of
        its two keyframes (before the next update: how much the factor still has to correct)."""
        if not 0 <= constraint_id < len(self._constraints):
            raise GraphError(f"no constraint with id {constraint_id}")
        c = self._constraints[constraint_id]
        error = between(c.measurement, between(self.estimate(c.i), self.estimate(c.j)))
        error[2] = wrap_angle(error[2])
        return float(error @ np.linalg.solve(c.covariance, error))

    def priors(self) -> list[Prior]:
        """All priors (the automatic one included once the graph has been optimised)."""
        return list(self._priors)

    def constraints(self, include_removed: bool = False) -> list[tuple[int, Constraint]]:
        """(constraint id, Constraint) of the odometry and loop factors, in insertion order."""
        return [
            (n, c) for n, c in enumerate(self._constraints) if include_removed or self._active[n]
        ]

    def loop_weights(self) -> dict[int, float]:
        """Loop id -> weight in [0, 1] after the last `optimize_final()` (GNC weight, or the robust
        kernel's weight at the solution for "lm"); < 0.5 means effectively rejected."""
        return dict(self._loop_weights)

    @property
    def num_isam2_factors(self) -> int:
        """Number of (non-removed) factors ISAM2 holds."""
        return int(self._solver.isam.getFactorsUnsafe().nrFactors())

    def _require_solved(self, key: int, what: str) -> int:
        key = self._require(key, what)
        if key not in self._solver.keys:
            raise GraphError(f"{what}: keyframe {key} is not in the solver yet; call update()")
        return key

    def marginal_covariance(self, key: int) -> FloatArray:
        """(3, 3) marginal covariance of keyframe `key` from ISAM2 (after `update()`), in the
        keyframe's body frame, order (x [m], y [m], yaw [rad])."""
        key = self._require_solved(key, "marginal_covariance")
        return np.asarray(self._solver.isam.marginalCovariance(key), dtype=np.float64)

    def relative_covariance(self, i: int, j: int) -> FloatArray:
        """(3, 3) covariance of the estimated T_i^-1 T_j (ISAM2 joint marginal of i and j,
        first-order propagation), in the frame of that relative pose."""
        i = self._require_solved(i, "relative_covariance")
        j = self._require_solved(j, "relative_covariance")
        if i == j:
            raise GraphError(f"relative_covariance: same keyframe {i} twice")
        joint = self._solver.isam.jointMarginalCovariance([i, j])
        full = np.block([[joint.at(i, i), joint.at(i, j)], [joint.at(j, i), joint.at(j, j)]])
        return relative_pose_covariance(self._solver_pose(i), self._solver_pose(j), full)


def _pose_of(pose: gtsam.Pose2) -> FloatArray:
    return np.array([pose.x(), pose.y(), pose.theta()], dtype=np.float64)


__all__ = [
    "DEFAULT_LOOP_KERNEL_WIDTH",
    "POSE_DIM",
    "Constraint",
    "GraphConfig",
    "LoopConstraint",
    "LoopKernel",
    "PoseGraph",
    "Prior",
    "add_loop_factors",
    "as_covariance",
    "as_pose",
    "gaussian_noise",
    "loop_noise",
    "relative_pose_covariance",
]
