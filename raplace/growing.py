"""`GrowingArray`: the append-only storage of place databases (one contiguous array)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from raplace import RaPlaceError

INITIAL_CAPACITY = 64
"""Rows allocated by an empty GrowingArray; capacity doubles when full."""


class GrowingArray:
    """Append-only array of fixed-shape items with amortised O(1) appends."""

    def __init__(self, item_shape: tuple[int, ...], dtype: np.dtype | type) -> None:
        self._data = np.empty((INITIAL_CAPACITY, *item_shape), dtype=dtype)
        self._count = 0

    def __len__(self) -> int:
        return self._count

    @property
    def item_shape(self) -> tuple[int, ...]:
        return tuple(self._data.shape[1:])

    @property
    def values(self) -> NDArray:
        """(len, *item_shape) view of the stored items (invalidated by the next append)."""
        return self._data[: self._count]

    def extend(self, items: NDArray) -> None:
        """Append (n, *item_shape) items."""
        items = np.asarray(items)
        if items.shape[1:] != self.item_shape:
            raise RaPlaceError(f"item shape {items.shape[1:]} != {self.item_shape}")
        needed = self._count + len(items)
        if needed > len(self._data):
            capacity = max(needed, 2 * len(self._data))
            grown = np.empty((capacity, *self.item_shape), dtype=self._data.dtype)
            grown[: self._count] = self._data[: self._count]
            self._data = grown
        self._data[self._count : needed] = items
        self._count = needed

    def append(self, item: NDArray | float | int) -> None:
        """Append one item of shape item_shape."""
        self.extend(np.asarray(item)[None])
