"""False-loop injection: the robustness experiment of the loop closure.

On a fraction of the database queries a random database entry is put first among the candidates
(`InjectingRecognizer`); the fake verifier passes it with a plausible measurement (a small random
offset, as confident as a good real loop) when it lies more than `min_distance_m` from the query
on the ground truth (a false loop), and ignores it otherwise, so that the injection adds false
loops and nothing else (`InjectingVerifier`). Real candidates are verified by the wrapped
verifier as usual. Used by `scripts/bench_pipeline.py --inject-false` and the pipeline tests.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from radar_slam.loops import KeyScan, Verification, Verifier
from raplace import Candidate, Recognizer


@dataclass(frozen=True)
class FakeLoopConfig:
    """What an injected false loop claims.

    Attributes:
        min_distance_m: an injected candidate lies at least this far from the query (ground
            truth) [m]; a nearer one is ignored.
        max_offset_m: the fake T_query_match translation is uniform in +-this per axis [m].
        max_offset_yaw_rad: ... and its rotation uniform in +-this [rad].
        sigma_xy_m, sigma_yaw_rad: standard deviations of the covariance given to it [m], [rad].
        sinogram_quality, refined_quality: the qualities it reports.
    """

    min_distance_m: float = 50.0
    max_offset_m: float = 3.0
    max_offset_yaw_rad: float = float(np.deg2rad(10.0))
    sigma_xy_m: float = 0.1
    sigma_yaw_rad: float = float(np.deg2rad(0.2))
    sinogram_quality: float = 1.0
    refined_quality: float = 100.0


class FalseLoopInjection:
    """Shared state of the injecting recognizer and verifier.

    Attributes:
        ground_truth: (N, 3) poses of the scans by key (to tell false candidates from true).
        fraction: fraction of the queries given an injected candidate.
        rng: random source (drawn from by both the recognizer and the verifier).
        fake: what an injected loop claims.
        injected_key: the candidate injected into the current query (None: none).
        passed: (query, match) keys of the false loops the fake verifier passed.
    """

    def __init__(
        self,
        ground_truth: NDArray[np.float64],
        fraction: float,
        rng: np.random.Generator,
        fake: FakeLoopConfig | None = None,
    ) -> None:
        self.ground_truth = ground_truth
        self.fraction = fraction
        self.rng = rng
        self.fake = FakeLoopConfig() if fake is None else fake
        self.injected_key: int | None = None
        self.passed: set[tuple[int, int]] = set()

    def recognizer(self, inner: Recognizer) -> InjectingRecognizer:
        return InjectingRecognizer(inner, self)

    def verifier(self, inner: Verifier) -> InjectingVerifier:
        return InjectingVerifier(inner, self)


class InjectingRecognizer:
    """A place database that puts a random database entry first on a fraction of queries."""

    def __init__(self, inner: Recognizer, injection: FalseLoopInjection) -> None:
        self.inner = inner
        self.injection = injection
        self.keys: list[int] = []

    def __len__(self) -> int:
        return len(self.inner)

    def add(self, descriptor: NDArray, key: int, time_s: float | None = None) -> None:
        self.inner.add(descriptor, key, time_s)
        self.keys.append(key)

    def query(
        self, descriptor: NDArray, k: int = 1, time_s: float | None = None
    ) -> list[Candidate]:
        found = self.inner.query(descriptor, k, time_s)
        inj = self.injection
        inj.injected_key = None
        if not self.keys or inj.rng.random() >= inj.fraction:
            return found
        index = int(inj.rng.integers(len(self.keys)))
        inj.injected_key = self.keys[index]
        others = [c for c in found if c.key != inj.injected_key]
        return [Candidate(inj.injected_key, index, 0.0, 0.0, np.pi), *others]


class InjectingVerifier:
    """Passes an injected candidate far from the query with a fake measurement (a false loop),
    ignores one near it, and verifies the real candidates with the wrapped verifier."""

    def __init__(self, inner: Verifier, injection: FalseLoopInjection) -> None:
        self.inner = inner
        self.injection = injection

    def __call__(self, query: KeyScan, match: KeyScan) -> Verification:
        inj = self.injection
        if match.key != inj.injected_key:
            return self.inner(query, match)
        fake = inj.fake
        gt = inj.ground_truth
        if np.hypot(*(gt[query.key, :2] - gt[match.key, :2])) <= fake.min_distance_m:
            nan = np.full(3, np.nan)
            return Verification(
                False, "injected near the query", nan, np.full((3, 3), np.nan), nan, 0.0
            )
        inj.passed.add((query.key, match.key))
        offset = np.array(
            [
                inj.rng.uniform(-fake.max_offset_m, fake.max_offset_m),
                inj.rng.uniform(-fake.max_offset_m, fake.max_offset_m),
                inj.rng.uniform(-fake.max_offset_yaw_rad, fake.max_offset_yaw_rad),
            ]
        )
        covariance = np.diag([fake.sigma_xy_m**2, fake.sigma_xy_m**2, fake.sigma_yaw_rad**2])
        return Verification(
            True, "", offset, covariance, offset, fake.sinogram_quality, fake.refined_quality
        )
