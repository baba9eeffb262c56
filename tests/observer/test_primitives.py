"""Siconos' predictor and the position projection have one compiled definition each
(:mod:`observer.primitives`): no other module of ``observer`` writes them out again."""

from __future__ import annotations

import re
from pathlib import Path

import observer.engines.compiled.kernel as kernel
import observer.engines.compiled.members as members
from observer import primitives

ROOT = Path(__file__).resolve().parents[2] / "observer"
PREDICTOR = re.compile(r"\+ 0\.5 \* h \* \w+")
"""The predictor's ``x + 0.5 * h * v`` in compiled code (the numpy reference writes ``S.h``)."""
PROJECTION = re.compile(r"q1\[\w+\] \+= \w+\[.+\] \* s")
"""The projection's update ``q1 += (N⁻¹W_j) Σ_j`` of one closed contact."""


def _code_lines(path: Path) -> list[str]:
    return [line.split("#")[0] for line in path.read_text(encoding="utf-8").splitlines()]


def test_the_patterns_catch_the_hand_written_forms():
    """The forms the kernel and the members' loop wrote by hand before (issue 32)."""
    assert PREDICTOR.search("g += Wv[p] * (qs[s, Wi[p]] + 0.5 * h * us[s, Wi[p]])")
    assert PREDICTOR.search("if g + NU[k, j] + 0.5 * h * NUD[k, j] <= 0.0:")
    assert PROJECTION.search("            q1[i] += KinvWT[slot, j, i] * s_")
    assert PROJECTION.search("                            q1[i] += KinvWT[slots[s], j, i] * s1")
    assert not PREDICTOR.search("g_pred = S.WT @ (q + 0.5 * S.h * u)")


def test_the_predictor_is_written_once():
    where = [(p.relative_to(ROOT).as_posix(), i) for p in sorted(ROOT.rglob("*.py"))
             for i, line in enumerate(_code_lines(p), 1) if PREDICTOR.search(line)]
    assert {p for p, _ in where} == {"primitives.py"}, where
    assert len(where) == 2                  # predicted_term and predicted_closed


def test_the_loops_call_the_shared_predictor_and_projection():
    for loop in (kernel._advance_loop, members.advance_members):     # generated (observer.engines.compiled.step)
        names = loop.py_func.__globals__
        assert names["predicted_closed"] is primitives.predicted_closed
        assert names["predicted_term"] is primitives.predicted_term
        assert names["project_positions"] is primitives.project_positions
    where = [(p.relative_to(ROOT).as_posix(), i) for p in sorted(ROOT.rglob("*.py"))
             for i, line in enumerate(_code_lines(p), 1) if PROJECTION.search(line)]
    assert {p for p, _ in where} == {"primitives.py"}, where
