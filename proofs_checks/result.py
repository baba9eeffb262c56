"""The record every proof check returns: :class:`CheckResult`.

A check that cannot fail proves nothing, so every result carries, besides ``passed``,
a signed numerical ``margin`` (how far from violation: ``margin ≥ −tolerance`` is
satisfied, a negative margin beyond the tolerance is a violation), the ``tolerance``
used, and a ``witness``: the state, matrices or inputs where the margin is worst.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

#: Values of :attr:`CheckResult.passed` and how the table prints them.
STATUS_TEXT = {True: "PASS", False: "FAIL", None: "n/a"}

#: Evidence levels of an applicable result, strongest first:
#:
#: ``"proved"``
#:     decided in exact rational arithmetic on the given float data, or by verified
#:     interval (ball) enclosures; the witness names the method.
#: ``"bounded"``
#:     floating point with a rigorous round-off bound.
#: ``"sampled"``
#:     random or adversarial search (the witness gives the number of samples); no
#:     counterexample found, nothing proved.
#: ``"violated"``
#:     a counterexample, re-checked in exact arithmetic (``passed`` is False).
#:
#: A not-applicable result (``passed is None``) has evidence :data:`NOT_APPLICABLE`.
EVIDENCE_LEVELS = ("proved", "bounded", "sampled", "violated")
NOT_APPLICABLE = "n/a"


@dataclass
class CheckResult:
    """Outcome of one numerical check of a step of the paper's proofs.

    Attributes
    ----------
    name : str
        Registry name of the check (see :data:`proofs_checks.CHECKS`).
    passed : bool or None
        ``True`` (satisfied), ``False`` (violated) or ``None`` (not applicable: the
        check's hypotheses do not hold for this system; ``reason`` says why).
    margin : float
        Signed distance from violation in the check's own (documented) units; the check
        is satisfied when ``margin >= -tolerance``. ``nan`` when not applicable.
    tolerance : float
        Tolerance used for ``passed`` (same units as ``margin``).
    witness : dict
        Where the margin is worst: state, matrices, inputs, step index, ... (plain
        Python/NumPy values); also the secondary measurements of the check.
    reason : str
        Why the check is not applicable (``passed is None``), or a note.
    equation : str
        The paper's equation or assumption the check verifies, e.g. ``"A3, eq. (6)"``.
    summary_keys : tuple of str
        Witness keys shown first by :meth:`summary`.
    scenario : str
        Scenario name (set by :func:`proofs_checks.run_checks`).
    elapsed : float
        Wall time of the check in seconds (including any shared run it triggered).
    evidence : str
        One of :data:`EVIDENCE_LEVELS` for an applicable check, ``"n/a"`` when
        ``passed is None``. Left empty by a constructor, it defaults to ``"n/a"``
        (not applicable), ``"violated"`` (failed) or ``"sampled"`` (passed): the weakest
        claim; every check states its level explicitly.
    verdict : str or None
        Optional one-line human verdict, e.g. ``"holds up to the discrete slack
        (order ≈ 1.0)"``.
    """

    name: str
    passed: bool | None
    margin: float
    tolerance: float
    witness: dict = field(default_factory=dict)
    reason: str = ""
    equation: str = ""
    summary_keys: tuple = ()
    scenario: str = ""
    elapsed: float = 0.0
    evidence: str = ""
    verdict: str | None = None

    def __post_init__(self) -> None:
        if not self.evidence:
            self.evidence = (NOT_APPLICABLE if self.passed is None
                             else "violated" if self.passed is False else "sampled")
        if self.evidence not in EVIDENCE_LEVELS + (NOT_APPLICABLE,):
            raise ValueError(f"evidence must be one of {EVIDENCE_LEVELS + (NOT_APPLICABLE,)}, "
                             f"got {self.evidence!r}")
        if (self.evidence == NOT_APPLICABLE) != (self.passed is None):
            raise ValueError(f"evidence {self.evidence!r} does not fit passed={self.passed!r}: "
                             "'n/a' exactly when the check is not applicable")
        if self.evidence == "violated" and self.passed is not False:
            raise ValueError("evidence 'violated' requires passed=False")

    # -- construction helpers ------------------------------------------------------------------
    @staticmethod
    def not_applicable(name: str, reason: str, equation: str = "", **witness: Any) -> "CheckResult":
        """A result for a check whose hypotheses do not hold (``passed=None``)."""
        return CheckResult(name, None, float("nan"), float("nan"), dict(witness), reason, equation,
                           evidence=NOT_APPLICABLE)

    @staticmethod
    def from_margin(name: str, margin: float, tolerance: float, witness: dict, equation: str,
                    summary_keys: tuple = (), reason: str = "", *, evidence: str = "",
                    verdict: str | None = None) -> "CheckResult":
        """``passed = margin >= -tolerance`` (NaN margins fail).

        ``evidence`` is the level of a pass; a failure gets ``"violated"`` unless
        ``evidence`` is given and is not ``"proved"`` (e.g. a float failure that was not
        re-checked exactly keeps ``"sampled"`` or ``"bounded"``)."""
        margin = float(margin) + 0.0          # no negative zero in tables
        passed = bool(margin >= -tolerance) if not math.isnan(margin) else False
        if not passed and evidence in ("", "proved"):
            evidence = "violated"
        return CheckResult(name, passed, margin, float(tolerance), witness, reason, equation,
                           tuple(summary_keys), evidence=evidence, verdict=verdict)

    # -- views ---------------------------------------------------------------------------------
    @property
    def status(self) -> str:
        """``"PASS"``, ``"FAIL"`` or ``"n/a"``."""
        return STATUS_TEXT[self.passed]

    def summary(self, width: int = 110) -> str:
        """One line: the witness's key values (after the reason, for a failure; only the
        reason, when not applicable)."""
        if self.passed is None:
            text = f"not applicable: {self.reason}"
        else:
            keys = list(self.summary_keys) or list(self.witness)[:4]
            parts = [f"{k}={_fmt(self.witness[k])}" for k in keys if k in self.witness]
            text = ", ".join(parts)
            if self.reason and self.passed is False:          # a failure: say why first
                text = f"{self.reason} | {text}" if text else self.reason
            elif self.reason:
                text = f"{text}; {self.reason}" if text else self.reason
        return text if len(text) <= width else text[: width - 3] + "..."

    def message(self) -> str:
        """Multi-line human-readable report (used by the assertion helpers)."""
        status = "NOT APPLICABLE" if self.passed is None else self.status
        lines = [f"{self.name} [{self.equation}] {status}" + (f" on {self.scenario}" if self.scenario else "")]
        if self.passed is not None:
            lines.append(f"  evidence  = {self.evidence}" + (f": {self.verdict}" if self.verdict else ""))
            lines.append(f"  margin    = {self.margin:.6g} (tolerance {self.tolerance:.3g}; "
                         "satisfied when margin >= -tolerance)")
        if self.reason:
            lines.append(f"  reason    = {self.reason}")
        if self.witness:
            lines.append("  witness:")
            for k, v in self.witness.items():
                lines.append(f"    {k} = {_fmt(v, long=True)}")
        return "\n".join(lines)

    def to_row(self) -> dict:
        """Flat dict for a DataFrame row: scenario, check, equation, status, evidence, passed,
        margin, tolerance, verdict, witness (one-line summary), reason, elapsed."""
        return {"scenario": self.scenario, "check": self.name, "equation": self.equation,
                "status": self.status, "evidence": self.evidence, "passed": self.passed,
                "margin": self.margin, "tolerance": self.tolerance, "verdict": self.verdict,
                "witness": self.summary(10_000), "reason": self.reason, "elapsed": self.elapsed}

    def to_dict(self) -> dict:
        """JSON-ready dict (arrays as lists, non-finite floats as strings)."""
        d = asdict(self)
        d["status"] = self.status
        d.pop("summary_keys")
        return json.loads(json.dumps(d, default=_jsonable), parse_constant=str)

    def __bool__(self) -> bool:  # pragma: no cover - guard against `assert check(...)`
        raise TypeError("use CheckResult.passed (True/False/None), not the result's truth value")


def _jsonable(x: Any) -> Any:
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    if isinstance(x, (set, frozenset, tuple)):
        return list(x)
    return str(x)


def _fmt(v: Any, long: bool = False) -> str:
    """Compact text for witness values (floats with 4 significant digits)."""
    if isinstance(v, (float, np.floating)):
        return f"{float(v):.4g}"
    if isinstance(v, (bool, np.bool_, int, np.integer, str)):
        return str(v)
    arr = np.asarray(v) if isinstance(v, (list, tuple, np.ndarray)) else None
    if arr is not None and arr.dtype.kind in "fiub":
        limit = 64 if long else 8
        flat = arr.ravel()
        body = ", ".join(f"{x:.4g}" if arr.dtype.kind == "f" else str(x) for x in flat[:limit])
        if flat.size > limit:
            body += ", ..."
        shape = "x".join(map(str, arr.shape))
        return f"[{body}]" if arr.ndim <= 1 else f"({shape})[{body}]"
    return str(v)
