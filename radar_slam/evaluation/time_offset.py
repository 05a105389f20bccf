"""The clock offset between a trajectory and its ground truth, from their speed profiles.

Ground truth often runs on another clock than the radar (a GNSS receiver's, a logging PC's):
scored as stamped, every metric then carries metres of error that are not the method's. The
offset d (GT clock minus estimate clock: the estimate's pose at t is the GT's at t + d) is found
without any heading: the speed |v(t)| of the estimate is cross-correlated with the GT's speed
|v(t + d)| over a grid of candidate offsets, and the peak refined by a parabola. Its
uncertainty is a block jackknife over `JACKKNIFE_BLOCKS` stretches of the drive.

Speeds come from finite differences of consecutive poses; a difference over a gap (a GT outage,
dropped scans: longer than `max_step_s` of the trajectory) is not a speed and is left out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from radar_slam.trajectory import Trajectory
from raplace import NS_PER_S, wrap_angle

FloatArray = NDArray[np.float64]

GRID_HZ = 20.0
"""Sampling rate of the speed profiles that are compared [Hz]."""
SEARCH_STEP_S = 0.01
"""Spacing of the candidate offsets [s]; the peak is then refined between them."""
DEFAULT_MAX_OFFSET_S = 5.0
"""Offsets searched: -max .. +max [s]."""
MAX_STEP_S = 0.6
"""A pose difference over a longer time is not a speed (an outage or dropped scans) [s] ..."""
GAP_FACTOR = 1.5
"""... unless the trajectory's own sampling is slower: then 1.5 of its median sample period."""
MIN_OVERLAP_S = 20.0
"""At least this much common driving for an estimate [s]."""
MIN_SPEED_STD_MPS = 0.5
"""A drive at constant speed has no profile to match: below this spread, no estimate [m/s]."""
JACKKNIFE_BLOCKS = 8
COARSE_STRIDE = 5
"""Offsets are first scored every this many search steps (one grid interval: the speed
correlation's peak is seconds wide), then every step around the best."""
PART_SEARCH_S = 1.0
"""Parts of a drive (jackknife, halves) are searched within this of the whole drive's peak [s];
a part's peak further off is at the window's edge, which shows as a large sigma."""


@dataclass(frozen=True)
class TimeOffset:
    """An estimated clock offset.

    Attributes:
        offset_s: GT clock minus estimate clock [s]: the estimate at t is the GT at t + offset.
        sigma_s: its one-sigma uncertainty (block jackknife) [s].
        correlation: the speed profiles' correlation at the offset (1 is a perfect match).
        overlap_s: how much driving the estimate rests on [s].
        halves_s: the offsets estimated from the first and the second half of the drive alone
            (NaN where a half is too short): how stable the estimate is.
    """

    offset_s: float
    sigma_s: float
    correlation: float
    overlap_s: float
    halves_s: tuple[float, float]

    def to_dict(self) -> dict[str, float | list[float | None]]:
        return {
            "offset_s": self.offset_s,
            "sigma_s": self.sigma_s,
            "correlation": self.correlation,
            "overlap_s": self.overlap_s,
            "halves_s": [v if np.isfinite(v) else None for v in self.halves_s],
        }


def max_step_s(times_ns: NDArray[np.int64]) -> float:
    """The longest step between samples that is not a gap [s]: `MAX_STEP_S`, or `GAP_FACTOR`
    median sample periods for a trajectory sampled more slowly (a 1 Hz odometry)."""
    if len(times_ns) < 2:
        return MAX_STEP_S
    return max(MAX_STEP_S, GAP_FACTOR * float(np.median(np.diff(times_ns))) / NS_PER_S)


def speed_samples(trajectory: Trajectory) -> tuple[FloatArray, FloatArray, float]:
    """(mid times [s], speeds [m/s], the step limit [s]) of consecutive poses at most
    `max_step_s` apart."""
    t = trajectory.timestamps_ns.astype(np.float64) / NS_PER_S
    step = np.diff(trajectory.poses[:, :2], axis=0)
    dt = np.diff(t)
    limit = max_step_s(trajectory.timestamps_ns)
    ok = (dt > 0) & (dt <= limit)
    speed = np.hypot(step[:, 0], step[:, 1])[ok] / dt[ok]
    return 0.5 * (t[1:] + t[:-1])[ok], speed, limit


def _profile(
    times_s: FloatArray, speeds: FloatArray, grid_s: FloatArray, limit_s: float
) -> FloatArray:
    """Speeds interpolated onto `grid_s`; NaN where no two samples `limit_s` apart bracket."""
    if len(times_s) < 2:
        return np.full(len(grid_s), np.nan)
    values = np.interp(grid_s, times_s, speeds)
    right = np.clip(np.searchsorted(times_s, grid_s), 1, len(times_s) - 1)
    bracket = times_s[right] - times_s[right - 1]
    outside = (grid_s < times_s[0]) | (grid_s > times_s[-1]) | (bracket > limit_s)
    values[outside] = np.nan
    return values


def _correlation(a: FloatArray, b: FloatArray) -> tuple[float, int]:
    """Pearson correlation over the samples both have, and how many they are."""
    both = np.isfinite(a) & np.isfinite(b)
    n = int(both.sum())
    if n < 3:
        return float("nan"), n
    a, b = a[both], b[both]
    x, y = a - a.mean(), b - b.mean()
    denominator = float(np.sqrt(np.sum(x * x) * np.sum(y * y)))
    return (float(np.sum(x * y) / denominator) if denominator > 0 else float("nan")), n


def _scores(
    est_profile: FloatArray, gt_fine: FloatArray, rows: NDArray[np.int64], shifts: NDArray[np.int64]
) -> tuple[FloatArray, NDArray[np.int64]]:
    """The speed correlation at each of `shifts` and its sample count (see `_best_offset`)."""
    scores = np.full(len(shifts), np.nan)
    counts = np.zeros(len(shifts), dtype=np.int64)
    for k, shift in enumerate(shifts):
        scores[k], counts[k] = _correlation(est_profile, gt_fine[rows + shift])
    return scores, counts


def _best_offset(
    est_profile: FloatArray, gt_fine: FloatArray, rows: NDArray[np.int64], shifts: NDArray[np.int64]
) -> tuple[float, float, float]:
    """(offset [s], correlation, overlap [s]) maximising the speed correlation.

    Args:
        est_profile: (G,) estimate speeds on the grid.
        gt_fine: GT speeds every `SEARCH_STEP_S`, index 0 at the grid's start minus the largest
            offset searched.
        rows: (G,) index in `gt_fine` of each grid time at offset zero.
        shifts: candidate offsets in steps of `SEARCH_STEP_S`: every `COARSE_STRIDE`-th scored,
            then those around the best of them.
    """
    coarse = shifts[::COARSE_STRIDE]
    scores, counts = _scores(est_profile, gt_fine, rows, coarse)
    valid = (counts >= MIN_OVERLAP_S * GRID_HZ) & np.isfinite(scores)
    if not np.any(valid):
        return float("nan"), float("nan"), 0.0
    top = coarse[int(np.nanargmax(np.where(valid, scores, np.nan)))]
    shifts = shifts[np.abs(shifts - top) <= COARSE_STRIDE]
    scores, counts = _scores(est_profile, gt_fine, rows, shifts)
    enough = counts >= MIN_OVERLAP_S * GRID_HZ
    if not np.any(enough & np.isfinite(scores)):
        return float("nan"), float("nan"), 0.0
    scores[~enough] = np.nan
    k = int(np.nanargmax(scores))
    offset = float(shifts[k]) * SEARCH_STEP_S
    if 0 < k < len(shifts) - 1 and np.isfinite(scores[k - 1 : k + 2]).all():
        left, mid, right = scores[k - 1], scores[k], scores[k + 1]
        curvature = left - 2.0 * mid + right
        if curvature < 0:
            offset += 0.5 * SEARCH_STEP_S * float(left - right) / float(curvature)
    return offset, float(scores[k]), float(counts[k] / GRID_HZ)


def estimate_time_offset(
    estimate: Trajectory, ground_truth: Trajectory, max_offset_s: float = DEFAULT_MAX_OFFSET_S
) -> TimeOffset | None:
    """The clock offset of `ground_truth` against `estimate` from their speed profiles.

    Cost: one pass over 2 * max_offset_s / SEARCH_STEP_S / COARSE_STRIDE candidate offsets,
    then eleven over 2 * PART_SEARCH_S / SEARCH_STEP_S / COARSE_STRIDE (and the steps around
    each pass's best).

    Args:
        estimate: e.g. the odometry, one pose per scan (any frame: only speeds are used).
        ground_truth: GT poses with their own stamps (NaN rows already dropped).
        max_offset_s: offsets searched are within +-this [s].

    Returns:
        None when the two overlap by less than `MIN_OVERLAP_S` of driving or the speed barely
        varies (no profile to match).
    """
    est_t, est_v, est_limit = speed_samples(estimate)
    gt_t, gt_v, gt_limit = speed_samples(ground_truth)
    if len(est_t) < 3 or len(gt_t) < 3 or np.std(est_v) < MIN_SPEED_STD_MPS:
        return None
    grid = np.arange(est_t[0], est_t[-1], 1.0 / GRID_HZ)
    est_profile = _profile(est_t, est_v, grid, est_limit)
    reach = int(np.ceil(max_offset_s / SEARCH_STEP_S))
    fine = grid[0] + SEARCH_STEP_S * np.arange(
        -reach, int((grid[-1] - grid[0]) / SEARCH_STEP_S) + reach + 2
    )
    gt_fine = _profile(gt_t, gt_v, fine, gt_limit)
    rows = reach + np.round((grid - grid[0]) / SEARCH_STEP_S).astype(np.int64)
    shifts = np.arange(-reach, reach + 1)

    def best(keep: NDArray[np.bool_], around: NDArray[np.int64]) -> tuple[float, float, float]:
        return _best_offset(est_profile[keep], gt_fine, rows[keep], around)

    everything = np.ones(len(grid), dtype=bool)
    offset, correlation, overlap = best(everything, shifts)
    if not np.isfinite(offset):
        return None
    # Parts of the drive are searched near the whole drive's peak only.
    centre = int(round(offset / SEARCH_STEP_S))
    near = shifts[np.abs(shifts - centre) <= int(round(PART_SEARCH_S / SEARCH_STEP_S))]
    leave_one_out = []
    for block in np.array_split(np.arange(len(grid)), JACKKNIFE_BLOCKS):
        keep = everything.copy()
        keep[block] = False
        leave_one_out.append(best(keep, near)[0])
    values = np.array(leave_one_out)
    values = values[np.isfinite(values)]
    n = len(values)
    sigma = float(np.sqrt((n - 1) / n * np.sum((values - values.mean()) ** 2))) if n > 1 else 0.0
    first = np.arange(len(grid)) < len(grid) // 2
    halves = (best(first, near)[0], best(~first, near)[0])
    return TimeOffset(offset, sigma, correlation, overlap, halves)


def ground_truth_at(ground_truth: Trajectory, times_ns: NDArray[np.int64]) -> FloatArray:
    """(N, 3) GT poses at `times_ns` by interpolation; NaN rows in outages or off the span."""
    t = ground_truth.timestamps_ns
    poses = ground_truth.poses
    query = np.asarray(times_ns, dtype=np.int64)
    result = np.full((len(query), 3), np.nan)
    if len(t) < 2:
        return result
    right = np.clip(np.searchsorted(t, query), 1, len(t) - 1)
    left = right - 1
    span = (t[right] - t[left]).astype(np.float64)
    ok = (query >= t[0]) & (query <= t[-1]) & (span <= max_step_s(t) * NS_PER_S)
    weight = (query[ok] - t[left][ok]) / span[ok]
    a, b = poses[left][ok], poses[right][ok]
    result[ok, :2] = a[:, :2] + weight[:, None] * (b[:, :2] - a[:, :2])
    result[ok, 2] = wrap_angle(a[:, 2] + weight * wrap_angle(b[:, 2] - a[:, 2]))
    return result


def ground_truth_with_offset(
    ground_truth: Trajectory, times_ns: NDArray[np.int64], offset_s: float
) -> Trajectory:
    """The GT at the estimate's times `times_ns` read through an offset: the pose of time t is
    the GT's at t + offset. Times without a GT pose (outage, off the span) are left out."""
    offset_ns = int(round(offset_s * NS_PER_S))
    poses = ground_truth_at(ground_truth, np.asarray(times_ns, dtype=np.int64) + offset_ns)
    return Trajectory.from_arrays(times_ns, poses, drop_nonfinite=True)
