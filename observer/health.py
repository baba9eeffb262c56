"""Health of a run: is it inside the regime where its numbers mean anything?

Every run of :meth:`observer.engines.timestepping.TimeStepping.advance` gets a :class:`Health` record (issue 12, item 2):

``max_residual``
    The largest complementarity residual of any contact step, *recomputed from the velocity
    the step applied* (:func:`observer.primitives.applied_residual`: ``Wᵀ(u_{k+1} − u_free)`` in
    place of the solver's ``ĜP``), relative like the solver's residual. A step above the
    run's tolerance stops the run (:class:`~observer.engines.loop.LoopOutput` ``stopped_at``).
    The python engine recomputes it on Newton steps and single-contact steps (one contact:
    the Poisson step is the Newton step); a Poisson step on several contacts contributes the
    solver's own residual there (``residual_source`` says which).
``penetration``, ``length_scale``, ``penetration_rel``
    The deepest penetration of the master over every step (``max(0, −min_k g_j(t_k))``) and
    the same relative to the scenario's length scale ℓ = max(‖q₀‖_∞, ‖ν(t₀)‖_∞, ‖g(t₀)‖_∞)
    (the size of the initial configuration and clearances: 0.25 m on ``double_mass``); when
    all three vanish, ℓ = the largest excursion ‖q_k − q₀‖_∞ of the recorded master.
``min_eig_L``
    The smallest eigenvalue of ``L_I = W_IᵀN⁻¹W_I`` over the closed sets I the position
    projections met (eqs. (13)-(14); N = K unless the design has its own metric), from the
    recorded rows (every step when ``record_every = 1``); None when nothing was projected.
``h_omega_max``
    ``h·ω_max`` with ω_max² the largest eigenvalue of ``K v = ω² M v``. The θ = ½ scheme is
    stable for every h, but the frequency of a mode ω becomes ``(2/h)·atan(hω/2)``: a
    relative error of 7.3 % at ``hω = 1`` (:data:`H_OMEGA_MAX`).
``energy_growth``
    For runs without time-dependent forcing or gap motion (``f`` constant, ``ν`` constant),
    without master projection and with every restitution ≤ 1: the largest rise of the
    master's mechanical energy ``E = ½uᵀMu + ½qᵀKq − f_cᵀq`` above its initial value over
    the recorded rows, relative to the energy scale
    ``max_k(½uᵀMu + ½qᵀKq + |f_cᵀq|)``. Damping (C ⪰ 0) and impacts (e ≤ 1) only remove
    energy; the discrete θ = ½ scheme adds at most round-off and the O(h) slack of the impulse
    term (README, "What holds in discrete time"). Checked: ``energy_growth ≤
    ENERGY_ROUNDOFF + ENERGY_SLACK·h·ω_ref`` with ω_ref = max(ω_max, 1/T) over the horizon T.
    None when not applicable.
``observer_gap``
    Per observer whose gap went deeper than its bound while χ said open (empty when none
    did): the contact, the row's time, the depth ``−g_s,i`` and the bound ``b_i``
    (:func:`observer_gaps`: the bound and the theorem it rests on).
``computed_by``
    How the spectral quantities were computed: ``omega_max`` (dense ``eigh``, or Lanczos with
    its tolerance for a large sparse system) and the model's checks of M, C, K, W
    (``check_methods`` of :class:`observer.LinearSystem`: dense eigenvalues and SVD, or banded
    Cholesky and Lanczos) and, when a K-metric projection needed K ≻ 0, how that was
    established (``K_definite``: a verified banded Cholesky of K − cI, or eigenvalues).

``warnings`` lists one line per check outside its bound; :func:`emit` sends them to stderr
(``warnings.warn`` with :class:`RunHealthWarning`).
"""

from __future__ import annotations

import os
import sys
import warnings
from dataclasses import asdict, dataclass, field

import numpy as np
import scipy.linalg as sla

from observer import sparse as sps

H_OMEGA_MAX = 1.0
"""Bound on h·ω_max: above it the stiffest mode's discrete frequency is off by > 7 %."""
PENETRATION_MAX_REL = 0.01
"""Bound on the master's deepest penetration relative to the length scale (1 %)."""
ENERGY_ROUNDOFF = 1e-10
"""Round-off allowance of the relative energy growth."""
ENERGY_SLACK = 1.0
"""Coefficient of the O(h) slack of the relative energy growth (per unit of h·ω_ref)."""
MAX_SETS = 4096
"""At most this many distinct projected closed sets get their L_I eigenvalue computed."""


class RunHealthWarning(UserWarning):
    """A run outside the regime where its numbers mean anything (see :class:`Health`)."""


@dataclass(frozen=True)
class Health:
    """Health metrics of one run (module docstring: definitions and bounds)."""

    max_residual: float = 0.0
    max_residual_t: float | None = None
    residual_tol: float = float("nan")
    residual_source: str = "applied"
    penetration: float = 0.0
    penetration_t: float | None = None
    length_scale: float = float("nan")
    penetration_rel: float = 0.0
    min_eig_L: float | None = None
    h_omega_max: float = float("nan")
    energy_growth: float | None = None
    energy_bound: float | None = None
    warnings: tuple = field(default_factory=tuple)
    computed_by: dict = field(default_factory=dict)
    observer_gap: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """Plain JSON-ready dict (the run's ``metadata["health"]``)."""
        d = asdict(self)
        d["warnings"] = list(self.warnings)
        return d


# ---------------------------------------------------------------------------------------
# the metrics
# ---------------------------------------------------------------------------------------
def length_scale(system, q0: np.ndarray, t0: float, q: np.ndarray | None = None) -> float:
    """ℓ = max(‖q₀‖_∞, ‖ν(t₀)‖_∞, ‖g(t₀)‖_∞); if 0, the master's largest excursion in ``q``."""
    q0 = np.asarray(q0, dtype=float)
    ell = max(float(np.max(np.abs(q0), initial=0.0)),
              float(np.max(np.abs(system.nu(t0)), initial=0.0)),
              float(np.max(np.abs(system.gaps(q0, t0)), initial=0.0)))
    if ell == 0.0 and q is not None and q.size:
        ell = float(np.max(np.abs(q - q0)))
    return ell


def omega_max(system) -> float:
    """Largest ω with ``K v = ω² M v`` (0 for K = 0); computed once per system (cached in
    its ``__dict__``, as :meth:`LinearSystem.stiffness_eigenvalue_range` does).

    Dense ``eigh`` (the last eigenvalue only) for a dense system; for a sparse one
    (:data:`observer.sparse.DENSE_MAX_N`) Lanczos on the generalized problem, O(n) per
    iteration (:func:`observer.sparse.largest_eigenvalue`: relative residual
    :data:`~observer.sparse.LANCZOS_TOL_MAX`, else the Gershgorin bound). :func:`omega_max_method`
    says which."""
    cached = system.__dict__.get("_omega_max")
    if cached is None:
        n = system.n
        if system.sparse:
            lam, how = sps.largest_eigenvalue(system.K, system.M)
        else:
            lam = sla.eigh(system.K, system.M, eigvals_only=True, subset_by_index=[n - 1, n - 1])[0]
            how = "dense generalized eigh (LAPACK)"
        cached = system.__dict__["_omega_max"] = float(np.sqrt(max(lam, 0.0)))
        system.__dict__["_omega_max_how"] = how
    return cached


def omega_max_method(system) -> str:
    """How :func:`omega_max` computed ω_max of ``system`` (computing it if needed)."""
    omega_max(system)
    return system.__dict__["_omega_max_how"]


def min_eig_projected(L_of, sets: list[tuple[int, np.ndarray]]) -> float | None:
    """Smallest eigenvalue of ``L_I`` over ``sets`` (pairs (system, closed-set mask));
    ``L_of(s)`` is system s's ``WᵀN⁻¹W``. Distinct pairs only, at most :data:`MAX_SETS`."""
    seen, lo = set(), None
    for s, mask in sets:
        key = (s, mask.tobytes())
        if key in seen or not mask.any():
            continue
        seen.add(key)
        if len(seen) > MAX_SETS:
            break
        idx = np.flatnonzero(mask)
        LI = L_of(s)[np.ix_(idx, idx)]
        lam = float(np.linalg.eigvalsh(0.5 * (LI + LI.T))[0])
        lo = lam if lo is None else min(lo, lam)
    return lo


def unforced(system, law, master_projection: bool) -> bool:
    """True when energy can only be removed: forcing and gap without time-dependent terms,
    no master projection, every restitution ≤ 1."""
    quiet = all(not np.any(np.asarray(h.amplitude)) for h in (system.forcing, system.gap))
    return quiet and not master_projection and bool(np.all(np.asarray(law.restitution) <= 1.0))


def mechanical_energy(system, q: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``E = ½uᵀMu + ½qᵀKq − f_cᵀq`` per row and its scale ``½uᵀMu + ½qᵀKq + |f_cᵀq|``."""
    fc = np.asarray(system.forcing.constant, dtype=float)
    T = 0.5 * sps.quadratic_rows(u, system.M)
    U = 0.5 * sps.quadratic_rows(q, system.K)
    W = q @ fc
    return T + U - W, T + U + np.abs(W)


def energy_growth(system, q: np.ndarray, u: np.ndarray) -> float:
    """``max_k (E_k − E_0) / max_k scale_k`` (:func:`mechanical_energy`), ≥ 0.

    The ratio does not change when q and u are divided by one number c (T, U and the scale
    by c², f_cᵀq by c, which only the ratio's forcing term feels): states so large that the
    energies overflow (finite rows of a run its guard stopped, :class:`observer.engines.loop.FiniteGuard`)
    are divided by their largest entry first — for an unforced run, the only one assessed,
    the same ratio."""
    with np.errstate(over="ignore", invalid="ignore"):
        E, scale = mechanical_energy(system, q, u)
    if not (np.all(np.isfinite(E)) and np.all(np.isfinite(scale))):
        c = max(float(np.max(np.abs(q))), float(np.max(np.abs(u))))
        E, scale = mechanical_energy(system, q / c, u / c)
    top = float(np.max(scale))
    if top == 0.0:
        return 0.0
    return max(0.0, float(np.max(E - E[0])) / top)


def aliased_signals(system, h: float) -> list[str]:
    """One warning per harmonic term of the forcing f(t) or the gap offset ν(t) that the grid
    t_k = k·h samples below its Nyquist rate (h·ω > π, nonzero amplitude).

    Such a term is aliased: the scheme sees it at a frequency in [0, π/h] that it does not
    have, and its response is not resolved however well h resolves the system's own modes
    (h·ω_max counts those only). The exact response to a forcing of amplitude F at
    ω ≫ ω_max is O(F/(m ω)) in velocity; the stepped one is O(F h/m).
    """
    out = []
    for field, sig in (("system.forcing", system.forcing), ("system.gap", system.gap)):
        for j, w in enumerate(np.asarray(sig.omega, dtype=float)):
            if h * w > np.pi and np.any(np.asarray(sig.amplitude)[j] != 0):
                out.append(f"{field} term {j}: h·ω = {h * w:.3g} > π (ω = {w:.4g} rad/s, h = {h:g}): "
                           "the signal is sampled below its Nyquist rate (aliased); the response "
                           "to it is not resolved: reduce h below π/ω")
    return out


# ---------------------------------------------------------------------------------------
# the record
# ---------------------------------------------------------------------------------------
def assess(inp, record_every: int, q: np.ndarray, u: np.ndarray, active: np.ndarray,
           chi: np.ndarray, stats: dict, L_of) -> Health:
    """Health of a loop run from its records (system s first axis; row r holds step
    r·record_every) and counters.

    ``stats`` holds ``applied_residual`` (and its ``applied_residual_step``), ``min_gap``
    and ``min_gap_step``; ``L_of(s)`` the projection matrix of system s.
    """
    st = inp.stepper
    sys_ = st.system
    h = st.h
    tol = float(st.residual_tol)
    T = float(st.time(st.steps)) - st.t0
    res = float(stats.get("applied_residual", 0.0))
    res_step = stats.get("applied_residual_step", -1)
    min_gap = stats.get("min_gap", np.inf)
    gap_step = stats.get("min_gap_step", -1)
    pen = max(0.0, -float(min_gap)) if np.isfinite(min_gap) else 0.0
    ell = length_scale(sys_, inp.q0[0], st.t0, q[0])
    pen_rel = pen / ell if ell > 0 else (np.inf if pen > 0 else 0.0)
    w = omega_max(sys_)
    how = h * w
    lam = min_eig_projected(L_of, projected_sets(inp, record_every, active, chi))
    growth = bound = None
    if unforced(sys_, st.law, bool(inp.master_projection)) and q.shape[1] > 1:
        growth = energy_growth(sys_, q[0], u[0])
        bound = ENERGY_ROUNDOFF + ENERGY_SLACK * h * max(w, 1.0 / T if T > 0 else 0.0)
    msgs = []
    if how > H_OMEGA_MAX:
        msgs.append(f"h·ω_max = {how:.3g} > {H_OMEGA_MAX:g}: the stiffest mode (ω_max = {w:.4g} rad/s) "
                    f"is not resolved by h = {h:g} (its discrete frequency is off by "
                    f"{100 * (1 - 2 * np.arctan(how / 2) / how):.0f} %)")
    msgs.extend(aliased_signals(sys_, h))
    if pen_rel > PENETRATION_MAX_REL:
        msgs.append(f"penetration {pen:.3g} = {100 * pen_rel:.3g} % of the length scale {ell:.3g} "
                    f"(bound {100 * PENETRATION_MAX_REL:g} %) at t = {float(st.time(gap_step)):.6g}: "
                    "reduce h")
    if growth is not None and growth > bound:
        msgs.append(f"mechanical energy grew by {growth:.3g} of its scale in an unforced run "
                    f"(allowed {bound:.3g}: round-off + O(h) slack)")
    deep = observer_gaps(inp, record_every, q, u, chi, ell)
    for name, d in deep.items():
        msgs.append(f"observer {name!r}: gap {d['contact']} = {-d['depth']:.3g} at t = {d['t']:.6g} "
                    f"while χ = 0, below −{d['bound']:.3g} (the master's penetration bound "
                    f"{100 * PENETRATION_MAX_REL:g} % of {ell:.3g} plus what its error at V's smallest "
                    "can explain): V rose, so χ is not the master's closed set (a closing missing "
                    "from the log?)")
    return Health(res, float(st.time(res_step)) if res_step >= 0 else None, tol,
                  stats.get("residual_source", "applied"), pen,
                  float(st.time(gap_step)) if gap_step >= 0 and pen > 0 else None, ell,
                  float(pen_rel), lam, how, growth, bound, tuple(msgs),
                  computed_by(sys_), deep)


ROW_BLOCK = 1 << 20
"""Entries (rows × max(n, m)) of one block of records that :func:`observer_gaps` evaluates at
once: its extra memory is a few such blocks, whatever the run's length."""
MAX_GAP_CONTACTS = 64
"""At most this many contacts (the deepest) get their ``‖W_i‖_{K⁻¹}`` computed by
:func:`observer_gaps` (each a solve with K's factor on a large system)."""


def observer_gaps(inp, record_every: int, q: np.ndarray, u: np.ndarray, chi: np.ndarray,
                  ell: float) -> dict:
    """Observers whose gap goes below its bound while χ says the contact is open.

    On a recorded row r whose step was coupled with χ_i = 0, observer s's gap
    ``g_s,i = W_iᵀq_s + ν_i(t)`` is checked against

    ``b_i(r) = PENETRATION_MAX_REL·ℓ + ‖W_i‖_{K⁻¹} · sqrt(2·min_{r₀ ≤ j ≤ r} V_j)``,

    ℓ the run's length scale (:func:`length_scale`), ``‖W_i‖²_{K⁻¹} = (WᵀK⁻¹W)_ii``, V the
    observer's error Lyapunov function (paper eq. (16)) against the run's master and r₀ the
    row before the first coupled step.

    **Why a correct χ never crosses it.** Observer and master share W and ν, so
    ``g_s,i − g_m,i = W_iᵀe`` (e = q_s − q_m, paper eq. (2)), and by Cauchy–Schwarz in the
    K inner product ``|W_iᵀe| = |(K⁻¹W_i)ᵀKe| ≤ ‖W_i‖_{K⁻¹}‖e‖_K ≤ ‖W_i‖_{K⁻¹}·sqrt(2V)``
    (eq. (16)). When χ is the master's closed set (``source="master"``, an exact log),
    master and observer are two solutions of (7)-(11) with the same χ and V is
    non-increasing (Theorem 1, eq. (17); in discrete time its twin (docs/theory/scheme.md §1), up to the
    slack of docs/theory/scheme.md §7.2), so V_r = min_{j≤r} V_j. A master inside its own
    health bound has ``g_m,i ≥ −PENETRATION_MAX_REL·ℓ``; hence ``g_s,i ≥ −b_i(r)``.
    A row below ``−b_i(r)`` therefore proves that V rose above its smallest value since
    coupling (or the master penetrated beyond its bound, which its own warning reports):
    χ did not follow the master's contacts — a closing missing from the log lets the
    observer move through the wall the master rests on.

    The bound needs no knowledge of the error beyond the run's own V; it uses the
    recorded rows only (every step when ``record_every = 1``); None of it applies to an
    uncoupled or self-driven observer (its own constraints keep its gap) or when K is not
    positive definite (no K-norm). Memory: blocks of :data:`ROW_BLOCK` entries.

    Returns
    -------
    dict
        Per observer name crossing its bound, the row with the largest excess
        ``−g_s,i − b_i``: ``{"contact", "t", "depth", "bound"}``.
    """
    st = inp.stepper
    sys_ = st.system
    S, R = q.shape[0], q.shape[1]
    if S < 2 or R < 2 or inp.self_driven or sys_.m == 0:
        return {}
    rows = np.arange(R)
    step_t = st.time(np.maximum(rows * record_every - 1, 0))      # the step ending at row r
    coupled = np.ones(R, bool) if inp.coupling is None else \
        (step_t >= inp.coupling[0]) & (step_t <= inp.coupling[1])
    coupled[0] = False
    if not coupled.any():
        return {}
    r0 = int(np.flatnonzero(coupled)[0]) - 1
    margin = PENETRATION_MAX_REL * ell
    names = tuple(inp.names) or tuple(f"obs{s}" for s in range(1, S))
    block = max(1, ROW_BLOCK // max(sys_.n, sys_.m, 1))
    out = {}
    for s in range(1, S):
        cand = _deep_rows(sys_, st, record_every, q[s], chi, coupled, margin, block)
        if cand is None:
            continue
        worst = _worst_excess(sys_, st, record_every, q, u, s, r0, cand, margin, block)
        if worst is not None:
            out[names[s - 1]] = worst
    return out


def _deep_rows(sys_, st, record_every, qs, chi, coupled, margin, block):
    """(row, contact, depth) of every coupled row with χ_i = 0 and ``−g_s,i > margin`` (None:
    no such row)."""
    found = []
    for a in range(0, qs.shape[0], block):
        b = min(a + block, qs.shape[0])
        g = sys_.gaps(np.asarray(qs[a:b]), st.time(np.arange(a, b) * record_every))
        open_ = ~np.asarray(chi[a:b], dtype=bool) & coupled[a:b, None]
        r, i = np.nonzero(open_ & (-g > margin))
        if r.size:
            found.append((r + a, i, -g[r, i]))
    if not found:
        return None
    return tuple(np.concatenate(c) for c in zip(*found))


def _worst_excess(sys_, st, record_every, q, u, s, r0, cand, margin, block):
    """The candidate row with the largest ``depth − b_i(r)`` if positive (else None); V and its
    running minimum from row r0 on (:func:`observer_gaps`)."""
    from observer.observers import lyapunov

    rows, contacts, depth = cand
    last = int(rows.max()) + 1
    vmin = np.empty(last - r0)
    low = np.inf
    for a in range(r0, last, block):
        b = min(a + block, last)
        V = lyapunov(sys_, np.asarray(q[s, a:b]), np.asarray(u[s, a:b]),
                     np.asarray(q[0, a:b]), np.asarray(u[0, a:b]))
        run = np.minimum.accumulate(np.concatenate([[low], V]))[1:]
        vmin[a - r0:b - r0] = run
        low = run[-1]
    deepest = np.unique(contacts[np.argsort(-depth)])[:MAX_GAP_CONTACTS]
    norms = _k_inverse_norms(st, deepest)
    if norms is None:
        return None
    keep = np.isin(contacts, deepest)
    rows, contacts, depth = rows[keep], contacts[keep], depth[keep]
    bound = margin + norms[np.searchsorted(deepest, contacts)] * np.sqrt(2.0 * np.maximum(vmin[rows - r0], 0.0))
    k = int(np.argmax(depth - bound))
    if not depth[k] > bound[k]:
        return None
    return {"contact": int(contacts[k]), "t": float(st.time(int(rows[k]) * record_every)),
            "depth": float(depth[k]), "bound": float(bound[k])}


def _k_inverse_norms(st, idx: np.ndarray) -> np.ndarray | None:
    """``‖W_i‖_{K⁻¹} = sqrt((WᵀK⁻¹W)_ii)`` for the contacts ``idx`` (sorted), from the
    stepper's K-projection data (None when K is not positive definite)."""
    if not st.system.stiffness_definiteness()[0]:
        return None
    if st.S.factored:
        L = st._active_slices(np.asarray(idx, dtype=np.int64))[5]
        if L is None:
            return None
        d = np.diag(L)
    else:
        if st.S.KinvW is None:
            return None
        d = np.diag(st.S.L)[idx]
    return np.sqrt(np.maximum(d, 0.0))


def computed_by(system) -> dict:
    """How the spectral quantities of ``system`` were computed: ``omega_max``, the model's
    checks (``check_M`` ...) and, once a K-metric projection asked, ``K_definite``: how K ≻ 0
    was established (a verified banded Cholesky of K − cI for a large banded K, else eigenvalues;
    :meth:`observer.model.LinearSystem.stiffness_definiteness`)."""
    out = {"omega_max": omega_max_method(system), **getattr(system, "check_methods", {})}
    if "_K_definite" in system.__dict__:
        out["K_definite"] = system.stiffness_definiteness()[1]
    return out


def projected_sets(inp, record_every: int, active: np.ndarray, chi: np.ndarray) -> list:
    """(system, closed set) of every recorded projected step (row r: step r·record_every): the
    master's closed sets with ``master_projection``, χ of the coupled steps for observers with
    position jumps. (An uncoupled observer's own closed sets are not recorded and not
    included.)"""
    out = []
    R = active.shape[0]
    if R < 2:
        return out
    act, ch = active[1:], chi[1:]
    if inp.master_projection:
        out += [(0, a) for a in _distinct(act)]
    jumps = np.flatnonzero(np.asarray(inp.jumps, dtype=bool)[1:]) + 1
    if jumps.size:
        tk = inp.stepper.time(np.arange(1, R) * record_every - 1)     # the steps ending at rows 1..
        coupled = np.ones(tk.shape, bool) if inp.coupling is None else \
            (tk >= inp.coupling[0]) & (tk <= inp.coupling[1])
        if inp.self_driven:
            coupled[:] = False
        sets = _distinct(ch[coupled])
        out += [(int(s), a) for s in jumps for a in sets]
    return out


def _distinct(masks: np.ndarray) -> list[np.ndarray]:
    """The distinct non-empty rows of a bool matrix (runs of equal rows collapsed first: the
    closed sets of a run change rarely, and sorting every recorded row cost more than the
    kernel's steps)."""
    if masks.size == 0:
        return []
    keep = np.ones(masks.shape[0], dtype=bool)
    keep[1:] = np.any(masks[1:] != masks[:-1], axis=1)
    masks = masks[keep]
    packed = np.unique(np.packbits(masks, axis=1), axis=0)
    m = masks.shape[1]
    return [r for r in np.unpackbits(packed, axis=1, count=m).astype(bool) if r.any()]


def emit(health: Health) -> None:
    """Each of ``health.warnings`` as a :class:`RunHealthWarning` (stderr by default),
    attributed to the first caller outside the ``observer`` package (the user's call)."""
    for msg in health.warnings:
        warnings.warn(msg, RunHealthWarning, stacklevel=_caller_level())


def _caller_level() -> int:
    """``stacklevel`` (seen from :func:`emit`) of the first frame outside this package."""
    pkg = os.path.dirname(os.path.abspath(__file__)) + os.sep
    frame, level = sys._getframe(2), 2
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(pkg):
        frame, level = frame.f_back, level + 1
    return level
