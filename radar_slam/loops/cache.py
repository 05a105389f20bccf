"""A bounded least-recently-used store of what verification makes per database scan.

Verifying a candidate needs the pose estimator's spectrum of the database scan (about 0.6 MB
with the default pose image), made from the scan's record; a scan is often a candidate of
several queries. `ByteBudgetCache` keeps the most recently inserted or used values within a byte
budget, so a long drive stays within its memory cap (the least recently used values are dropped
and made again when they are needed).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

V = TypeVar("V")

BYTES_PER_MB = 1 << 20


class ByteBudgetCache(Generic[V]):
    """Key -> value, the least recently used values dropped beyond `budget_mb`.

    Args:
        budget_mb: the most the values may take together [MiB]; 0 keeps nothing.
        size_of: the bytes a value takes.
    """

    def __init__(self, budget_mb: float, size_of: Callable[[V], int]) -> None:
        self.budget_bytes = int(budget_mb * BYTES_PER_MB)
        self.size_of = size_of
        self._values: OrderedDict[Hashable, tuple[V, int]] = OrderedDict()
        self.bytes = 0
        self.hits = 0
        self.misses = 0

    def __len__(self) -> int:
        return len(self._values)

    def get(self, key: Hashable) -> V | None:
        """The value of `key` (now the most recently used), or None."""
        item = self._values.get(key)
        if item is None:
            self.misses += 1
            return None
        self.hits += 1
        self._values.move_to_end(key)
        return item[0]

    def put(self, key: Hashable, value: V) -> None:
        """Keep `value` as the most recently used; drop the least recently used beyond budget."""
        size = self.size_of(value)
        if size > self.budget_bytes:
            return
        old = self._values.pop(key, None)
        if old is not None:
            self.bytes -= old[1]
        self._values[key] = (value, size)
        self.bytes += size
        while self.bytes > self.budget_bytes:
            _, (_, dropped) = self._values.popitem(last=False)
            self.bytes -= dropped
