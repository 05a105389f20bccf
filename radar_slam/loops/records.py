"""Records of loop closing: the constraint handed to a back end and the detector's decisions.

Measurements follow the graph convention: a loop (i = query, j = match) measures T_i^-1 T_j,
the match scan's pose in the query scan's frame (x forward, y left [m], yaw CCW [rad]).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from odometry import PolarScan, Scan
from radar_slam.errors import RadarSlamError

FloatArray = NDArray[np.float64]
LoopStatus = Literal["accepted", "rejected", "pending"]


class LoopClosureError(RadarSlamError):
    """Loop-closing input is inconsistent (poses given for some scans only, keys reused, ...)."""


class LoopConstraint(NamedTuple):
    """A verified loop: the pose of keyframe j in the frame of keyframe i, with its covariance.

    Attributes:
        i: key of the reference (usually the query) keyframe.
        j: key of the other keyframe.
        measurement: (3,) T_i^-1 T_j `(x [m], y [m], yaw [rad])`.
        covariance: (3, 3) of the measurement, tangent order (x, y, yaw), frame of the measurement.
    """

    i: int
    j: int
    measurement: ArrayLike
    covariance: ArrayLike


@dataclass(frozen=True)
class Verification:
    """Outcome of the geometric verification of one proposal.

    Attributes:
        ok: every check passed.
        reason: why it failed ("" when ok).
        measurement: (3,) T_query_match, the refined estimate when available, else the sinogram
            estimate (NaN before any estimate).
        covariance: (3, 3) of `measurement` (GTSAM tangent order x, y, yaw; NaN unless ok).
        sinogram: (3,) the sinogram estimate of T_query_match.
        sinogram_quality: its aligned normalised correlation.
        refined_quality: peak-to-noise ratio of the phase-correlation refinement (0 if not run).
    """

    ok: bool
    reason: str
    measurement: FloatArray
    covariance: FloatArray
    sinogram: FloatArray
    sinogram_quality: float
    refined_quality: float = 0.0


@dataclass(frozen=True)
class LoopDecision:
    """What happened to one verified proposal (a row of loops.csv).

    Attributes:
        query_key, match_key: keys of the two scans (scan indices in the pipeline).
        query_ns, match_ns: their timestamps [ns].
        distance: RaPlace descriptor distance.
        measurement: (3,) T_query_match (dx, dy [m], dyaw [rad]); NaN when no estimate exists.
        covariance: (3, 3) of the measurement (NaN unless verified).
        sinogram_quality: normalised correlation after the sinogram alignment.
        refined_quality: phase-correlation peak-to-noise ratio (0 if not run).
        status: "accepted", "rejected" or "pending" (waiting for consistent support).
        reason: why (accepted or not), one line.
    """

    query_key: int
    match_key: int
    query_ns: int
    match_ns: int
    distance: float
    measurement: FloatArray
    covariance: FloatArray
    sinogram_quality: float
    refined_quality: float
    status: LoopStatus
    reason: str

    @classmethod
    def of(
        cls,
        query: KeyScan,
        match: KeyScan,
        match_key: int,
        distance: float,
        result: Verification,
    ) -> LoopDecision:
        """The decision on a verified proposal: rejected if verification failed, else pending."""
        return cls(
            query_key=query.key,
            match_key=match_key,
            query_ns=int(query.timestamp_ns),
            match_ns=int(match.timestamp_ns),
            distance=distance,
            measurement=np.asarray(result.measurement, dtype=np.float64),
            covariance=np.asarray(result.covariance, dtype=np.float64),
            sinogram_quality=result.sinogram_quality,
            refined_quality=result.refined_quality,
            status="pending" if result.ok else "rejected",
            reason=result.reason,
        )

    @property
    def accepted(self) -> bool:
        return self.status == "accepted"

    def constraint(self) -> LoopConstraint:
        """The loop as a graph constraint (i = query, j = match)."""
        return LoopConstraint(self.query_key, self.match_key, self.measurement, self.covariance)


@dataclass(frozen=True)
class KeyScan:
    """A database scan as the verifier sees it.

    Attributes:
        key: the caller's key (scan index).
        timestamp_ns: scan time [ns].
        scan: the scan itself.
        twist: (3,) body velocity (vx, vy [m/s], yaw rate [rad/s]) for de-skewing, or None.
        twist_change: (3,) change of the odometry's twist across the scan (the step after's
            minus the step before's, same units), or None; the de-skew twist's error grows
            with it (`LoopCovarianceConfig.deskew_error_fraction`).
        twist_span_s: time between the two odometry steps' middles the twist was interpolated
            between [s] (about the scan interval), or None; at low frame rates the sweep's yaw
            rate can be far from that interpolation (`verification.YAW_RATE_SEARCH`).
        sweep_s: how long the scan's sweep lasted [s] when `scan` has no azimuth times but
            stands for one that had (a scan's record: its image already de-skewed), or None;
            the loop covariance's de-skew terms grow with it.
        polar: `scan` conditioned with the verifier's odometry settings (`odometry.Odometry`'s
            own, in a run), or None: the verifier conditions it.
    """

    key: int
    timestamp_ns: int
    scan: Scan
    twist: FloatArray | None = None
    twist_change: FloatArray | None = None
    twist_span_s: float | None = None
    sweep_s: float | None = None
    polar: PolarScan | None = None


def raplace_input(polar: PolarScan) -> tuple[NDArray[np.float32], FloatArray, float]:
    """A conditioned scan as RaPlace's extractors (`LOOP_RAPLACE`) take it: its image (n_azimuths,
    n_bins), the azimuth of each row (n_azimuths,) [rad] CCW from +x, its bin size [m]."""
    rows = np.arange(polar.n_azimuths, dtype=np.float64)
    return polar.image, polar.first_azimuth_rad + rows * polar.azimuth_step_rad, polar.bin_size_m


@dataclass(frozen=True)
class VerifiedLoop:
    """A verified loop as the consistency gate sees it.

    Attributes:
        decision: index of its `LoopDecision`.
        query_key, match_key: scan keys.
        measurement: (3,) T_query_match; covariance: (3, 3).
        query_pose, match_pose: (3,) odometry poses T_world_scan of the two scans.
        query_path_m, match_path_m: odometry path length from the first scan [m].
        query_segment, match_segment: odometry segments of the two scans: the number of odometry
            steps before them faster than a vehicle moves or turns (the odometry is not trusted
            across such a step, so loops on either side of one do not judge each other).
    """

    decision: int
    query_key: int
    match_key: int
    measurement: FloatArray
    covariance: FloatArray
    query_pose: FloatArray
    match_pose: FloatArray
    query_path_m: float
    match_path_m: float
    query_segment: int = 0
    match_segment: int = 0
