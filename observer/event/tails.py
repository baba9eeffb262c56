"""Joint Zeno tails: several contacts accumulating impacts at the same time (issue 19).

A run of impacts that alternates between contacts (a flat body settling on two supports,
two bodies landing together, a contact re-launched by the other's impacts and accumulating
again between them) has no geometric run of one contact set, so
:meth:`observer.event.master._Run.zeno_check` never extrapolates it, and resolving it until
the hops reach the gap's round-off (:meth:`~observer.event.master._Run.land`) puts the
accumulation time where the coordinates' round-off (|q| + |ν|) cuts the sequence: up to
1e-5 s apart under a translation of coordinates.

The same holds for one contact bouncing on a held set (a ball whose neighbour already rests,
the chain's blocks), which was landed likewise.

What the engine does instead (:func:`joint_tail`): once one of the impacting contacts is
resolved as far as its gap's representation allows (its next hop not certainly above the
gap's certified error, :meth:`~observer.event.master._Run.hop_error`; or the gap's round-off
over its speed, plus the time resolution, carrying more than the cluster's share of the
stated accuracy ``zeno_time_rtol·(t − t0)`` into t_∞: :func:`joint_due`), the tail of the
whole cluster — that contact and every open contact landing within a few of its tail lengths — is resolved by **exact hops relative to the
contact points**: each contact carries its own gap ``d_c`` (0 exactly after its impact, the
gap's value at the start for the others), advanced by the Taylor polynomial of its
increment ``Σ_{k≥1} g_c^{(k)} Δ^k/k!`` (degree :data:`HOP_ORDER`, the flow's exact
derivatives, which do not carry |q| or |ν|), never re-read from the coordinates. The
first landing is an impact of the run's law on the held set and the landing contact(s);
a held contact that the impact lifts re-enters the cluster at d = 0; a contact whose next
hop is within the time coordinate's resolution (:func:`observer.event.roots.time_resolution`,
two ulp of t; decided from an enclosure of the hop's duration, :func:`hop_within`) is held
(its remaining tail is below it too) if the acceleration LCP keeps its force positive. When every contact of the
cluster is held, their common accumulation time t_∞ is reached. The tail lists what it
resolves, as the event loop would: each impact, a held contact lifted by a hop above the
time resolution (``liftoff``), each hold (``stick``), note ``joint tail of contacts …: exact
hop``; each contact's last hold is an ``accumulation`` row and its ``stick`` row, the note
saying ``joint tail of contacts …: N impacts resolved by exact hops from the contact
points``. A tail that runs past t_end lists its events before t_end, and an accumulation
row's impulse is its contact's up to t_end (:attr:`JointTail.until_end`). Where the tail starts
depends on the coordinates (the trigger reads the gap's round-off); what it lists does not.
Its error is the gaps' round-off at the start over the cluster's speeds, which the trigger
keeps, to first order, within ``zeno_time_rtol·(t − t0)`` (``run_master``'s stated accuracy,
:meth:`~observer.event.master._Run.time_budget`) for one contact and within 1/k² of it for
each contact of a cluster of k (:func:`joint_due`: each contact's location error enters its own
rest and the re-launch of each of the other k − 1, k² terms of the common t_∞); interleaved
accumulations of coupled contacts can amplify it beyond those k² terms (each landing decides
the other's re-launch, again and again): there the stated accuracy is a first-order target,
not a bound (tests/observer/event/test_joint_tails.py holds clusters of 2 and 3 contacts to it
at settings where they meet it).
If a tail does not converge (a hop that is not a falling-back arc, a held force that
vanishes, more than :data:`TAIL_HOPS` hops) or another contact's event falls inside it,
:func:`joint_tail` returns None and the sequence is resolved, and landed, as before.
"""

from __future__ import annotations

from dataclasses import dataclass

import flint
import numpy as np

from observer.event.flow import Flow, flow_for
from observer.event.enclosures import Decision, _refine, arb_dot, coupled, gamma
from observer.event.roots import RootIsolationError, first_zero, time_resolution
from observer.impact import impact

HOP_ORDER = 8
"""Degree of the Taylor polynomial of a hop. A hop whose truncation is not certainly below the
polynomial's own float64 evaluation error (:func:`taylor_holds`) ends the joint tail (None)."""

TAIL_HOPS = 20_000
"""Hops after which a joint tail that has not converged is abandoned (None)."""

CLUSTER_REACH = 4.0
"""An open contact joins the cluster if it lands within this many tail lengths
``2γ⁺/(α(1 − e))`` of the impacting contact (the hop sum of a constant acceleration)."""

@dataclass
class JointTail:
    """A converged joint tail: the time every contact of the cluster is held (t_∞), the state
    there (held set projected), the held set, the impulse of each contact over the tail
    (impacts and held forces), the count of impacts resolved by hops, and the time each
    contact of the cluster was held for the last time (its own accumulation time; a held
    contact that an impact lifts by a hop below the time resolution is held again at once,
    and rests from there: every impact of another contact that re-launches it counts)."""

    t_inf: float
    x: np.ndarray
    held: tuple
    impulse: np.ndarray
    hops: int
    settled: dict
    rows: list
    """The tail's events in order, ``(time, contact, kind, γ⁻, γ⁺, impulse, note)``: every impact
    it resolves, a held contact lifted by a hop it resolves (``liftoff``), a contact held
    (``stick``) but for its last hold (``settled``), which the accumulation rows state; the
    note states a decision left undecided at the precision cap, with its enclosure, else ""."""
    until_end: np.ndarray
    """The impulse of each contact from the tail's start to the run's t_end: the impacts before
    t_end and the held forces' ∫λ dt up to t_end (``impulse`` itself when t_∞ < t_end)."""


def _rows(flow: Flow, c: int) -> np.ndarray:
    """Rows of g_c', g_c'', …, g_c^(HOP_ORDER) on ``flow`` (cached on the flow)."""
    cache = flow.__dict__.setdefault("_hop_rows", {})
    if c not in cache:
        R = [flow.velocity_rows[c]]
        for _ in range(HOP_ORDER - 1):
            R.append(R[-1] @ flow.A)
        cache[c] = np.array(R)
    return cache[c]


_FACT = np.cumprod(np.arange(1, HOP_ORDER + 1, dtype=float))


def taylor_holds(flow: Flow, c: int, z: np.ndarray, d: float, D: np.ndarray, dt: float) -> bool:
    """Whether the hop polynomial ``p(Δ) = d + Σ_{k≤K} D_k Δ^k/k!`` (K = :data:`HOP_ORDER`) of
    contact c is the flow's relative gap over ``[0, dt]`` to within its own float64 evaluation
    error: the Lagrange remainder ``|g_c^{(K+1)}(ξ)| dt^{K+1}/(K+1)!``, bounded by
    ``‖r A_S^{K}‖₁·e^{‖A_S‖∞ dt}‖z_S‖∞`` (r A^K the row of g_c^{(K+1)}, S the components it
    depends on, :func:`observer.event.enclosures.coupled`: a mode it does not see does not
    shorten the hop), is at most ``γ_{2K+2}·(|d| + Σ|D_k| dt^k/k!)`` (Horner's bound,
    Higham §5.1). Zero remainder (a polynomial motion: free fall) holds for any dt. Not a
    time scale of the system: the hop's own data decide."""
    cache = flow.__dict__.setdefault("_hop_remainder", {})
    if c not in cache:
        top = _rows(flow, c)[-1] @ flow.A              # row of g_c^(K+1)
        S = coupled(flow.A, top != 0.0)
        normA = float(np.max(np.abs(flow.A[np.ix_(S, S)]).sum(axis=1))) if S.any() else 0.0
        cache[c] = (float(np.abs(top).sum()), S, normA)
    top, S, normA = cache[c]
    if top == 0.0:
        return True
    k = HOP_ORDER + 1
    bound = top * float(np.max(np.abs(z[S]))) * np.exp(normA * dt) * dt ** k / (_FACT[-1] * k)
    terms = abs(d) + float(np.abs(D) @ (dt ** np.arange(1, HOP_ORDER + 1) / _FACT))
    g = gamma(2 * HOP_ORDER + 2)
    return bool(bound * (1.0 + 4.0 * g) <= g * terms)


def landing(d: float, D: np.ndarray) -> float:
    """First Δ > 0 with ``p(Δ) = d + Σ_k D_k Δ^k/k! = 0`` (D = g', g'', …; d ≥ 0): Newton
    from the parabola's root (on p(Δ)/Δ when d = 0: the contact point itself is no root);
    inf if the arc does not come back, nan if Newton leaves the arc."""
    co = D / _FACT[:D.size]
    if d <= 0.0:
        if D[0] <= 0.0:
            return np.nan                              # at the contact point, not leaving
        if D[1] >= 0.0:
            return np.inf
        poly, dt = co, -2.0 * D[0] / D[1]
    else:                                          # stable root of d + D₀s + D₁s²/2
        disc = D[0] * D[0] - 2.0 * D[1] * d
        den = -D[0] + np.sqrt(disc) if disc >= 0.0 else 0.0
        if den <= 0.0:
            return np.inf
        poly, dt = np.concatenate([[d], co]), 2.0 * d / den
    dpoly = (poly[1:] * np.arange(1, poly.size))[::-1].tolist()
    poly = poly[::-1].tolist()
    for _ in range(40):
        step = np.float64(horner(poly, dt)) / horner(dpoly, dt)   # numpy's division: 0 → inf
        dt -= step
        if not np.isfinite(dt) or dt <= 0.0:
            return np.nan
        if abs(step) <= 4e-16 * dt:
            break
    return float(dt)


def advance(d: float, D: np.ndarray, dt: float) -> float:
    """The relative gap ``d + Σ_k D_k dt^k/k!`` after a flight of dt."""
    return float(d + dt * horner((D / _FACT)[::-1].tolist(), dt))


def horner(coefficients: list, x: float) -> float:
    """``np.polyval(coefficients, x)`` for a float x (highest degree first): the same Horner
    recurrence ``y = y·x + c`` from y = 0, on Python floats (no array per call)."""
    y = 0.0
    for c in coefficients:
        y = y * x + c
    return y


def representation(rows: np.ndarray, z: np.ndarray) -> np.ndarray:
    """``eps·Σ_j |r_ij z_j|``: the representation error δg of each functional ``rows @ z``
    (it grows with |q| and |ν|), over which an impact's location error is δg/γ⁺
    (:func:`joint_due`, :meth:`observer.event.master._Run.noisy_tail`)."""
    return np.finfo(float).eps * (np.abs(rows) @ np.abs(z))


def joint_due(run, key: tuple, t: float, x: np.ndarray, held: tuple, tiny: list) -> list | None:
    """The cluster whose joint tail starts after the impact of ``key`` at t (state x, held
    set ``held``), or None if it is not due: due once a contact of key is resolved as far as
    its gap's representation allows (``tiny``: its next hop is within the gap's certified
    error, :meth:`~observer.event.master._Run.tiny_hops`; or the location error of its impact,
    the gap's round-off δg over its speed γ⁺ plus the time resolution δt
    (:func:`observer.event.roots.time_resolution`), puts more than its share of the stated
    accuracy into the tail, ``(1 + 2/(1 − e))·(δg/γ⁺ + δt) ≥ run.time_budget(t)/k²``, as
    :meth:`~observer.event.master._Run.noisy_tail` does for k = 1; or, for a key of several
    contacts landing together, a next hop ``γ⁺²/(2|γ̇|)`` no higher than the gap an impact
    would land together with them, :meth:`~observer.event.master._Run.merge_band`: below it
    event-by-event impacts merge the contacts' landings by the carried error, the joint tail
    resolves them from the contact points). The cluster is key and
    every open contact landing within :data:`CLUSTER_REACH` tail lengths ``2γ⁺/(α(1 − e))``
    (parabolic estimate); its k contacts share the budget ``zeno_time_rtol·(t − t0)``
    (:meth:`~observer.event.master._Run.time_budget`) as k² first-order terms of the common
    t_∞: each contact's location error enters its own rest and, through the coupling, the
    re-launch of each of the other k − 1 (the interleaved accumulations of issue 19, whose
    contacts carry their location errors into each other's flights). (It was 1/16 of the
    budget for any k > 1, the share at k = 4; the translated interleaved pair of
    tests/observer/event/test_invariance.py, which that factor was set on, rests within
    1e-9 s of its 30-digit t_∞ with 1/k², as the test asserts.)"""
    fl = flow_for(run.system, held)
    z = fl.z(t, x)
    g, v = fl.gap_rows @ z, fl.velocity_rows @ z
    a = (fl.velocity_rows @ fl.A) @ z
    dg = representation(fl.gap_rows, z)
    e = np.asarray(run.law.restitution, dtype=float)
    reach = 0.0
    for c in key:
        if not (a[c] < 0.0 and v[c] > 0.0 and 0.0 <= e[c] < 1.0):
            return None
        reach = max(reach, CLUSTER_REACH * 2.0 * v[c] / (-a[c] * (1.0 - e[c])))
    cluster = list(key)
    for b in range(run.m):
        if b in key or b in held:
            continue
        s = landing(max(g[b], 0.0), np.array([v[b], a[b]]))
        if s <= reach or (g[b] <= 0.0 and np.isnan(s)):
            cluster.append(b)
    share = run.time_budget(t) / len(cluster) ** 2      # k² terms share the budget
    due = bool(tiny)
    merged = run.merge_band(t, x) if len(key) > 1 else None   # what an impact lands together
    for c in key:
        due |= (1.0 + 2.0 / (1.0 - e[c])) * (dg[c] / v[c] + time_resolution(t)) >= share
        due |= len(key) > 1 and v[c] * v[c] <= 2.0 * -a[c] * merged[c]
    return sorted(cluster) if due else None


def joint_tail(run, t: float, x: np.ndarray, held: tuple, cluster: list, key: tuple
               ) -> JointTail | None:
    """Resolve the tail of ``cluster`` after the impact of ``key`` at t (state x after it,
    contacts ``held`` held) by exact hops relative to the contact points (module docstring):
    the JointTail once every contact of the cluster is held, None if it does not converge or
    another contact's event falls inside it."""
    g0 = flow_for(run.system, held).gaps(t, x)
    d = {c: (0.0 if c in key else max(float(g0[c]), 0.0)) for c in cluster if c not in held}
    held = held0 = tuple(sorted(held))
    x0 = x
    impulse = np.zeros(run.m)
    until_end = None                                        # the impulse up to t_end
    tail, hops, settled, rows = 0.0, 0, {}, []
    while hops < TAIL_HOPS:
        if all(c in held for c in cluster):
            last = {(s, c) for c, s in settled.items()}        # stated by the accumulation rows
            rows = [r for r in rows if not (r[2] == "stick" and (r[0], r[1]) in last)]
            out = JointTail(t + tail, x, held, impulse, hops, settled, rows,
                            impulse if until_end is None else until_end)
            return out if _clear(run, t, x0, held0, cluster, out.t_inf) else None
        fl = flow_for(run.system, held)
        z = fl.z(t + tail, x)
        if held and np.any(fl.force_rows @ z <= 0.0):
            return None                                     # a held force vanishes: not a tail
        D = {c: _rows(fl, c) @ z for c in d}
        s = {c: landing(d[c], D[c]) for c in d}
        if not d or any(np.isnan(v) for v in s.values()):
            return None
        dt = min(s.values())
        if not np.isfinite(dt) or not all(taylor_holds(fl, c, z, d[c], D[c], dt) for c in d):
            return None
        if until_end is None and t + (tail + dt) >= run.t_end:   # this hop reaches t_end:
            until_end = impulse.copy()                  # its impact (at t + tail after it, not
            if held:                                    # before t_end) and ∫λ past t_end are out
                until_end[list(held)] += fl.force_rows @ fl.integral(run.t_end - (t + tail), z)
        if held:                                            # ∫λ dt of the held forces
            impulse[list(held)] += fl.force_rows @ fl.integral(dt, z)
        x = fl.x_of(fl.propagate(t + tail, z, dt))
        tail += dt
        res = time_resolution(t + tail)
        landed = [c for c in d if s[c] - dt <= res]
        for c in d:
            d[c] = 0.0 if c in landed else max(advance(d[c], D[c], dt), 0.0)
        x, new, lifted = _hop_impact(run, t + tail, x, held, landed, d, impulse, res, rows)
        if x is None:
            return None
        # held from here on: contacts that landed, and held ones the impact lifted by a hop
        # below the time resolution (held again at once: they rest from here, not from before)
        settled.update({c: t + tail for c in new if c not in held or c in lifted})
        held = new
        hops += 1
    return None


def hop_within(fl: Flow, c: int, z: np.ndarray, res: float, notes: dict | None = None) -> bool:
    """Whether the next hop of contact c from the contact point, ``2γ⁺/α`` (γ⁺ = g_c'·z,
    α = −g_c''·z > 0 on ``fl``), lasts no longer than ``res`` (the time coordinate's
    resolution, :func:`observer.event.roots.time_resolution`): the sign of
    ``w = −res·g_c''·z − 2·g_c'·z`` (w ≥ 0: within), decided from its enclosure — float64 with
    the certified bound γ_N·(res·Σ|g_c'' z| + 2·Σ|g_c' z|) first, else ball arithmetic at
    doubling precision from the same data (:func:`observer.event.enclosures._refine`, exact
    for float64 data at the cap). No count of round-offs decides it. Undecided at the cap:
    not within (the contact keeps hopping), and the enclosure goes to ``notes[c]`` (the note
    of the contact's event row at this impact)."""
    vr, ar = _rows(fl, c)[0], _rows(fl, c)[1]
    w = -res * float(ar @ z) - 2.0 * float(vr @ z)
    g = gamma(z.size + 2)
    err = (res * float(np.abs(ar) @ np.abs(z)) + 2.0 * float(np.abs(vr) @ np.abs(z))) \
        * g * (1.0 + 2.0 * g) + z.size * 5e-324
    if np.isfinite(w) and np.isfinite(err) and abs(w) > err:
        return w > 0.0
    dec = _refine(lambda: -arb_dot(ar, z) * res - 2 * arb_dot(vr, z))
    if dec.sign is None and notes is not None:
        notes[c] = f"contact {c}: hop within the time resolution {dec.note}"
    return dec.sign is not None and dec.sign >= 0


def leaves(run, t: float, x_before: np.ndarray, x: np.ndarray, A: list, lam: np.ndarray,
           c: int, held: bool = False) -> Decision:
    """Sign of contact c's velocity after the impulses ``lam`` on the contacts A took the state
    from ``x_before`` to ``x`` (``u ← u + M⁻¹W_A λ``): +1 when it certainly leaves its contact
    point. The quantity is the exact velocity of the jump from the float64 data (the state
    before, λ, M⁻¹, W), ``r·z(x_before) + r_u·M⁻¹W_A λ``; its float64 value ``r·z(x)`` is
    enclosed by the certified bound of its evaluation, γ_{N+1}·Σ|r z|, plus the rounding of
    the jump seen through r, ``|r_u|·γ_{n+|A|+1}(|M⁻¹||W_A||λ| + |u|)`` (as
    :meth:`observer.event.master._Run.jump_error`); where that contains 0, ball arithmetic at
    doubling precision from the same data (:func:`observer.event.enclosures._refine`). No
    count of round-offs of the impact speed decides it (it was 1e3·eps·max|γ⁻|).

    ``held``: c was held before the impact, so its velocity was exactly 0 (the held flow
    keeps γ_c = 0; the float state's γ_c is that flow's round-off, ~1e-17, not motion), and
    the velocity after is the jump's alone, ``r_u·M⁻¹W_A λ`` (an impact of a decoupled contact
    lifts no held contact)."""
    fl, n = run.free_flow, run.n
    r = fl.velocity_rows[c]
    W = run.system.W[:, list(A)]
    if held:
        return _jump_sign(r[n:2 * n], run.Minv, W, lam)
    z = fl.z(t, x)
    ru = np.abs(r[n:2 * n])
    g = gamma(n + len(A) + 1)
    jump = g * (np.abs(run.Minv) @ (np.abs(W) @ np.abs(lam)) + np.abs(x[n:]))
    gz = gamma(z.size + 1)
    val = float(r @ z)
    err = (float(np.abs(r) @ np.abs(z)) * gz + float(ru @ jump)) * (1.0 + 2.0 * gz) \
        + z.size * 5e-324
    if np.isfinite(val) and np.isfinite(err) and abs(val) > err:
        return Decision(1 if val > 0.0 else -1, val - err, val + err, 53)
    zb = fl.z(t, x_before)
    return _refine(lambda: arb_dot(r, zb) + _arb_jump(r[n:2 * n], run.Minv, W, lam))


def _jump_sign(ru: np.ndarray, Minv: np.ndarray, W: np.ndarray, lam: np.ndarray) -> Decision:
    """Sign of ``ru·M⁻¹·W·λ`` (float64 data): float64 with its certified bound
    γ_{n+k+2}·|ru|·|M⁻¹|·|W|·|λ|, else :func:`_arb_jump` at doubling precision."""
    val = float(ru @ (Minv @ (W @ lam)))
    g = gamma(Minv.shape[0] + W.shape[1] + 2)
    err = float(np.abs(ru) @ (np.abs(Minv) @ (np.abs(W) @ np.abs(lam)))) * g * (1.0 + 2.0 * g) \
        + (Minv.shape[0] + W.shape[1]) * 5e-324
    if np.isfinite(val) and np.isfinite(err) and abs(val) > err:
        return Decision(1 if val > 0.0 else -1, val - err, val + err, 53)
    return _refine(lambda: _arb_jump(ru, Minv, W, lam))


def _arb_jump(ru: np.ndarray, Minv: np.ndarray, W: np.ndarray, lam: np.ndarray):
    """``ru·M⁻¹·W·λ`` of float64 data in ball arithmetic (the current precision)."""
    wl = [arb_dot(row, lam) for row in np.asarray(W, dtype=float)]
    s = flint.arb(0)
    for i, a in enumerate(np.asarray(ru, dtype=float).tolist()):
        if a != 0.0:
            s += flint.arb(a) * sum((flint.arb(float(m)) * w for m, w in zip(Minv[i], wl)
                                     if m != 0.0), flint.arb(0))
    return s


def _hop_impact(run, t: float, x: np.ndarray, held: tuple, landed: list, d: dict,
                impulse: np.ndarray, res: float, rows: list):
    """The impact of the law at a landing of ``landed`` on the held set (generalized Newton,
    eq. (5), on A = held ∪ landed); held contacts it lifts re-enter d at 0; a landed contact
    whose next hop ``2γ⁺/α`` is below the time resolution ``res`` is held if the acceleration
    LCP keeps its force. Appends the impact's events to ``rows`` (the landed contacts'
    impacts, ``liftoff`` of a held contact lifted by a hop above the resolution, ``stick`` of a
    contact held now; a held contact lifted and held again at once, by a hop below the
    resolution, has none). Returns (x, held, lifted: the held contacts the impact lifted), or
    (None, None, None) if the state is not a tail."""
    A = sorted(set(held) | set(landed))
    idx = np.array(A, dtype=int)
    gm = run.free_flow.velocities(t, x)[idx]
    if not np.any(gm < 0.0):
        return None, None, None
    lam = np.maximum(impact(run.law, run.delassus(A), gm, idx, run.solve), 0.0)
    x_before, x = x, x.copy()
    x[run.n:] += run.velocity_jump(A, lam)
    impulse[A] += lam
    rises = {}

    notes: dict = {}

    def rising(c: int) -> bool:                   # undecided at the cap: not leaving
        if c not in rises:
            rises[c] = leaves(run, t, x_before, x, A, lam, c, c in held)
            if rises[c].sign is None:
                notes[c] = f"contact {c}: leaving its contact point {rises[c].note}"
        return rises[c].sign == 1
    keep = [c for c, l in zip(A, lam) if c in held and (l > 0.0 or not rising(c))]
    lifted = [c for c in held if c not in keep]
    for c in lifted:
        d[c] = 0.0                                          # lifted by the impact
    fl = flow_for(run.system, tuple(keep))
    z = fl.z(t, x)
    a = (fl.velocity_rows @ fl.A) @ z
    at_contact = sorted(set(landed) | {c for c in d if d[c] == 0.0})   # lifted ones too
    settle = [c for c in at_contact
              if not rising(c) or (a[c] < 0.0 and hop_within(fl, c, z, res, notes))]
    if settle:
        stick = run.sticking(t, x, sorted(set(keep) | set(settle)))
        if not set(settle) <= set(stick):
            return None, None, None
        keep = stick
    for c in keep:
        d.pop(c, None)
    x = run.project(t, x, list(keep))
    gp = run.free_flow.velocities(t, x)[idx]
    first = len(rows)
    for c, before, after, lc in zip(A, gm, gp, lam):
        if c in landed:
            rows.append((t, c, "impact", before, after, lc, notes.pop(c, "")))
        elif c in lifted and c not in keep:
            rows.append((t, c, "liftoff", before, after, lc, notes.pop(c, "")))
        if c in keep and c not in held:
            rows.append((t, c, "stick", after, after, 0.0, notes.pop(c, "")))
    if notes and len(rows) > first:                # a contact without a row of its own here
        row = rows[first]
        rows[first] = (*row[:6], "; ".join(filter(None, [row[6], *notes.values()])))
    return x, tuple(sorted(keep)), lifted


def _clear(run, t: float, x: np.ndarray, held: tuple, cluster: list, t_inf: float) -> bool:
    """No event of a contact outside the cluster and the held set in ``[t, t_∞]`` (searched on
    the flow holding them from the tail's start: the tail's hops are below resolution there)."""
    others = [j for j in range(run.m) if j not in held and j not in cluster]
    if not others or t_inf <= t:
        return True
    fl = flow_for(run.system, held)
    xp = run.project(t, x, list(held))
    try:
        zero, _, _ = first_zero(fl, fl.gap_rows[others], t, fl.z(t, xp), min(t_inf, run.t_end))
    except RootIsolationError:
        return False
    return zero is None
