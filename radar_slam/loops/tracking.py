"""Cheaper verifications along a closed stretch: the loop predicted from the stretch's latest one.

Along a stretch of road already closed by consecutive accepted loops
(`radar_slam.loops.throttle`), the next loop is known before it is measured: the latest accepted
loop T_q'm' of the stretch, carried to the new query q and match m by the odometry between q'
and q and between m' and m, predicts T_qm (`predicted_loop`). Over the few tens of metres
between throttled verifications the odometry is accurate to a few decimetres and a degree or
two, well inside the verifier's agreement bounds. So the loop detector checks such a candidate
with the phase-correlation refinement alone, started from the prediction
(`GeometricVerifier.refine`), instead of first estimating the relative pose from the two
sinograms (about half a verification's cost). The refinement must agree with the prediction as
it must otherwise agree with the sinogram estimate; a candidate that fails is verified again in
full, so a wrong prediction never rejects a loop, and the consistency gate checks every loop as
before.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radar_slam.loops.records import KeyScan, Verification
from raplace import between, compose

FloatArray = NDArray[np.float64]


@runtime_checkable
class Refiner(Protocol):
    """A verifier that can check a loop from an initial estimate (`GeometricVerifier.refine`)."""

    def refine(
        self, query: KeyScan, match: KeyScan, initial: FloatArray, initial_quality: float
    ) -> Verification: ...


def predicted_loop(
    query_pose: ArrayLike,
    match_pose: ArrayLike,
    anchor_query_pose: ArrayLike,
    anchor_match_pose: ArrayLike,
    anchor_measurement: ArrayLike,
) -> FloatArray:
    """T_query_match (3,) predicted from an accepted loop T_q'm' (`anchor_measurement`, the
    anchor) and the odometry: T_qm = (T_wq^-1 T_wq') T_q'm' (T_wm'^-1 T_wm).

    Args:
        query_pose, match_pose: (3,) odometry poses T_world_scan of the query and the match.
        anchor_query_pose, anchor_match_pose: (3,) odometry poses of the anchor's two scans (the
            odometry must be trusted between each and its counterpart).
        anchor_measurement: (3,) the anchor's measured T_q'm' (dx, dy [m], dyaw [rad]).
    """
    to_anchor_query = between(query_pose, anchor_query_pose)
    from_anchor_match = between(anchor_match_pose, match_pose)
    return compose(compose(to_anchor_query, anchor_measurement), from_anchor_match)
