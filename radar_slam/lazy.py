"""Modules loaded on first use: a package's names (PEP 562), so that importing it stays light,
and modules loaded ahead on a thread (`preload`)."""

from __future__ import annotations

import importlib
import threading
from collections.abc import Callable, Iterable, Mapping


def lazy_exports(
    package: str, exports: Mapping[str, str]
) -> tuple[Callable[[str], object], Callable[[], list[str]]]:
    """The `__getattr__` and `__dir__` of `package` whose names `exports` maps to the modules
    that define them (each imported on first use)."""
    namespace = importlib.import_module(package).__dict__

    def __getattr__(name: str) -> object:
        module = exports.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(importlib.import_module(module), name)

    def __dir__() -> list[str]:
        return sorted({*namespace, *exports})

    return __getattr__, __dir__


def preload(modules: Iterable[str]) -> threading.Thread:
    """Import `modules` on a thread started here; returns it.

    For modules a caller needs only later (at the end of a run): the imports go on while the
    caller works in code that releases the GIL, so that on two cores they cost it no time. Join
    the thread before the caller's own first import of any of them (two threads importing the
    same modules at once could each wait for the other's). An import that fails here is left to
    fail again, with its message, where the module is used.
    """
    names = tuple(modules)

    def load() -> None:
        for name in names:
            try:
                importlib.import_module(name)
            except Exception:  # raised again by the caller's own import
                return

    thread = threading.Thread(target=load, name="preload")
    thread.start()
    return thread
