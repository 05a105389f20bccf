"""RaPlace: radar image geometry and place recognition (the bottom layer of radar-slam).

Radon-transform place recognition with a mutable threshold (Jang, Jung, Kim, IROS 2023), the
polar/Cartesian warping it rests on, and the helpers every package shares. Pure
numpy/scipy/opencv; takes arrays, never paths.

Public API (what `odometry`, `radar_slam` and a user's own code import from here; the other
submodules are internal, and an import-linter contract keeps `radar_slam` off them):

- place recognition: `DescriptorExtractor`, `PlaceRecognizer` (the `Recognizer` protocol,
  `Candidate` matches), `PoseEstimator` (`RelativePose`, `PoseSpectrum`), and the Scan Context
  baseline (`ScanContextExtractor`, `ScanContextRecognizer`);
- their configuration: `RaPlaceConfig` and its sections `DescriptorConfig`, `RetrievalConfig`,
  `ExclusionConfig`;
- polar/Cartesian geometry: `CartesianGrid`, `CartesianWarper`;
- SE(2) poses `(x [m], y [m], yaw [rad])`, the one convention of the project: `compose`,
  `inverse`, `between`, `wrap_angle`, `adjoint`, `rotate_covariance`, `accumulate`,
  `relative_motions`;
- time units: `NS_PER_S`, `NS_PER_MS`, `NS_PER_US`, `US_PER_S`;
- errors: `RaPlaceError`.

Two helper modules are public as modules, because their functions read as a namespace:
`raplace.checks` (config value checks, `checks.positive(...)`) and `raplace.config_io` (the
strict dataclass config reader, `config_io.merge`, `ConfigReadError`, `to_dict`).
"""


class RaPlaceError(ValueError):
    """Bad input to a raplace function (wrong shape, empty database, ...)."""


# After RaPlaceError, which the modules import.
from raplace.config import (  # noqa: E402
    DescriptorConfig,
    ExclusionConfig,
    RaPlaceConfig,
    RetrievalConfig,
)
from raplace.descriptor import DescriptorExtractor  # noqa: E402
from raplace.pose import PoseEstimator, PoseSpectrum, RelativePose  # noqa: E402
from raplace.retrieval import Candidate, PlaceRecognizer, Recognizer  # noqa: E402
from raplace.scancontext import ScanContextExtractor, ScanContextRecognizer  # noqa: E402
from raplace.se2 import (  # noqa: E402
    accumulate,
    adjoint,
    between,
    compose,
    inverse,
    relative_motions,
    rotate_covariance,
    wrap_angle,
)
from raplace.units import NS_PER_MS, NS_PER_S, NS_PER_US, US_PER_S  # noqa: E402
from raplace.warp import CartesianGrid, CartesianWarper  # noqa: E402

__all__ = [
    "NS_PER_MS",
    "NS_PER_S",
    "NS_PER_US",
    "US_PER_S",
    "Candidate",
    "CartesianGrid",
    "CartesianWarper",
    "DescriptorConfig",
    "DescriptorExtractor",
    "ExclusionConfig",
    "PlaceRecognizer",
    "PoseEstimator",
    "PoseSpectrum",
    "RaPlaceConfig",
    "RaPlaceError",
    "Recognizer",
    "RelativePose",
    "RetrievalConfig",
    "ScanContextExtractor",
    "ScanContextRecognizer",
    "accumulate",
    "adjoint",
    "between",
    "compose",
    "inverse",
    "relative_motions",
    "rotate_covariance",
    "wrap_angle",
]
