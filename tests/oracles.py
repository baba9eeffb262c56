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


def siconos_generated(name: str, t_end: float | None = None, label: str | None = None):
    """A generated Siconos oracle (``siconos/generated/NAME.json``: its exact input) as a
    Scenario named ``label`` (default NAME; horizon ``t_end``, default the oracle's own T), with
    the oracle's trajectory."""
    import json

    import pandas as pd

    from observer.scenario import Scenario

    spec = json.loads(oracle("siconos", "generated", f"{name}.json").read_text())
    ref = pd.read_csv(oracle("siconos", "generated", f"{name}.csv"))
    f = spec["forcing"]
    doc = {"system": {"M": spec["M"], "C": spec["C"], "K": spec["K"], "W": spec["W"],
                      "forcing": {"constant": f["constant"], "amplitude": f["amplitude"],
                                  "omega": f["omega"], "phase": f["phase"]},
                      "gap": {"offset": spec["gap_offset"]}},
           "impact": {"law": "newton", "restitution": spec["restitution"]},
           "initial": {"q": spec["q0"], "u": spec["u0"]},
           "simulation": {"h": spec["h"], "t_end": spec["T"] if t_end is None else t_end,
                          "theta": spec["theta"]}}
    return Scenario.from_dict(doc, label or name), ref
