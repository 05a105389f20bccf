"""Loop closing: verified radar loop constraints for any pose-graph back end (no GTSAM here).

`LoopDetector` proposes loops with RaPlace, verifies them geometrically
(`radar_slam.loops.verification`) and, given odometry poses, accepts those that agree pairwise
(`radar_slam.loops.consistency`); it returns `LoopConstraint`s, T_query_match with covariance.
"""

from radar_slam.loops.config import (
    ConsistencyConfig,
    LoopClosureConfig,
    LoopCovarianceConfig,
    ThrottleConfig,
    VerificationConfig,
)
from radar_slam.loops.consistency import ConsistencyGate, cycle_mahalanobis
from radar_slam.loops.detector import (
    LoopDetector,
    LoopDetectorProtocol,
    NullLoopDetector,
    make_loop_detector,
)
from radar_slam.loops.records import (
    KeyScan,
    LoopClosureError,
    LoopConstraint,
    LoopDecision,
    LoopStatus,
    Verification,
    VerifiedLoop,
)
from radar_slam.loops.throttle import StretchThrottle
from radar_slam.loops.verification import (
    GeometricVerifier,
    Verifier,
    loop_covariance,
    motion_compensated,
)
from raplace import Recognizer

__all__ = [
    "ConsistencyConfig",
    "ConsistencyGate",
    "GeometricVerifier",
    "KeyScan",
    "LoopClosureConfig",
    "LoopClosureError",
    "LoopConstraint",
    "LoopCovarianceConfig",
    "LoopDecision",
    "LoopDetector",
    "LoopDetectorProtocol",
    "LoopStatus",
    "NullLoopDetector",
    "Recognizer",
    "StretchThrottle",
    "ThrottleConfig",
    "Verification",
    "VerificationConfig",
    "VerifiedLoop",
    "Verifier",
    "cycle_mahalanobis",
    "loop_covariance",
    "make_loop_detector",
    "motion_compensated",
]
