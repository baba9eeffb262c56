"""Issue 34, item 1 (acceptance): no tolerance in ``observer/event/`` is built on the motion's
time scale τ = 1/ω_max, on a guessed length scale, or on a count of round-offs.

The code of every module (comments and strings dropped: a docstring may tell the history)
is scanned for the names such tolerances were built from — τ and what it feeds
(``time_scale``, ``run.tau``, ``resolution(t, τ)``, ``time_ulp``, the motion scale and
tolerance, the touch band, the Zeno noise limit) and the round-off counts (``ROUNDOFF``,
``CONTACT_TOL``, ``FLOOR_FACTOR``, …) — and for a literal count of machine epsilons
(``1e3 * np.finfo(float).eps``). What may stay: the certified error bounds of a float64
evaluation (γ_n = n·u/(1 − n·u), a factor ``1 + k·u`` that dominates the rounding of a
bound, Higham §3.1) and the time coordinate's own resolution (``time_resolution``: two ulp
of t, no time scale).
"""

from __future__ import annotations

import io
import re
import tokenize
from pathlib import Path


import observer.event

EVENT = Path(observer.event.__file__).parent

FORBIDDEN = {
    "the time scale τ": r"\btime_scale\b|\bmotion_time_scale\b|\b(?:self|run|fs)\.tau\b"
                        r"|\btau\s*=\s*(?:run|self)\.tau\b",
    "a time resolution on τ": r"(?<![\w.])resolution\(|\btime_ulp\b",
    "a motion or length scale": r"\bmotion_scale\b|\bmotion_tolerance\b|\btouch_band\b"
                                r"|\btail_noise_limit\b|\btail_noise\b|\bTAIL_SPAN\b",
    "a count of round-offs": r"\bROUNDOFF\b|\bCONTACT_TOL\b|\bTOUCH_FACTOR\b|\bFLOOR_FACTOR\b"
                             r"|\bZENO_HOP_ROUNDOFF\b|\bZENO_TAIL_RTOL\b|\bMERGE_HOPS\b"
                             r"|\bCLUSTER_NOISE\b|\bCANCELLED\b|\btolerance\(",
}
EPS_COUNT = re.compile(r"([0-9][0-9.]*(?:e[+-]?[0-9]+)?)\s*\*\s*(?:np\.)?finfo\(float\)\.eps")
"""A literal k·eps; k ≤ 4 is a rounding factor of a certified bound, more is a count."""


def code_lines(path: Path) -> list[tuple[int, str]]:
    """The lines of ``path`` with comments and string literals blanked (tokenize)."""
    src = path.read_text()
    lines = src.splitlines()
    keep = [list(line) for line in lines]
    for tok in tokenize.generate_tokens(io.StringIO(src).readline):
        if tok.type in (tokenize.COMMENT, tokenize.STRING):
            (r0, c0), (r1, c1) = tok.start, tok.end
            for r in range(r0, r1 + 1):
                row = keep[r - 1]
                a = c0 if r == r0 else 0
                b = c1 if r == r1 else len(row)
                row[a:b] = " " * (b - a)
    return [(i + 1, "".join(row)) for i, row in enumerate(keep)]


def scale_tolerances(root: Path = EVENT) -> list[str]:
    """Every use of a forbidden name, and every literal count of round-offs, in root/*.py."""
    found = []
    for path in sorted(root.glob("*.py")):
        for no, line in code_lines(path):
            for what, pattern in FORBIDDEN.items():
                for m in re.finditer(pattern, line):
                    found.append(f"{path.name}:{no}: {what}: {m.group(0).strip()}")
            for m in EPS_COUNT.finditer(line):
                if float(m.group(1)) > 4.0:
                    found.append(f"{path.name}:{no}: a count of round-offs: {m.group(0)}")
    return found


def test_the_scan_finds_each_kind_of_tolerance_in_a_known_bad_module(tmp_path):
    """The scanner itself: it finds a τ-, motion-scale- and round-off-count-based tolerance
    in code, and nothing in a comment or docstring that names them."""
    (tmp_path / "bad.py").write_text(
        '"""ROUNDOFF and run.tau in a docstring are history."""\n'
        "import numpy as np\n"
        "band = CONTACT_TOL * motion_tolerance(r, A, z, run.tau, t)  # ROUNDOFF\n"
        "small = 1e3 * np.finfo(float).eps * v\n"
        "inflate = 1.0 + 4.0 * np.finfo(float).eps\n")
    found = scale_tolerances(tmp_path)
    kinds = {f.split(": ")[1] for f in found}
    assert kinds == {"the time scale τ", "a motion or length scale", "a count of round-offs"}
    assert all(f.startswith("bad.py:3:") or f.startswith("bad.py:4:") for f in found)
    assert any("1e3 * np.finfo(float).eps" in f for f in found)


def test_no_time_scale_length_scale_or_roundoff_count_tolerance_is_left():
    """Issue 34's grep: no use of τ, of a motion or length scale or of a count of round-offs
    is left in ``observer/event/`` (the simultaneity and velocity bands take the carried
    error up to the run's stated accuracy, :meth:`observer.event.master._Run.accuracy_caps`;
    a joint tail of several contacts is due at the simultaneity band,
    :meth:`observer.event.master._Run.merge_band`)."""
    found = scale_tolerances()
    assert not found, "\n".join(found)
