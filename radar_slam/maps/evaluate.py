"""Accuracy of localisation in a map, through the map's own GT alignment (pure functions).

A localised pose T_map_radar is taken into the ground truth's frame by the map's stored
alignment T_gt_map, never re-aligned to the localised sequence: the figures say how well the
sequence is placed in the map, map errors included. Errors are expressed in the ground-truth
pose's frame: longitudinal along its x (forward), lateral along its y (left).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import NDArray

from radar_slam.maps.format import Map
from radar_slam.maps.localizer import Localization
from raplace import between, compose, wrap_angle

FloatArray = NDArray[np.float64]

NEAR_ROUTE_M = 10.0
"""Scans within this distance of the map's route (GT positions) should be localised [m]."""
GOOD_ERROR_M = 1.0
"""A localised scan is correct within this position error [m] ..."""
GOOD_ERROR_DEG = 2.0
"""... and this rotation error [deg]."""
WRONG_ERROR_M = 5.0
"""A localised scan farther off than this is wrongly localised [m]."""


@dataclass(frozen=True)
class LocalizationMetrics:
    """metrics.json of `radar-slam localize` (lengths [m], angles [deg], fractions 0..1).

    Attributes:
        scans: scans processed; localised: scans relocalised or tracked.
        relocalisations: global relocalisation events.
        fraction_localised: localised / scans.
        near_route_scans: scans with GT within `NEAR_ROUTE_M` of the map's route.
        near_route_correct: fraction of those localised within `GOOD_ERROR_M` and
            `GOOD_ERROR_DEG`.
        longitudinal_rmse_m, lateral_rmse_m, yaw_rmse_deg: RMS errors of the localised scans.
        max_error_m: largest position error of a localised scan.
        wrong_localised: localised scans more than `WRONG_ERROR_M` off.
        wrong_relocalisations: relocalisation events more than `WRONG_ERROR_M` off.
    """

    scans: int
    localised: int
    relocalisations: int
    fraction_localised: float
    near_route_scans: int
    near_route_correct: float | None
    longitudinal_rmse_m: float | None
    lateral_rmse_m: float | None
    yaw_rmse_deg: float | None
    max_error_m: float | None
    wrong_localised: int
    wrong_relocalisations: int

    def to_dict(self) -> dict[str, float | int | None]:
        return asdict(self)


def map_route_gt(m: Map) -> FloatArray:
    """(K, 2) the map keyframes' positions in the GT frame: their GT where known, else their
    map pose through the map's alignment (needs `m.gt_alignment`)."""
    gt = m.gt_poses[:, :2].copy()
    unknown = ~np.all(np.isfinite(gt), axis=1)
    if unknown.any():
        assert m.gt_alignment is not None
        gt[unknown] = compose(m.gt_alignment, m.poses[unknown])[:, :2]
    return gt


def _rms(values: FloatArray) -> float | None:
    return float(np.sqrt(np.mean(values**2))) if len(values) else None


def near_map_route(gt_poses: FloatArray, m: Map) -> NDArray[np.bool_]:
    """(N,) whether each GT pose (N, 3) lies within `NEAR_ROUTE_M` of the map's route (GT
    frame; NaN rows: False)."""
    gt = np.asarray(gt_poses, dtype=np.float64)
    route = map_route_gt(m)
    near = np.zeros(len(gt), dtype=bool)
    for n in np.flatnonzero(np.all(np.isfinite(gt), axis=1)):
        near[n] = float(np.min(np.hypot(*(route - gt[n, :2]).T))) <= NEAR_ROUTE_M
    return near


def evaluate_localization(
    fixes: Sequence[Localization], gt_poses: FloatArray, m: Map
) -> LocalizationMetrics | None:
    """Metrics of a localised sequence, or None when the map has no GT alignment.

    Args:
        fixes: one `Localization` per scan, in order.
        gt_poses: (N, 3) the sequence's ground truth per scan (NaN rows: unknown).
        m: the map (its `gt_alignment` and keyframes).
    """
    if m.gt_alignment is None:
        return None
    gt = np.asarray(gt_poses, dtype=np.float64)[: len(fixes)]
    known = np.all(np.isfinite(gt), axis=1)
    near = near_map_route(gt, m)
    localised = np.array([f.localised for f in fixes], dtype=bool)
    scored = np.flatnonzero(localised & known)
    errors = np.zeros((len(fixes), 3))
    if len(scored):
        poses = np.array([fixes[int(n)].pose for n in scored])
        errors[scored] = between(gt[scored], compose(m.gt_alignment, poses))
        errors[scored, 2] = wrap_angle(errors[scored, 2])
    distance = np.hypot(errors[:, 0], errors[:, 1])
    correct = localised & known & (distance <= GOOD_ERROR_M)
    correct &= np.abs(np.rad2deg(errors[:, 2])) <= GOOD_ERROR_DEG
    wrong = localised & known & (distance > WRONG_ERROR_M)
    relocalised = np.array([f.status == "relocalised" for f in fixes], dtype=bool)
    return LocalizationMetrics(
        scans=len(fixes),
        localised=int(localised.sum()),
        relocalisations=int(relocalised.sum()),
        fraction_localised=float(localised.mean()) if len(fixes) else 0.0,
        near_route_scans=int(near.sum()),
        near_route_correct=float(correct[near].mean()) if near.any() else None,
        longitudinal_rmse_m=_rms(errors[scored, 0]),
        lateral_rmse_m=_rms(errors[scored, 1]),
        yaw_rmse_deg=_rms(np.rad2deg(errors[scored, 2])),
        max_error_m=float(distance[scored].max()) if len(scored) else None,
        wrong_localised=int(wrong.sum()),
        wrong_relocalisations=int((wrong & relocalised).sum()),
    )
