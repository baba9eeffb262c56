"""Model assumptions of section 2 and of the proof of Theorem 1.

* M = Mᵀ ≻ 0 and K = Kᵀ ≻ 0 (section 2; K ≻ 0 because K is the metric of the kinematic
  equation (7) and K⁻¹ appears in L_I = W_IᵀK⁻¹W_I, THEORY §2 erratum 6);
* the symmetric part C̄ = ½(C + Cᵀ) ≻ 0 (the proof of Theorem 1 needs ‖v‖²_C̄ > 0 for
  v ≠ 0 after eq. (20));
* the columns w_i of W are linearly independent (section 2; used after eq. (21)).

Definiteness is measured by the relative smallest eigenvalue ``λ_min/λ_max`` of the
symmetric part, and required to exceed ``rcond_min`` (a matrix with a smaller relative
eigenvalue is numerically singular). The independence of W is measured by its condition
number ``σ_max/σ_min`` (``inf`` when m > n).

Not applicable: a stiffness (damping) matrix that is only positive *semi*-definite (e.g. the
bouncing ball, K = C = 0) does not violate the mechanical model, but the paper's
observer with position jumps and Theorem 1 do not cover it; those checks report
``passed=None`` with the reason. An *indefinite* matrix fails.
"""

from __future__ import annotations

import numpy as np

from proofs_checks.result import CheckResult

RCOND_MIN = 1e-12
"""Smallest accepted λ_min/λ_max for a positive definite matrix."""

SYMMETRY_RTOL = 1e-10
"""Largest accepted max|A − Aᵀ| / max|A| for a matrix required to be symmetric."""

PSD_RTOL = 1e-10
"""λ_min/λ_max above −PSD_RTOL counts as positive semi-definite (round-off)."""


def _spectrum(A: np.ndarray) -> tuple[np.ndarray, float, float]:
    A = np.asarray(A, dtype=float)
    sym = 0.5 * (A + A.T)
    eig = np.linalg.eigvalsh(sym)
    scale = float(np.max(np.abs(eig))) if eig.size else 0.0
    asym = float(np.max(np.abs(A - A.T)) / max(float(np.max(np.abs(A))), 1e-300))
    return eig, scale, asym


def not_definite_reason(K: np.ndarray, consequence: str) -> str | None:
    """None if the symmetric part of K is positive definite (λ_min > 1e-12·λ_max, the rule of
    :meth:`observer.model.LinearSystem.is_stiffness_definite`), else why not, and
    ``consequence``: the one K-definiteness test of the run-based checks."""
    eig = np.linalg.eigvalsh(0.5 * (K + K.T))
    if eig[-1] <= 0 or eig[0] <= 1e-12 * abs(eig[-1]):
        return f"K is not positive definite (λ_min = {eig[0]:.3g}): {consequence}"
    return None


def _definite(name: str, label: str, A: np.ndarray, equation: str, *, symmetric: bool,
              semidefinite_ok_reason: str | None, rcond_min: float) -> CheckResult:
    A = np.asarray(A, dtype=float)
    eig, scale, asym = _spectrum(A)
    evec = np.linalg.eigh(0.5 * (A + A.T))[1][:, 0]
    rel = float(eig[0] / scale) if scale > 0 else 0.0
    witness = {"lambda_min": float(eig[0]), "lambda_max": float(eig[-1]), "relative_lambda_min": rel,
               "required": rcond_min, "eigenvector_min": evec}
    if symmetric:
        witness["asymmetry"] = asym
    keys = ("lambda_min", "lambda_max", "relative_lambda_min", "asymmetry")
    if symmetric and asym > SYMMETRY_RTOL:
        return CheckResult(name, False, -asym, SYMMETRY_RTOL, witness,
                           f"{label} is not symmetric (max|A − Aᵀ|/max|A| = {asym:.3g})", equation,
                           ("asymmetry",) + keys)
    if semidefinite_ok_reason is not None and -PSD_RTOL <= rel < rcond_min:
        return CheckResult(name, None, float("nan"), float("nan"), witness,
                           f"{label} is only positive semi-definite (λ_min = {eig[0]:.3g}): "
                           f"{semidefinite_ok_reason}", equation, keys)
    return CheckResult.from_margin(name, rel - rcond_min, 0.0, witness, equation, keys)


def check_mass_spd(M: np.ndarray, *, rcond_min: float = RCOND_MIN) -> CheckResult:
    """M = Mᵀ ≻ 0 (section 2, after eq. (1)).

    ``margin = λ_min(M)/λ_max(M) − rcond_min``; the witness holds λ_min, λ_max, the
    eigenvector of λ_min and the asymmetry.
    """
    return _definite("mass_spd", "M", M, "section 2: M = Mᵀ ≻ 0", symmetric=True,
                     semidefinite_ok_reason=None, rcond_min=rcond_min)


def check_stiffness_spd(K: np.ndarray, *, rcond_min: float = RCOND_MIN) -> CheckResult:
    """K = Kᵀ ≻ 0 (section 2; metric of the kinematic equation (7), L_I = W_IᵀK⁻¹W_I).

    ``margin = λ_min(K)/λ_max(K) − rcond_min``. A K that is only positive semi-definite
    (free rigid-body mode) is reported not applicable; an indefinite K fails.
    """
    return _definite("stiffness_spd", "K", K, "section 2: K = Kᵀ ≻ 0; eq. (7)", symmetric=True,
                     semidefinite_ok_reason="free rigid-body mode; the position jumps (K-metric), "
                     "eqs. (13)-(14) and Theorem 1 need K ≻ 0 (THEORY §2 erratum 6)",
                     rcond_min=rcond_min)


def check_damping_pd(C: np.ndarray, *, rcond_min: float = RCOND_MIN) -> CheckResult:
    """C̄ = ½(C + Cᵀ) ≻ 0 (proof of Theorem 1, eqs. (17) and (20)).

    C itself need not be symmetric. ``margin = λ_min(C̄)/λ_max(C̄) − rcond_min``. A C̄ that
    is only positive semi-definite (e.g. C = 0) keeps dV ≤ 0 but not the convergence
    argument: reported not applicable. An indefinite C̄ fails (dV can be positive).
    """
    C = np.asarray(C, dtype=float)
    if not np.any(C):
        return CheckResult("damping_pd", None, float("nan"), float("nan"),
                           {"lambda_min": 0.0, "lambda_max": 0.0},
                           "C = 0 (undamped): dV ≤ 0 holds, but Theorem 1's argument v → 0 needs "
                           "C̄ ≻ 0", "proof of Theorem 1: C̄ ≻ 0, eq. (17)")
    return _definite("damping_pd", "C̄", C, "proof of Theorem 1: C̄ ≻ 0, eq. (17)", symmetric=False,
                     semidefinite_ok_reason="dV ≤ 0 holds, but Theorem 1's argument v → 0 "
                     "(after eq. (20)) needs C̄ ≻ 0", rcond_min=rcond_min)


def check_constraints_independent(W: np.ndarray, *, cond_max: float = 1e6) -> CheckResult:
    """The columns w_i of W are linearly independent (section 2; used after eq. (21)).

    ``margin = log10(cond_max) − log10(σ_max/σ_min)`` (decades to spare); the witness holds
    the singular values, the condition number and the right singular vector of σ_min
    (the combination of columns that nearly vanishes; for m > n a unit vector c with
    W c = 0, from the full SVD).
    """
    W = np.asarray(W, dtype=float)
    n, m = W.shape
    # full V: for m > n the last row of Vt spans part of the null space of W (σ = 0)
    U, s, Vt = np.linalg.svd(W, full_matrices=True)
    smin = float(s[-1]) if m <= n else 0.0
    cond = float(s[0] / smin) if smin > 0 else float("inf")
    witness = {"n": n, "m": m, "sigma_min": smin, "sigma_max": float(s[0]), "condition_number": cond,
               "cond_max": cond_max, "null_combination": Vt[-1]}
    margin = np.log10(cond_max) - (np.log10(cond) if np.isfinite(cond) else np.inf)
    reason = "more contacts than degrees of freedom (m > n)" if m > n else ""
    return CheckResult.from_margin("constraints_independent", margin, 0.0, witness,
                                   "section 2: w_i linearly independent; eq. (21)",
                                   ("condition_number", "sigma_min", "sigma_max", "null_combination"),
                                   reason)
