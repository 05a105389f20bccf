"""Loop closing (being split into a package)."""

from radar_slam.loops.detector import *  # noqa: F403
from radar_slam.loops.detector import (  # noqa: F401
    KeyScan,
    LoopCloser,
    LoopDecision,
    Recognizer,
    Verification,
    Verifier,
    cycle_mahalanobis,
    is_true_loop,
    loop_covariance,
    make_loop_detector,
    motion_compensated,
)
