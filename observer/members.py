"""Moved: an ensemble's members over one recorded master are
:mod:`observer.engines.compiled.members`. This module keeps ``observer.members.NAME`` working
for code written against the old layout; it defines nothing.
"""

from __future__ import annotations

import observer.engines.compiled.members as _members


def __getattr__(name: str):
    """``NAME`` from :mod:`observer.engines.compiled.members`."""
    if name in vars(_members):
        return vars(_members)[name]
    raise AttributeError(f"module 'observer.members' has no attribute {name!r}")
