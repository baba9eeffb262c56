"""The position jump's metric: which observer designs keep the jump part of ΔV ≤ 0.

For two observers of one design driven by the same χ, the position jumps of a step change
V = ½‖v‖²_M + ½‖e‖²_K by the jump part ``J = ½‖e⁺‖²_K − ½‖e⁻‖²_K`` (e⁻ the error before
the step's projections, e⁺ after). Both observers are projected onto the same constraint
set ``{W_Iᵀq + ν_I = 0}``:

* in the K metric (paper eqs. (13)-(14)) the projection is K-orthogonal, so
  ``J = −½‖Δg⁻‖²_{L_I⁻¹} ≤ 0`` exactly (Δg⁻ the pre-projection gap difference): the
  energy-consistent choice the paper argues for;
* in any other metric N (mass, identity, …) the projection is oblique in the K norm and J
  has no sign: the position jump can raise V.

:func:`check_projection_energy` measures max J over a run for every registered design
with position jumps (:data:`observer.observers.OBSERVER_DESIGNS`) and passes when the
paper's design (metric K) has no positive jump part beyond round-off
(:func:`proofs_checks.lyapunov.roundoff_allowance`); the other designs' values are in the
witness (``designs``: name → largest J/V, positive where the jump raised V).
"""

from __future__ import annotations

import numpy as np

from observer.observers import OBSERVER_DESIGNS, ObserverDesign
from proofs_checks.assumptions import not_definite_reason
from proofs_checks.lyapunov import roundoff_allowance
from proofs_checks.result import CheckResult
from proofs_checks.runs import Run, SlaveSpec, lyapunov_pair, replay

EQUATION = "eqs. (13)-(14), (17): position-jump part of dV"


def jump_parts(run: Run, a: str, b: str) -> tuple[np.ndarray, np.ndarray]:
    """Per step (shape (N,)): the jump part J of ΔV between observers ``a`` and ``b`` and its
    round-off allowance, both in energy units."""
    A, B = run.slaves[a], run.slaves[b]
    K = run.system.K
    e, e_pre = A.q[1:] - B.q[1:], A.q_pre[1:] - B.q_pre[1:]
    J = 0.5 * (np.einsum("ki,ij,kj->k", e, K, e) - np.einsum("ki,ij,kj->k", e_pre, K, e_pre))
    return J, roundoff_allowance(run, A, B)


def design_pair_run(scenario, design: ObserverDesign, specs: list[SlaveSpec], h: float,
                    t_end: float, engine: str | None = None) -> Run:
    """Two observers of ``design`` (the states of ``specs``) coupled to the master over the run."""
    N = design.metric_matrix(scenario.system)
    pair = [SlaveSpec(f"{design.name}_{x}", True, s.q0, s.u0, N) for x, s in zip("ab", specs)]
    return replay(scenario, h=h, t_end=t_end, slaves=pair,
                  master_projection=scenario.master_projection, engine=engine)


def check_projection_energy(scenario, specs: list[SlaveSpec], *, h: float, t_end: float,
                            designs: dict[str, ObserverDesign] | None = None,
                            tolerance: float = 0.0, engine: str | None = None) -> CheckResult:
    """Position jumps in the K metric never raise V (eqs. (13)-(14) in eq. (17)); measure the
    other metrics.

    Parameters
    ----------
    scenario : Scenario
    specs : list of SlaveSpec
        Two initial observer states (the first two are used).
    h, t_end : float
    designs : dict, optional
        Designs to measure (default: the registry); those without position jumps are skipped.
    tolerance : float
        On the margin ``−max_k (J_k − allowance_k)/V_k`` of the K-metric designs.
    engine : str, optional
        The engine of the runs (:func:`proofs_checks.runs.replay`).

    Returns
    -------
    CheckResult
        ``witness["designs"]``: per design the largest ``J_k/V_k`` (positive: a jump raised V)
        and ``witness["metrics"]`` its metric; not applicable without a K-metric design to
        judge (no such design registered, or K not positive definite).
    """
    designs = OBSERVER_DESIGNS if designs is None else designs
    why = not_definite_reason(scenario.system.K, "½‖e‖²_K is no norm and there is no K-metric projection")
    if why:
        return CheckResult("projection_energy", None, float("nan"), tolerance, {}, why, EQUATION)
    measured, metrics, margin, worst = {}, {}, np.inf, {}
    for name, d in designs.items():
        if not d.position_jumps:
            continue
        run = design_pair_run(scenario, d, specs[:2], h, t_end, engine)
        a, b = f"{name}_a", f"{name}_b"
        J, allow = jump_parts(run, a, b)
        V = np.maximum(lyapunov_pair(run.system, run.slaves[a], run.slaves[b])[:-1], np.finfo(float).tiny)
        rel = J / V
        k = int(np.argmax(rel))
        measured[name], metrics[name] = float(rel[k]), d.metric
        if d.metric == "K":
            excess = (J - allow) / V
            kk = int(np.argmax(excess))
            if -excess[kk] < margin:
                margin = float(-excess[kk])
                worst = {"design": name, "step": kk, "t": float(run.t[kk]), "J": float(J[kk]),
                         "allowance": float(allow[kk]), "V": float(V[kk])}
    witness = {"designs": measured, "metrics": metrics, **worst}
    if not np.isfinite(margin):
        return CheckResult("projection_energy", None, float("nan"), tolerance, witness,
                           "no registered design projects in the K metric", EQUATION, ("designs",))
    passed = bool(margin >= -tolerance)
    reason = "" if passed else (f"a K-metric position jump raised V by {-margin:.3g}·V beyond "
                                f"round-off at step {worst['step']}")
    return CheckResult("projection_energy", passed, margin, tolerance, witness, reason, EQUATION,
                       ("designs",), evidence="sampled")
