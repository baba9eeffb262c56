"""The compiled kernel's arguments, by name: the bundles and their constructors.

Each :class:`typing.NamedTuple` here is one group of the kernel's arrays
(:class:`SystemBundle` the scheme's constant matrices, :class:`LawBundle` the impact law,
:class:`SignalBundle` the signals' tables, :class:`WindowBundle` a window's waves and
coupling, :class:`ObserverBundle` the designs and projection metrics, :class:`StateBundle`
the state advanced in place, :class:`StorageBundle` the records, :class:`SummaryBundle` the
streaming summary); the functions build them from a :class:`~observer.engines.loop.LoopInput`
once per run (:class:`observer.engines.compiled.driver.CompiledRun`), every array a fresh
C-contiguous one of the type the kernel was compiled for.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from observer.engines.compiled.kernel import WAVE_NAMES, fill_waves
from observer.engines.compiled.step import MODEL_READS, MODEL_TABLES
from observer.engines.loop import LoopInput, projection_slots
from observer.errors import InputError
from observer.model import grid_anchors
from observer.result import RECORD_ARRAYS
from observer.stepping import FACTORED_MIN_N, MoreauJean, dense, to_band
from observer.primitives import (CONTACTS_DENSE, CONTACTS_FACTORED, STATS_SIZE, STRUCTURE_BANDED, STRUCTURE_DENSE,
                                 SUMMARY_FIELDS)



# ---------------------------------------------------------------------------------------
# the bundles: the kernel's arguments by name (built by the constructors below)
# ---------------------------------------------------------------------------------------
class SystemBundle(NamedTuple):
    """The scheme's constant arrays for one grid (:func:`observer.engines.compiled.bundles.system_bundle`).

    Attributes
    ----------
    structure : int
        :data:`STRUCTURE_DENSE` or :data:`STRUCTURE_BANDED`.
    Bu, Bq, Bf : ndarray (n, n)
        ``u_free = Bu u + Bq q + Bf f̄`` (dense; (1, 1) placeholders when banded).
    Ru_b, Rq_b, Ach_b : ndarray (bw + 1, n)
        R_u, R_q and the Cholesky factor of Â in lower band storage (banded; (1, 1)
        placeholders when dense).
    bw : int
        The bandwidth (0 when dense).
    Wp, Wi, Wv : ndarray
        W in CSC storage (column pointers, row indices, values; indices sorted).
    AinvWT : ndarray (m, n)
        ``(Â⁻¹W)ᵀ`` ((1, 1) placeholder with factored contacts).
    Ghat, G0 : ndarray (m, m)
        ``Ĝ = WᵀÂ⁻¹W`` and ``G₀ = WᵀM⁻¹W`` ((1, 1) placeholders with factored contacts).
    contacts : int
        :data:`CONTACTS_DENSE` or :data:`CONTACTS_FACTORED` (banded structure only: Ĝ_AA and
        ``δu = Â⁻¹W_A P`` from ``Ach_b`` per step, :func:`factored_impulse`).
    Acache : ndarray (C, n)
        Cached columns ``Â⁻¹W_j`` (factored contacts; (1, 1) placeholder otherwise).
    Aslot, Aowner, Astamp : ndarray of int (m,), (C,), (C + 1,)
        The cache's contact → row and row → contact maps, last uses and clock
        (:func:`_factored_column`).
    h, theta, t0 : float
        The step, θ and the grid's start.
    """

    structure: int
    Bu: np.ndarray
    Bq: np.ndarray
    Bf: np.ndarray
    Ru_b: np.ndarray
    Rq_b: np.ndarray
    Ach_b: np.ndarray
    bw: int
    Wp: np.ndarray
    Wi: np.ndarray
    Wv: np.ndarray
    AinvWT: np.ndarray
    Ghat: np.ndarray
    G0: np.ndarray
    contacts: int
    Acache: np.ndarray
    Aslot: np.ndarray
    Aowner: np.ndarray
    Astamp: np.ndarray
    h: float
    theta: float
    t0: float


class LawBundle(NamedTuple):
    """The impact law and the solver's settings (:func:`observer.engines.compiled.bundles.law_bundle`).

    Attributes
    ----------
    code : int
        The law's kernel code (0: Newton; :data:`observer.impact.POISSON`: Glocker's phases).
    e : ndarray (m,)
        Restitution coefficients.
    tol : float
        Largest accepted relative complementarity residual (LCP and applied).
    """

    code: int
    e: np.ndarray
    tol: float


class SignalBundle(NamedTuple):
    """The tables of the signals f(t), ν(t), ν̇(t) (:func:`observer.engines.compiled.bundles.signal_tables`).

    Attributes
    ----------
    omega, phase : ndarray (waves,)
        The distinct waves ``function(ω t + phase)``.
    function : ndarray of int (waves,)
        Their function codes (:data:`WAVE_NAMES`).
    e_ptr : ndarray of int (4,)
        Signal i's entries are ``e_ptr[i]:e_ptr[i+1]`` (f, ν, ν̇).
    e_col, e_coef, e_wave : ndarray (entries,)
        Each entry's column, coefficient and wave, in summation order.
    v_ptr : ndarray of int (4,)
        Signal i's varying columns are ``v_col[v_ptr[i]:v_ptr[i+1]]``.
    v_col : ndarray of int
        The varying columns.
    f_c, nu_c : ndarray (n,), (m,)
        The constants of f and ν.
    """

    omega: np.ndarray
    phase: np.ndarray
    function: np.ndarray
    e_ptr: np.ndarray
    e_col: np.ndarray
    e_coef: np.ndarray
    e_wave: np.ndarray
    v_ptr: np.ndarray
    v_col: np.ndarray
    f_c: np.ndarray
    nu_c: np.ndarray


class WindowBundle(NamedTuple):
    """What changes per window of steps kb..k1 (:func:`observer.engines.compiled.bundles.window_bundle`).

    Attributes
    ----------
    kb : int
        The window's first step (row k − kb of the arrays below holds step k).
    waves : ndarray (waves, k1 − kb + 1)
        The waves at the window's grid points (:func:`observer.engines.compiled.bundles.wave_table`).
    coupled : ndarray of bool
        Per step, whether the observers are coupled to χ_k ((1,): the master alone).
    chi_log : ndarray of bool (steps, m)
        χ_k from a closing log or given explicitly ((1, 1) placeholder when unused).
    use_log : bool
        Whether ``chi_log`` is χ (else the master's closed set).
    """

    kb: int
    waves: np.ndarray
    coupled: np.ndarray
    chi_log: np.ndarray
    use_log: bool


class ObserverBundle(NamedTuple):
    """The observers' designs and the projection metrics (:func:`observer.engines.compiled.bundles.observer_bundle`).

    Attributes
    ----------
    jumps : ndarray of bool (S,)
        Position jumps while coupled (row 0, the master, ignored).
    slots : ndarray of int (S,)
        Each system's projection metric (slot in the stacks below).
    master_projection : bool
        The master is projected on its closed set.
    KinvWT : ndarray (P, m, n)
        ``(N⁻¹W)ᵀ`` per projection metric N ((1, 1, 1) placeholder with factored contacts).
    L : ndarray (P, m, m)
        ``WᵀN⁻¹W`` per projection metric N ((1, 1, 1) placeholder with factored contacts).
    Kch : ndarray (P, bwk + 1, n)
        With factored contacts: the lower banded Cholesky factor of each metric (zeros: none,
        the projection then fails); else a (1, 1, 1) placeholder.
    bwk : int
        Their bandwidth.
    Kcache, Kslot, Kowner, Kstamp : ndarray
        Per metric, the cache of columns ``N⁻¹W_j`` (P, C, n) and its maps (P, m), (P, C),
        (P, C + 1) (:func:`_factored_column`).
    """

    jumps: np.ndarray
    slots: np.ndarray
    master_projection: bool
    KinvWT: np.ndarray
    L: np.ndarray
    Kch: np.ndarray
    bwk: int
    Kcache: np.ndarray
    Kslot: np.ndarray
    Kowner: np.ndarray
    Kstamp: np.ndarray


class StateBundle(NamedTuple):
    """The mutable state the kernel advances in place (:func:`observer.engines.compiled.bundles.state_bundle`).

    Attributes
    ----------
    qs, us : ndarray (S, n)
        The current states, row 0 the master.
    chi_now : ndarray of bool (m,)
        The closed set fed to the observers at the current step.
    stats : ndarray (:data:`STATS_SIZE`,)
        The work and health counters.
    """

    qs: np.ndarray
    us: np.ndarray
    chi_now: np.ndarray
    stats: np.ndarray


class StorageBundle(NamedTuple):
    """The records (:func:`observer.engines.compiled.bundles.storage_bundle`); row r holds step r·record_every.

    Attributes
    ----------
    record_every : int
    q, u : ndarray (S, R, n)
    P, sigma : ndarray (S, R, m)
        Impulses and projection multipliers (zero-filled).
    active, chi : ndarray of bool (R, m)
        The master's closed set and the observers' χ (zero-filled).
    q_pre : ndarray (S, R or 0, n)
        Positions before the projection.
    record_pre : bool
        Whether ``q_pre`` is recorded.
    t : ndarray (R,) or (0,)
        The rows' times, written by :func:`advance_scalar` when it has a row per record.
    """

    record_every: int
    q: np.ndarray
    u: np.ndarray
    P: np.ndarray
    sigma: np.ndarray
    active: np.ndarray
    chi: np.ndarray
    q_pre: np.ndarray
    record_pre: bool
    t: np.ndarray


class SummaryBundle(NamedTuple):
    """The streaming summary (``store="summary"``, :func:`observer.engines.compiled.bundles.summary_bundle`).

    Attributes
    ----------
    on : bool
        Whether the summary is computed.
    k_on, k_off : int
        The coupling window's grid samples.
    rhos : ndarray (thresholds,)
    summ : ndarray (S, :data:`SUMMARY_FIELDS` + 2·thresholds)
    vprev : ndarray (S, n)
        Each observer's previous velocity difference.
    Vprev : ndarray (S,)
        Each observer's previous V.
    rec_V : ndarray (S, R or 0)
        V at the recorded rows.
    closings : ndarray of int (m,)
        The master's closings per contact.
    prev_act : ndarray of bool (m,)
        The master's previous closed set.
    Mq, Kq, Cq : ndarray
        M, K and the symmetric part of C in the system's structure ((1, 1) placeholders
        when off).
    """

    on: bool
    k_on: int
    k_off: int
    rhos: np.ndarray
    summ: np.ndarray
    vprev: np.ndarray
    Vprev: np.ndarray
    rec_V: np.ndarray
    closings: np.ndarray
    prev_act: np.ndarray
    Mq: np.ndarray
    Kq: np.ndarray
    Cq: np.ndarray


ModelBundle = NamedTuple("ModelBundle", [(name, object) for name in MODEL_READS + MODEL_TABLES
                                         + ("omega", "phase", "function")])
ModelBundle.__doc__ = """The observers' own model in the kernel's layout (:func:`observer.engines.compiled.bundles.model_bundle`):
    what an observer's step reads of its system (dense structure and contacts).

    Attributes
    ----------
    Bu, Bq, Bf, Wp, Wi, Wv, AinvWT, Ghat : ndarray
        The model's :class:`SystemBundle` fields of the same names.
    code : int
    e : ndarray (m,)
        The model's impact law and restitution.
    e_ptr, e_col, e_coef, e_wave, v_ptr, v_col, f_c, nu_c : ndarray
        The model's signal tables (:class:`SignalBundle`).
    waves : ndarray (waves, k1 − kb + 1)
        The model's waves at the current window's grid points (:func:`model_window`).
    omega, phase, function : ndarray
        The model's distinct waves (to build ``waves`` per window).
    """


def model_bundle(model_inp: LoopInput) -> "ModelBundle":
    """The :class:`ModelBundle` of the observers' model (``model_inp``: the loop input on the
    model's stepper); its waves empty until :func:`model_window`.

    Raises
    ------
    InputError
        Naming ``observer.model`` when the model's scheme is not dense (banded structure or
        factored contacts: the model loop has the dense step only).
    """
    st = model_inp.stepper
    if st.S.band is not None or st.S.factored:
        raise InputError("observer.model", "the compiled model loop needs a dense scheme (n < "
                         f"{FACTORED_MIN_N}, structure dense)")
    sb, law, sig = system_bundle(model_inp), law_bundle(st), signal_tables(st.system)
    return ModelBundle(Bu=sb.Bu, Bq=sb.Bq, Bf=sb.Bf, Wp=sb.Wp, Wi=sb.Wi, Wv=sb.Wv, AinvWT=sb.AinvWT, Ghat=sb.Ghat,
                       code=law.code, e=law.e, e_ptr=sig.e_ptr, e_col=sig.e_col, e_coef=sig.e_coef,
                       e_wave=sig.e_wave, v_ptr=sig.v_ptr, v_col=sig.v_col, f_c=sig.f_c, nu_c=sig.nu_c,
                       waves=np.empty((sig.omega.size, 0)), omega=sig.omega, phase=sig.phase,
                       function=sig.function)


def model_window(model: "ModelBundle", t0: float, h: float, kb: int, k1: int) -> "ModelBundle":
    """``model`` with the waves of the window kb..k1 (:func:`wave_table`)."""
    return model._replace(waves=wave_table(t0, h, kb, k1, model.omega, model.phase, model.function))


def model_observers(inp: LoopInput, model_inp: LoopInput) -> "ObserverBundle":
    """The projection metrics of a model run: the master's of the plant (slot 0), every
    observer's of the model (slots 1..: :func:`projection_slots` of ``model_inp``)."""
    plant = observer_bundle(inp)
    slots, NinvWT, L = projection_slots(model_inp)
    p0 = plant.slots[0]
    slots = np.concatenate([[0], 1 + slots[1:]]).astype(np.int64)
    return plant._replace(slots=slots, KinvWT=np.ascontiguousarray(np.concatenate([plant.KinvWT[p0:p0 + 1], NinvWT])),
                          L=np.ascontiguousarray(np.concatenate([plant.L[p0:p0 + 1], L])))


def system_bundle(inp: LoopInput) -> "SystemBundle":
    """The scheme's constant arrays in the kernel's layout (:class:`observer.engines.compiled.bundles.SystemBundle`):
    dense ``Bu, Bq, Bf`` or the banded ``R_u, R_q`` and factor of Â, W in CSC, ``(Â⁻¹W)ᵀ``,
    Ĝ, G₀, and the grid's h, θ, t0. Every array a fresh C-contiguous float64 (or int64) one,
    so that every run types the kernel alike (:func:`quadratic_forms`)."""

    stepper = inp.stepper
    S = stepper.S
    Wp, Wi, Wv = stepper.csc
    c = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731
    dummy = np.zeros((1, 1))
    if S.band is None:
        structure, dense, banded, bw = STRUCTURE_DENSE, (c(S.Bu), c(S.Bq), c(S.Bf)), (dummy,) * 3, 0
    else:
        b = S.band
        banded = (c(b.Ru), c(b.Rq), c(b.Achol))
        structure, dense, bw = STRUCTURE_BANDED, (dummy,) * 3, int(b.bw)
    if S.factored:
        contacts, cache = CONTACTS_FACTORED, column_cache(1, stepper.system.n, stepper.system.m)
        AinvWT, Ghat, G0 = dummy, dummy, dummy
    else:
        contacts, cache = CONTACTS_DENSE, column_cache(1, 1, 1, 1)
        AinvWT, Ghat, G0 = c(S.AinvW.T), c(S.Ghat), c(S.G0)
    return SystemBundle(structure=structure, Bu=dense[0], Bq=dense[1], Bf=dense[2], Ru_b=banded[0],
                        Rq_b=banded[1], Ach_b=banded[2], bw=bw, Wp=Wp, Wi=Wi, Wv=Wv, AinvWT=AinvWT,
                        Ghat=Ghat, G0=G0, contacts=contacts, Acache=cache[0][0], Aslot=cache[1][0],
                        Aowner=cache[2][0], Astamp=cache[3][0], h=float(stepper.h),
                        theta=float(stepper.theta), t0=float(stepper.t0))


FACTORED_CACHE_BYTES = 1 << 26
"""Memory of each cache of solved columns (``N⁻¹W_j``) of the factored contact data: 64 MiB,
at least 8 and at most 256 columns (:func:`column_cache`)."""


def column_cache(P: int, n: int, m: int, C: int | None = None) -> tuple[np.ndarray, ...]:
    """P empty caches of C solved columns of length n for m contacts, in the kernel's layout
    (:func:`observer.engines.compiled.kernel._factored_column`): ``(cols (P, C, n), slot_of (P, m) = −1,
    owner (P, C) = −1, stamp (P, C + 1) = 0)``; C from :data:`FACTORED_CACHE_BYTES` unless given."""
    if C is None:
        C = int(min(m, max(8, min(256, FACTORED_CACHE_BYTES // (8 * n)))))
    return (np.zeros((P, C, n)), np.full((P, m), -1, np.int64), np.full((P, C), -1, np.int64),
            np.zeros((P, C + 1), np.int64))


def law_bundle(stepper: MoreauJean) -> "LawBundle":
    """The impact law's kernel code, its restitution and the residual tolerance."""

    e = np.ascontiguousarray(stepper.law.restitution, dtype=np.float64)
    return LawBundle(code=int(stepper.law.code), e=e, tol=float(stepper.residual_tol))


def observer_bundle(inp: LoopInput) -> "ObserverBundle":
    """The designs' jumps, each system's projection slot and the stacked metrics
    (:func:`projection_slots`)."""

    jumps, mp = np.asarray(inp.jumps, dtype=np.bool_), bool(inp.master_projection)
    st = inp.stepper
    if st.S.factored:
        slots, Kch = factored_metrics(inp)
        cache = column_cache(Kch.shape[0], st.system.n, st.system.m)
        dummy = np.zeros((1, 1, 1))
        return ObserverBundle(jumps=jumps, slots=slots, master_projection=mp, KinvWT=dummy, L=dummy, Kch=Kch,
                              bwk=int(Kch.shape[1] - 1), Kcache=cache[0], Kslot=cache[1], Kowner=cache[2],
                              Kstamp=cache[3])
    slots, NinvWT, L = projection_slots(inp)
    cache = column_cache(1, 1, 1, 1)
    return ObserverBundle(jumps=jumps, slots=slots, master_projection=mp, KinvWT=NinvWT, L=L,
                          Kch=np.zeros((1, 1, 1)), bwk=0, Kcache=cache[0], Kslot=cache[1], Kowner=cache[2],
                          Kstamp=cache[3])


def factored_metrics(inp: LoopInput) -> tuple[np.ndarray, np.ndarray]:
    """With factored contact data: every system's projection slot (0) and the one metric's
    banded factor stack (1, bw + 1, n), K's (zeros when K is not positive definite: the
    projection then fails, :data:`observer.primitives.PROJECTION_FAILED`). Another metric raises
    :class:`InputError` naming ``observers``."""
    st = inp.stepper
    if any(inp.metric_of(s) is not None for s in range(inp.q0.shape[0])):
        raise InputError("observers", "a projection metric other than K (jump_mass, jump_identity) needs "
                         f"n < {FACTORED_MIN_N} degrees of freedom; this system has "
                         f"n = {st.system.n} (use the K-metric design \"jump\")")
    b = st.S.band
    Kch = np.zeros((b.bw + 1, st.system.n)) if b.Kchol is None else np.array(b.Kchol, dtype=np.float64)
    return np.zeros(inp.q0.shape[0], np.int64), np.ascontiguousarray(Kch[None])


def state_bundle(inp: LoopInput) -> "StateBundle":
    """Fresh copies of the initial states, χ cleared, the counters at their start values."""

    stats = np.zeros(STATS_SIZE)
    stats[3:7] = (np.inf, -1.0, 0.0, -1.0)
    return StateBundle(qs=inp.q0.astype(float).copy(), us=inp.u0.astype(float).copy(),
                       chi_now=np.zeros(inp.stepper.system.m, dtype=np.bool_), stats=stats)


def storage_bundle(rec: dict, record_every: int, record_pre: bool, t_rec: np.ndarray | None) -> "StorageBundle":
    """The records of :func:`allocate_records` (``t_rec``: the rows' times, or None)."""

    return StorageBundle(record_every=int(record_every), **{a.name: rec[a.name] for a in RECORD_ARRAYS},
                         record_pre=bool(record_pre), t=np.empty(0) if t_rec is None else t_rec)


def summary_bundle(inp: LoopInput, on: bool, rhos: tuple, R: int) -> "SummaryBundle":
    """The streaming summary's arrays (placeholders of the same types when ``on`` is False)."""

    S, n, m = inp.q0.shape[0], inp.stepper.system.n, inp.stepper.system.m
    Mq, Kq, Cq = quadratic_forms(inp.stepper) if on else (np.zeros((1, 1)),) * 3
    rho_arr = np.asarray(rhos, dtype=np.float64)
    k_on, k_off = coupling_samples(inp)
    summ = np.zeros((S, SUMMARY_FIELDS + 2 * rho_arr.size))
    summ[:, SUMMARY_FIELDS:] = -1.0
    return SummaryBundle(on=bool(on), k_on=int(k_on), k_off=int(k_off), rhos=rho_arr, summ=summ,
                         vprev=np.zeros((S, n)), Vprev=np.zeros(S), rec_V=np.zeros((S, R if on else 0)),
                         closings=np.zeros(m, np.int64), prev_act=np.zeros(m, np.bool_), Mq=Mq, Kq=Kq, Cq=Cq)


_NO_COUPLING, _NO_LOG = np.zeros(1, np.bool_), np.zeros((1, 1), np.bool_)


def window_bundle(inp: LoopInput, signals: "SignalBundle", kb: int, k1: int,
                  tw: np.ndarray | None) -> "WindowBundle":
    """The window of steps kb..k1: its waves, and (with observers; ``tw`` its grid points)
    the coupling and χ from a log."""

    st = inp.stepper
    waves = wave_table(st.t0, st.h, kb, k1, signals.omega, signals.phase, signals.function)
    if inp.q0.shape[0] == 1:
        return WindowBundle(kb=int(kb), waves=waves, coupled=_NO_COUPLING, chi_log=_NO_LOG, use_log=False)
    chi_w = inp.chi_window(tw, kb)
    return WindowBundle(kb=int(kb), waves=waves, coupled=np.ascontiguousarray(inp.coupled(tw), dtype=np.bool_),
                        chi_log=_NO_LOG if chi_w is None else np.ascontiguousarray(chi_w, dtype=np.bool_),
                        use_log=chi_w is not None)


def signal_tables(system) -> "SignalBundle":
    """The kernel's tables of the signals f(t), ν(t), ν̇(t) (:func:`observer.engines.compiled.kernel.advance`
    evaluates them at every grid point), as a :class:`observer.engines.compiled.bundles.SignalBundle`.

    ``(ω, phase, function)`` of the distinct waves (function codes
    :data:`~observer.engines.compiled.kernel.WAVE_COS`, ``WAVE_SIN``, ``WAVE_MINUS_SIN``); the entries
    ``(column, coefficient, wave)`` of f, then ν, then ν̇, each signal's in the summation
    order of :meth:`observer.model.Harmonic.entries` (``e_ptr`` (4,): signal i's entries are
    ``e_ptr[i]:e_ptr[i+1]``); the varying columns (those with an entry) of the three signals
    (``v_ptr``, ``v_col`` likewise); and the constants of f and ν. A wave shared by several
    entries (the same ω, phase and function) is evaluated once per grid point.
    """

    codes = {name: code for code, name in enumerate(WAVE_NAMES)}
    waves: dict[tuple, int] = {}
    cols, coefs, wave, e_ptr, v_col, v_ptr = [], [], [], [0], [], [0]
    for entries in (system.forcing.entries(), system.gap.entries(), system.gap.entries(derivative=True)):
        for col, coef, w, ph, fn in entries:
            cols.append(col)
            coefs.append(coef)
            wave.append(waves.setdefault((w, ph, codes[fn]), len(waves)))
        varying = sorted({col for col, *_ in entries})
        v_col += varying
        e_ptr.append(len(cols))
        v_ptr.append(len(v_col))
    wv = np.array(list(waves), dtype=float).reshape(-1, 3)
    i64 = lambda x: np.array(x, dtype=np.int64)  # noqa: E731
    return SignalBundle(omega=np.ascontiguousarray(wv[:, 0]), phase=np.ascontiguousarray(wv[:, 1]),
                        function=wv[:, 2].astype(np.int64), e_ptr=i64(e_ptr), e_col=i64(cols),
                        e_coef=np.array(coefs, dtype=float), e_wave=i64(wave), v_ptr=i64(v_ptr), v_col=i64(v_col),
                        f_c=np.ascontiguousarray(system.forcing.constant, dtype=float),
                        nu_c=np.ascontiguousarray(system.gap.constant, dtype=float))


SPECIALIZATIONS = ("general", "lean", "scalar")
"""The compiled loop's specializations, from the most general (:func:`specialization`)."""


def specialization(S: int, structure: int, summary: bool, record_pre: bool, master_projection: bool,
                   n: int, m: int) -> str:
    """Which compiled loop a run takes (each the same operations as the general one on what
    it runs: bitwise the same trajectory).

    ``"lean"``: the master alone, dense structure, no summary, no pre-projection records and
    no master projection (:func:`observer.engines.compiled.kernel.advance` with ``general=None``); ``"scalar"``:
    that case with one degree of freedom and one contact (:func:`observer.engines.compiled.kernel.advance_scalar`,
    the state in registers); ``"general"`` otherwise.
    """

    if not (S == 1 and structure == STRUCTURE_DENSE and not summary and not record_pre
            and not master_projection):
        return "general"
    return "scalar" if n == 1 and m == 1 else "lean"


def wave_table(t0: float, h: float, k0: int, k1: int, omega: np.ndarray, phase: np.ndarray,
               function: np.ndarray) -> np.ndarray:
    """The waves of :func:`signal_tables` at the grid points k0..k1: shape (waves, k1 − k0 + 1),
    entry ``[p, k − k0] = function_p(ω_p t_k + phase_p)``, the values of
    :func:`observer.model.grid_wave` (so of :meth:`observer.model.Harmonic.on_grid`) bit for
    bit: its anchors (:func:`observer.model.grid_anchors`, numpy) combined by the compiled
    :func:`observer.engines.compiled.kernel.fill_waves`."""

    P = omega.size
    out = np.empty((P, k1 - k0 + 1))
    if P == 0:
        return out
    anchors = [grid_anchors(t0, h, k0, k1, w, ph) for w, ph in zip(omega, phase)]
    ca, sa, cb, sb = (np.ascontiguousarray([a[i] for a in anchors], dtype=np.float64) for i in range(4))
    fill_waves(ca, sa, cb, sb, np.ascontiguousarray(function, dtype=np.int64), int(k0), out)
    return out


def quadratic_forms(stepper: MoreauJean) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """M, K and the symmetric part of C in the kernel's structure (dense or lower band).

    Always fresh writable C-contiguous copies: numba types a read-only array differently, so
    passing the scenario's (sometimes read-only) matrices as they are compiled a second
    specialization of the kernel in the middle of a timed run (12–17 s, seen in the bench's
    observer cases)."""
    sys_ = stepper.system
    C = 0.5 * (sys_.C + sys_.C.T)
    if stepper.S.band is None:
        return tuple(np.array(dense(A), dtype=np.float64, order="C", copy=True) for A in (sys_.M, sys_.K, C))
    bw = stepper.S.band.bw
    return tuple(np.array(to_band(A, bw), dtype=np.float64, order="C", copy=True) for A in (sys_.M, sys_.K, C))


def coupling_samples(inp: LoopInput) -> tuple[int, int]:
    """Grid samples k_on..k_off of the coupling window (t_on ≤ t_k ≤ t_off), as in
    :func:`observer.metrics.sync_time`; the whole run when not coupled to a window."""
    st = inp.stepper
    if inp.coupling is None or inp.self_driven:
        return 0, st.steps
    t_on, t_off = inp.coupling
    k_on = max(0, int(np.ceil((t_on - st.t0) / st.h - 1e-9)))
    while k_on > 0 and st.time(k_on - 1) >= t_on:
        k_on -= 1
    while k_on <= st.steps and st.time(k_on) < t_on:
        k_on += 1
    k_off = min(st.steps, int(np.floor((t_off - st.t0) / st.h + 1e-9)))
    while k_off < st.steps and st.time(k_off + 1) <= t_off:
        k_off += 1
    while k_off >= 0 and st.time(k_off) > t_off:
        k_off -= 1
    return k_on, k_off
