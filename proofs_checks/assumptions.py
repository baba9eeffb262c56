"""Model assumptions of section 2 and of the proof of Theorem 1.

* M = Mᵀ ≻ 0 and K = Kᵀ ≻ 0 (section 2; K ≻ 0 because K is the metric of the kinematic
  equation (7) and K⁻¹ appears in L_I = W_IᵀK⁻¹W_I, docs/theory/index.md §2 erratum 6);
* the symmetric part C̄ = ½(C + Cᵀ) ≻ 0 (the proof of Theorem 1 needs ‖v‖²_C̄ > 0 for
  v ≠ 0 after eq. (20));
* the columns w_i of W are linearly independent (section 2; used after eq. (21)).

Symmetry of M and K is decided exactly: an entry with ``A[i, j] ≠ A[j, i]`` (one ulp is
enough) is a counterexample to ``A = Aᵀ``, reported ``violated`` with the entry and both
values as witness (the statement is about A, which the equations use, not its symmetric
part). Definiteness is *decided* in exact rational arithmetic on the given float matrix (every
float is a dyadic rational): an exact LDLᵀ of the symmetric part over Q
(:func:`proofs_checks.exact.classify_float`; verified ball arithmetic beyond
:data:`proofs_checks.exact.EXACT_MAX_N` rows). Its certificate (positive pivots, or a
vector x with xᵀAx ≤ 0 re-checked exactly) is the witness, and the result's evidence is
``proved`` (definite) or ``violated`` (exact counterexample). The margin is the float
relative smallest eigenvalue ``λ_min/λ_max`` of the symmetric part minus ``rcond_min``; when
round-off gives it the wrong sign it is replaced by the exact certificate's relative value
(smallest pivot / largest diagonal entry, or xᵀAx/(‖x‖²·max|a_ii|)), so its sign is exact.
``rcond_min`` (default 0) is an optional *conditioning* requirement on top of the exact
decision, judged on the float eigenvalues (evidence ``bounded``). The independence of W is
decided by its exact rank over Q; its condition number ``σ_max/σ_min`` (``inf`` when
m > n) is compared with ``cond_max`` on top.

The checks that need K ≻ 0 gate on the same exact decision (:func:`not_definite_reason`),
so no check calls singular a K that ``stiffness_spd`` proves definite; a run-based check on a
K ≻ 0 too ill-conditioned for the toolkit's float64 projection says exactly that.

Not applicable: a stiffness (damping) matrix that is only positive *semi*-definite (e.g. the
bouncing ball, K = C = 0) does not violate the mechanical model, but the paper's
observer with position jumps and Theorem 1 do not cover it; those checks report
``passed=None`` with the reason. An *indefinite* matrix fails.
"""

from __future__ import annotations

import numpy as np

from proofs_checks import exact
from proofs_checks.result import CheckResult

RCOND_MIN = 0.0
"""Default smallest accepted λ_min/λ_max on top of the exact decision (none)."""

SYMMETRY_RTOL = 0.0
"""Accepted max|A − Aᵀ| / max|A| for M and K: none, symmetry is decided exactly
(:func:`asymmetric_entry`), as the loader requires (:data:`observer.validation.SYMMETRY_RTOL`)."""


def _spectrum(A: np.ndarray) -> tuple[np.ndarray, float, float]:
    A = np.asarray(A, dtype=float)
    sym = 0.5 * (A + A.T)
    eig = np.linalg.eigvalsh(sym)
    scale = float(np.max(np.abs(eig))) if eig.size else 0.0
    asym = float(np.max(np.abs(A - A.T)) / max(float(np.max(np.abs(A))), 1e-300))
    return eig, scale, asym


RUN_RCOND_MIN = 1e-12
"""The toolkit's float64 rule for running the K-metric projection (λ_min > 1e-12·λ_max of K,
:meth:`observer.model.LinearSystem.is_stiffness_definite`): an exactly definite K below it is
still K ≻ 0, but the run-based checks cannot run an observer with position jumps on it."""

_CLASS_CACHE: dict[bytes, exact.Definiteness] = {}


def exact_class(A: np.ndarray) -> exact.Definiteness:
    """The exact inertia class of the symmetric part of ``A``
    (:func:`proofs_checks.exact.classify_float`), computed once per matrix: the one decision
    every check that needs ``A ≻ 0`` gates on (one run, one answer)."""
    A = np.ascontiguousarray(np.asarray(A, dtype=float))
    key = A.shape[0].to_bytes(4, "little") + A.tobytes()
    cert = _CLASS_CACHE.get(key)
    if cert is None:
        if len(_CLASS_CACHE) > 64:
            _CLASS_CACHE.clear()
        cert = _CLASS_CACHE[key] = exact.classify_float(A)
    return cert


def not_definite_reason(K: np.ndarray, consequence: str, *, run: bool = True) -> str | None:
    """None if K ≻ 0 is *proved* (:func:`exact_class`) and, with ``run``, the toolkit can run
    the K-metric projection on it (:data:`RUN_RCOND_MIN`); else why not, ending with
    ``consequence``. The one K test of every check that needs K ≻ 0: a K that ``stiffness_spd``
    proves definite is never called singular here."""
    cert = exact_class(K)
    if cert.status == "semidefinite":
        return f"K is singular (exact: Kx = 0, x in stiffness_spd's witness): {consequence}"
    if cert.status == "indefinite":
        return f"K is indefinite (exact: xᵀKx < 0, x in stiffness_spd's witness): {consequence}"
    if run:
        eig = np.linalg.eigvalsh(0.5 * (K + K.T))
        if not eig[0] > RUN_RCOND_MIN * abs(eig[-1]):
            return (f"K ≻ 0 holds (exact), but float64 gives λ_min/λ_max = {eig[0] / abs(eig[-1]):.3g}, "
                    f"below the toolkit's {RUN_RCOND_MIN:g} for the K-metric projection "
                    "(LinearSystem.is_stiffness_definite): no observer with position jumps is run, so this "
                    "run-based check has nothing to examine")
    return None


def jumps_runnable(K: np.ndarray) -> bool:
    """True when the run-based checks can run observers with position jumps
    (:func:`not_definite_reason` is None)."""
    return not_definite_reason(K, "") is None


def asymmetric_entry(A: np.ndarray) -> tuple[int, int] | None:
    """The first entry (i, j), row-major, with ``A[i, j] != A[j, i]`` (exact float comparison:
    symmetry is decided exactly), or None when ``A = Aᵀ`` exactly."""
    bad = np.argwhere(A != A.T)
    return (int(bad[0][0]), int(bad[0][1])) if bad.size else None


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
    bad = asymmetric_entry(A) if symmetric else None
    if bad is not None:
        i, j = bad
        a, b = float(A[i, j]), float(A[j, i])
        witness.update(entry=[i, j], entry_value=repr(a), transposed_value=repr(b))
        margin = -asym if asym > 0 else -float(np.finfo(float).tiny)
        return CheckResult(name, False, margin, SYMMETRY_RTOL, witness,
                           f"{label} is not symmetric: {label}[{i}, {j}] = {a!r} but {label}[{j}, {i}] = {b!r} "
                           f"(max|A − Aᵀ|/max|A| = {asym:.3g})", equation,
                           ("entry", "entry_value", "transposed_value", "asymmetry") + keys, evidence="violated",
                           verdict=f"{label} ≠ {label}ᵀ (exact): entry [{i}, {j}]")
    cert = exact_class(A)
    diag = float(np.max(np.abs(np.diag(A)))) if A.size else 0.0
    witness.update(exact_class=cert.status, method=cert.method)
    if cert.pivots:
        witness["min_pivot"] = exact.to_float(min(cert.pivots))
    if cert.vector is not None:
        witness["exact_vector"] = np.array([exact.to_float(v) for v in cert.vector])
        witness["exact_vector_rational"] = [str(v) for v in cert.vector]
        witness["exact_xAx"] = exact.to_float(cert.value)
    if cert.status == "definite":
        margin = rel - rcond_min
        note = ""
        if rcond_min <= 0.0 and not margin > 0:      # float round-off has the wrong sign
            pmin = witness.get("min_pivot", 0.0)
            margin = pmin / diag if diag > 0 and pmin > 0 else float(np.finfo(float).tiny)
            note = (f"float eigvalsh gives λ_min = {eig[0]:.3g} ≤ 0: round-off, the exact LDLᵀ proves "
                    f"{label} ≻ 0")
        if margin >= 0:
            return CheckResult(name, True, margin, 0.0, witness, note, equation, keys, evidence="proved",
                               verdict=f"{label} ≻ 0 (" + ("exact" if "exact" in cert.method else "ball arithmetic") + ")")
        # exactly definite, but worse conditioned than the requested rcond_min
        text = (f"{label} is positive definite (exact) but λ_min/λ_max = {rel:.3g} < rcond_min = "
                f"{rcond_min:.3g}")
        if semidefinite_ok_reason is not None:
            return CheckResult(name, None, float("nan"), float("nan"), witness,
                               f"{text}: numerically only semi-definite: {semidefinite_ok_reason}",
                               equation, keys)
        return CheckResult(name, False, margin, 0.0, witness, text, equation, keys, evidence="bounded",
                           verdict="ill-conditioned relative to rcond_min (float eigenvalues)")
    xnorm2 = sum(float(exact.to_float(v)) ** 2 for v in cert.vector)
    rq = exact.to_float(cert.value) / (xnorm2 * diag) if diag > 0 and xnorm2 > 0 else 0.0
    if cert.status == "semidefinite" and semidefinite_ok_reason is not None:
        return CheckResult(name, None, float("nan"), float("nan"), witness,
                           f"{label} is only positive semi-definite (λ_min = {eig[0]:.3g}; exactly singular, "
                           f"x with {label}x = 0 in the witness): {semidefinite_ok_reason}", equation, keys)
    margin = min(rel - rcond_min, rq) if cert.status == "indefinite" else min(rel - rcond_min, 0.0)
    if not margin < 0:
        margin = rq if rq < 0 else -float(np.finfo(float).tiny)
    what = "indefinite: xᵀAx < 0" if cert.status == "indefinite" else "singular: Ax = 0"
    return CheckResult(name, False, margin, 0.0, witness,
                       f"{label} is not positive definite ({what} for the exact vector x in the witness)",
                       equation, keys, evidence="violated", verdict=f"{label} {cert.status} (exact)")


def check_mass_spd(M: np.ndarray, *, rcond_min: float = RCOND_MIN) -> CheckResult:
    """M = Mᵀ ≻ 0 (section 2, after eq. (1)).

    Decided exactly (module docstring). ``margin = λ_min(M)/λ_max(M) − rcond_min`` (its sign made exact); the witness holds λ_min,
    λ_max, the eigenvector of λ_min, the asymmetry and the exact certificate: its class,
    method, smallest LDLᵀ pivot or the vector x with xᵀMx ≤ 0.
    """
    return _definite("mass_spd", "M", M, "section 2: M = Mᵀ ≻ 0", symmetric=True,
                     semidefinite_ok_reason=None, rcond_min=rcond_min)


def check_stiffness_spd(K: np.ndarray, *, rcond_min: float = RCOND_MIN) -> CheckResult:
    """K = Kᵀ ≻ 0 (section 2; metric of the kinematic equation (7), L_I = W_IᵀK⁻¹W_I).

    Decided exactly; ``margin = λ_min(K)/λ_max(K) − rcond_min`` (sign exact). A K that is
    exactly positive semi-definite and singular (free rigid-body mode) is reported not
    applicable; an indefinite K fails with an exact vector x, xᵀKx < 0.
    """
    return _definite("stiffness_spd", "K", K, "section 2: K = Kᵀ ≻ 0; eq. (7)", symmetric=True,
                     semidefinite_ok_reason="free rigid-body mode; the position jumps (K-metric), "
                     "eqs. (13)-(14) and Theorem 1 need K ≻ 0 (docs/theory/index.md §2 erratum 6)",
                     rcond_min=rcond_min)


def check_damping_pd(C: np.ndarray, *, rcond_min: float = RCOND_MIN) -> CheckResult:
    """C̄ = ½(C + Cᵀ) ≻ 0 (proof of Theorem 1, eqs. (17) and (20)).

    C itself need not be symmetric. Decided exactly on C̄ (computed exactly);
    ``margin = λ_min(C̄)/λ_max(C̄) − rcond_min`` (sign exact). A C̄ that is exactly only
    positive semi-definite (e.g. C = 0) keeps dV ≤ 0 but not the convergence argument:
    reported not applicable. An indefinite C̄ fails (dV can be positive).
    """
    C = np.asarray(C, dtype=float)
    if not np.any(C):
        return CheckResult("damping_pd", None, float("nan"), float("nan"),
                           {"lambda_min": 0.0, "lambda_max": 0.0},
                           "C = 0 (undamped): dV ≤ 0 holds, but Theorem 1's argument v → 0 needs "
                           "C̄ ≻ 0", "proof of Theorem 1: C̄ ≻ 0, eq. (17)", evidence="n/a")
    return _definite("damping_pd", "C̄", C, "proof of Theorem 1: C̄ ≻ 0, eq. (17)", symmetric=False,
                     semidefinite_ok_reason="dV ≤ 0 holds, but Theorem 1's argument v → 0 "
                     "(after eq. (20)) needs C̄ ≻ 0", rcond_min=rcond_min)


def check_constraints_independent(W: np.ndarray, *, cond_max: float = 1e6) -> CheckResult:
    """The columns w_i of W are linearly independent (section 2; used after eq. (21)).

    Decided by the exact rank of W over Q (``fmpq_mat.rref``): rank m is ``proved``; a
    smaller rank is ``violated`` with an exact combination c ≠ 0, W c = 0
    (``exact_null_combination``). On top, the float condition number ``σ_max/σ_min`` must not
    exceed ``cond_max`` (numerical independence; a failure of that alone has evidence
    ``bounded``: LAPACK's singular values carry a backward-error bound of order n·eps·σ_max).

    ``margin = log10(cond_max) − log10(σ_max/σ_min)`` (decades to spare; −inf for an exact
    dependence); the witness holds the singular values, the condition number and the right
    singular vector of σ_min (for m > n a unit vector c with W c = 0, from the full SVD).
    """
    W = np.asarray(W, dtype=float)
    n, m = W.shape
    # full V: for m > n the last row of Vt spans part of the null space of W (σ = 0)
    U, s, Vt = np.linalg.svd(W, full_matrices=True)
    smin = float(s[-1]) if m <= n else 0.0
    cond = float(s[0] / smin) if smin > 0 else float("inf")
    rank = exact.rank(W)
    witness = {"n": n, "m": m, "sigma_min": smin, "sigma_max": float(s[0]), "condition_number": cond,
               "cond_max": cond_max, "null_combination": Vt[-1], "exact_rank": rank,
               "method": "rank over Q (fmpq_mat.rref)"}
    margin = np.log10(cond_max) - (np.log10(cond) if np.isfinite(cond) else np.inf)
    reason = "more contacts than degrees of freedom (m > n)" if m > n else ""
    eq = "section 2: w_i linearly independent; eq. (21)"
    keys = ("exact_rank", "condition_number", "sigma_min", "sigma_max", "null_combination")
    if rank < m:
        c = exact.null_vector(W)
        witness["exact_null_combination"] = np.array([exact.to_float(v) for v in c])
        return CheckResult("constraints_independent", False, -np.inf, 0.0, witness,
                           reason or "the columns of W are exactly dependent", eq, keys,
                           evidence="violated", verdict=f"rank W = {rank} < m = {m} (exact)")
    res = CheckResult.from_margin("constraints_independent", margin, 0.0, witness, eq, keys, reason,
                                  evidence="proved", verdict=f"rank W = m = {m} (exact)")
    if res.passed is False:
        res.evidence = "bounded"
        res.verdict = f"rank W = m exactly, but cond(W) = {cond:.3g} > cond_max = {cond_max:.3g}"
        res.reason = "numerically dependent columns (condition number above cond_max)"
    return res
