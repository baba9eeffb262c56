"""Moved: the compiled kernel is :mod:`observer.engines.compiled.kernel` (its step loops),
:mod:`observer.engines.compiled.bundles` (its arguments) and :mod:`observer.primitives`
(what it shares with the numpy engine). This module keeps ``observer.kernel.NAME`` working
for code written against the old layout; it defines nothing.
"""

from __future__ import annotations

import observer.engines.compiled.bundles as _bundles
import observer.engines.compiled.kernel as _kernel
import observer.primitives as _primitives

_HOMES = (_kernel, _bundles, _primitives)


def __getattr__(name: str):
    """``NAME`` from the first of its new homes that defines it."""
    for home in _HOMES:
        if name in vars(home):
            return vars(home)[name]
    raise AttributeError(f"module 'observer.kernel' has no attribute {name!r}")
