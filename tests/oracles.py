"""Where the external oracle data lives, and what a missing oracle means.

The oracles are read-only data beside the project (``../shared/oracles`` from the project
root, the layout of every developer checkout and of CI's fresh clone); the environment
variable ``OBSERVER_ORACLES`` points elsewhere. A missing oracle **fails** when the
environment variable ``CI`` is set (a CI run that silently skipped its oracles would be
green for the wrong reason) and skips otherwise (a user's clone without ``shared/``).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

PROJECT_ROOT = Path(__file__).resolve().parents[1]
ORACLES = Path(os.environ.get("OBSERVER_ORACLES", PROJECT_ROOT.parent / "shared" / "oracles"))
SICONOS = ORACLES / "siconos"


def oracle(*parts: str) -> Path:
    """Path of an oracle file or folder below :data:`ORACLES`; fail (CI) or skip if absent."""
    path = ORACLES.joinpath(*parts)
    if not path.exists():
        message = f"oracle data not found: {path} (set OBSERVER_ORACLES or clone shared/ beside the project)"
        if os.environ.get("CI"):
            pytest.fail(message, pytrace=False)
        pytest.skip(message)
    return path
