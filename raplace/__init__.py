"""RaPlace: radar image geometry and place recognition (the bottom layer of radar-slam).

Radon-transform place recognition with a mutable threshold (Jang, Jung, Kim, IROS 2023), the
polar/Cartesian warping it rests on, the SE(2) and unit helpers every package shares
(`raplace.se2`, `raplace.units`) and the strict config reader (`raplace.config_io`). Pure
numpy/scipy/opencv; takes arrays, never paths.
"""


class RaPlaceError(ValueError):
    """Bad input to a raplace function (wrong shape, empty database, ...)."""


# After RaPlaceError, which the modules import.
from raplace.config import RaPlaceConfig  # noqa: E402
from raplace.descriptor import DescriptorExtractor  # noqa: E402
from raplace.pose import PoseEstimator, RelativePose  # noqa: E402
from raplace.retrieval import Candidate, PlaceRecognizer, Recognizer  # noqa: E402
from raplace.scancontext import ScanContextExtractor, ScanContextRecognizer  # noqa: E402

__all__ = [
    "Candidate",
    "DescriptorExtractor",
    "PlaceRecognizer",
    "PoseEstimator",
    "RaPlaceConfig",
    "RaPlaceError",
    "Recognizer",
    "RelativePose",
    "ScanContextExtractor",
    "ScanContextRecognizer",
]
