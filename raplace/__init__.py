"""RaPlace: radar place recognition with the Radon transform and a mutable threshold.

Pure numpy/scipy/opencv; takes arrays, never paths. Jang, Jung, Kim, IROS 2023.
"""


class RaPlaceError(ValueError):
    """Bad input to a raplace function (wrong shape, empty database, ...)."""
