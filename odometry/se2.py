"""Compatibility alias: the SE(2) helpers live in `raplace.se2` (the bottom layer)."""

from raplace.se2 import (
    accumulate,
    adjoint,
    between,
    compose,
    from_matrix,
    inverse,
    relative_motions,
    rotate_covariance,
    to_matrix,
    transform_points,
    wrap_angle,
)

__all__ = [
    "accumulate",
    "adjoint",
    "between",
    "compose",
    "from_matrix",
    "inverse",
    "relative_motions",
    "rotate_covariance",
    "to_matrix",
    "transform_points",
    "wrap_angle",
]
