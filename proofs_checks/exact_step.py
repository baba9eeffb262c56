"""One step of ΔV, eq. (17), recomputed in exact rational arithmetic on the float states.

The floating-point states of a replay (:mod:`proofs_checks.runs`) are rational numbers.
:class:`ExactSteps` takes them as they are (python-flint ``fmpq``/``fmpq_mat``, no rounding)
and evaluates, for one step k of a pair (e = q_a − q_b, v = u_a − u_b), every term of the
discrete energy identity of :mod:`proofs_checks.lyapunov` exactly. The float states do not
satisfy the θ-scheme exactly; their *scheme residuals* (exact, from the states)::

    ρ_u = MΔv + hCv_θ + hKe_θ − WΔP,      ρ_q = Δe − hv_θ

(the forcing cancels in the difference of two members), with e_θ = (1−θ)e_k + θe⁻_{k+1},
enter the identity as the term ``R = v_θᵀρ_u + e_θᵀKρ_q``, so that, for symmetric M and K,
**exactly**::

    V_{k+1} − V_k = damping + impulse + numerical + projection + R.

``identity_defect`` = ΔV − (the four parts) − R is therefore exactly 0 (a proved identity,
not a float comparison). R is the round-off of the step, known exactly: it is not a
heuristic allowance.

The impulse part splits exactly (:mod:`proofs_checks.lyapunov`, Newton's law on
y = γ_{k+1} + Eγ_k per member, and Poisson on one contact, which is Newton's step) into::

    impulse = compl_sign + delassus + slack + R_impulse

with ``compl_sign = −½Σ_i (1 + D_i)(P₁⁺y₂⁺ + P₂⁺y₁⁺)_i ≤ 0`` (the cross products of the two
members' complementarity, non-positive by construction), ``delassus = −½ΔPᵀDĜΔP``,
``slack = −½ΔPᵀDδ`` (D = (I − E)(I + E)⁻¹, δ = −W_AᵀÂ⁻¹(hCv_k + hK(e_k + hθv_k)) = O(h))
and ``R_impulse`` the remainder (each member's own complementarity products P_iy_i, its
negative y or P, and the residual of γ_{k+1} = γ_free + ĜP: round-off). For Poisson on
several contacts the monotonicity term is Glocker's ``ΔPᵀΔγ̄_G`` (γ̄_G = γ̃ + ĜP/2), kept
whole as a sign part (≤ 0 when the impact map is monotone, A3; its own round-off is not
separated, since the replay keeps only the total impulse, not Glocker's two phases: a rise
on such a step whose Glocker term is positive by round-off alone would read as violated;
none occurs on the built-ins). The projection part splits
into ``projection_jump = −½‖Δg⁻‖²_{L_I⁻¹}`` (≤ 0), the plain master's unprojected gap
``½‖Δr‖²_{L_I⁻¹}`` (not counted: Proposition 1's mismatched pair) and ``R_projection`` (the
float projection's round-off). So, exactly::

    rise := ΔV − gap = signs + slack + roundoff

    signs    = damping + numerical + compl_sign + delassus + projection_jump   (≤ 0 for a valid system)
    slack    = slack (+ the Poisson target, 0)                                  (no sign, O(h))
    roundoff = R + R_impulse + R_projection                                     (exact)

and a rise of V on a step is explained by round-off iff ``signs + slack ≤ 0``, by the
discrete slack iff ``signs ≤ 0``, and is a violation otherwise (:func:`classify`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from flint import fmpq, fmpq_mat

ZERO = fmpq(0)
HALF = fmpq(1, 2)


def q(x: float) -> fmpq:
    """The float ``x`` as the rational it is (no rounding)."""
    n, d = float(x).as_integer_ratio()
    return fmpq(n, d)


def qmat(a: np.ndarray) -> fmpq_mat:
    """A float array as an exact rational matrix (a 1-D array as a column)."""
    a = np.asarray(a, dtype=float)
    if a.ndim == 1:
        a = a[:, None]
    r, c = a.shape
    return fmpq_mat(r, c, [q(x) for x in a.ravel()])


def dot(x: fmpq_mat, y: fmpq_mat) -> fmpq:
    """xᵀy of two columns."""
    return (x.transpose() * y)[0, 0] if x.nrows() else ZERO


def quad(x: fmpq_mat, A: fmpq_mat) -> fmpq:
    """xᵀAx."""
    return dot(x, A * x) if x.nrows() else ZERO


def rows(A: fmpq_mat, idx) -> fmpq_mat:
    """The rows ``idx`` of A."""
    idx = list(idx)
    return fmpq_mat(len(idx), A.ncols(), [A[i, j] for i in idx for j in range(A.ncols())])


def cols(A: fmpq_mat, idx) -> fmpq_mat:
    """The columns ``idx`` of A."""
    return rows(A.transpose(), idx).transpose()


def sub(x: fmpq_mat, idx) -> fmpq_mat:
    """Entries ``idx`` of a column."""
    return rows(x, idx)


SIGN_PARTS = ("damping", "numerical", "compl_sign", "delassus", "projection_jump", "impulse_unsplit")
"""Pieces of the rise that are ≤ 0 for a system satisfying the theorem's hypotheses."""

ROUNDOFF_PARTS = ("R_scheme", "R_impulse", "R_projection")
"""Pieces of the rise that are the floating-point states' residuals (exact)."""


@dataclass
class StepVerdict:
    """Classification of one exactly recomputed step (:func:`classify`).

    ``kind`` is ``"none"`` (no rise: ΔV − gap ≤ 0 exactly), ``"roundoff"`` (the rise is at
    most the exact round-off), ``"slack"`` (at most round-off plus the discrete slack) or
    ``"violated"`` (beyond both: ``unexplained`` > 0, ``cause`` the largest positive sign part).
    """

    kind: str
    rise: fmpq
    roundoff: fmpq
    slack: fmpq
    signs: fmpq
    unexplained: fmpq
    cause: str


def classify(parts: dict[str, fmpq], allowance: float = float("inf")) -> StepVerdict:
    """Three-valued verdict of a step from its exact parts (module docstring).

    ``allowance`` is the a priori floating-point bound of the step's round-off
    (:func:`proofs_checks.lyapunov.roundoff_allowance`): the exact round-off explains a rise
    only up to it (a larger residual is not round-off: a scheme that is not the θ-method, a
    projection that is not the K-metric one, a solver that violates complementarity).
    """
    rise = parts["total"] - parts["projection_unprojected_gap"]
    ro = sum((parts[k] for k in ROUNDOFF_PARTS), ZERO)
    sl = parts["slack"]
    signs = sum((parts[k] for k in SIGN_PARTS), ZERO)
    ro_p, sl_p = max(ro, ZERO), max(sl, ZERO)
    if ro_p > 0 and allowance < float("inf") and ro_p > q(allowance):
        ro_p = q(allowance)
    unexplained = rise - ro_p - sl_p
    cause = ""
    if rise <= 0:
        kind = "none"
    elif rise <= ro_p:
        kind = "roundoff"
    elif unexplained <= 0:
        kind = "slack"
    else:
        kind = "violated"
        cand = {k: parts[k] for k in SIGN_PARTS if parts[k] > 0}
        if ro > ro_p:
            cand["roundoff"] = ro - ro_p
        cause = max(cand, key=cand.get) if cand else "roundoff"
    return StepVerdict(kind, rise, ro, sl, signs, unexplained, cause)


class ExactSteps:
    """Exact recomputation of single steps of a replay (:class:`proofs_checks.runs.Run`).

    The system's matrices, h, θ, the restitution and the signals ν, ν̇ are taken as the
    rationals their floats are; Â = M + hθC + h²θ²K and K⁻¹ are formed and inverted exactly
    (once; the slices per active set are cached).
    """

    def __init__(self, run):
        s = run.system
        self.run = run
        self.n, self.m = s.n, s.m
        self.M, self.C, self.K, self.W = qmat(s.M), qmat(s.C), qmat(s.K), qmat(s.W)
        self.Cbar = (self.C + self.C.transpose()) * HALF
        self.h, self.th = q(run.h), q(run.theta)
        self.symmetric = bool(np.array_equal(s.M, s.M.T) and np.array_equal(s.K, s.K.T))
        self.e = [q(x) for x in np.broadcast_to(np.asarray(run.stepper.law.restitution, float), (s.m,))]
        self.newton = run.stepper.law.law == "newton"
        grid = run.stepper.grid
        self.nu, self.nu_dot = grid.nu, grid.nu_dot
        self._Ahat_inv = None
        self._Kinv = None
        self._sets: dict = {}

    # -- exact matrices --------------------------------------------------------------------
    @property
    def Ahat_inv(self) -> fmpq_mat:
        if self._Ahat_inv is None:
            h, th = self.h, self.th
            self._Ahat_inv = (self.M + self.C * (h * th) + self.K * (h * h * th * th)).inv()
        return self._Ahat_inv

    @property
    def Kinv(self) -> fmpq_mat:
        if self._Kinv is None:
            self._Kinv = self.K.inv()
        return self._Kinv

    def _set(self, kind: str, idx: tuple):
        key = (kind, idx)
        hit = self._sets.get(key)
        if hit is None:
            WA = cols(self.W, idx)
            if kind == "impulse":
                H = WA.transpose() * self.Ahat_inv            # W_AᵀÂ⁻¹
                hit = (WA, H, H * WA)                          # Ĝ = W_AᵀÂ⁻¹W_A
            else:
                hit = (WA, (WA.transpose() * self.Kinv * WA).inv())   # L_I⁻¹
            self._sets[key] = hit
        return hit

    # -- one step --------------------------------------------------------------------------
    def parts(self, A, B, k: int) -> dict[str, fmpq]:
        """Every exact term of step k (k → k+1) of the pair (A, B) (:class:`Trajectory`)."""
        M, K, W, h, th = self.M, self.K, self.W, self.h, self.th
        qa0, qa1, qam = qmat(A.q[k]), qmat(A.q[k + 1]), qmat(A.q_pre[k + 1])
        qb0, qb1, qbm = qmat(B.q[k]), qmat(B.q[k + 1]), qmat(B.q_pre[k + 1])
        ua0, ua1, ub0, ub1 = qmat(A.u[k]), qmat(A.u[k + 1]), qmat(B.u[k]), qmat(B.u[k + 1])
        Pa, Pb = qmat(A.P[k + 1]), qmat(B.P[k + 1])
        v0, v1, e0, e1, em = ua0 - ub0, ua1 - ub1, qa0 - qb0, qa1 - qb1, qam - qbm
        dP = Pa - Pb
        one = fmpq(1)
        v_th = v0 * (one - th) + v1 * th
        v_bar = (v0 + v1) * HALF
        e_th = e0 * (one - th) + em * th
        dv, de = v1 - v0, em - e0
        V0 = HALF * quad(v0, M) + HALF * quad(e0, K)
        V1 = HALF * quad(v1, M) + HALF * quad(e1, K)
        out: dict[str, fmpq] = {"V": V0, "V_next": V1, "total": V1 - V0}
        out["damping"] = -h * quad(v_th, self.Cbar)
        WdP = W * dP
        out["impulse"] = dot(v_bar, WdP)
        out["numerical"] = -(th - HALF) * (quad(dv, M) + quad(de, K) - dot(dv, WdP))
        out["projection"] = HALF * (quad(e1, K) - quad(em, K))
        rho_u = M * dv + self.C * v_th * h + K * e_th * h - WdP
        rho_q = de - v_th * h
        out["R_scheme"] = dot(v_th, rho_u) + dot(e_th, K * rho_q)
        out["identity_defect"] = (out["total"] - out["damping"] - out["impulse"] - out["numerical"]
                                  - out["projection"] - out["R_scheme"])
        for key in ("compl_sign", "delassus", "slack", "impulse_unsplit", "projection_jump",
                    "projection_unprojected_gap"):
            out[key] = ZERO
        self._impulse(A, B, k, v0, e0, dP, out)
        self._projection(A, B, k, qam, qbm, out)
        out["R_impulse"] = (out["impulse"] - out["compl_sign"] - out["delassus"] - out["slack"]
                            - out["impulse_unsplit"])
        out["R_projection"] = out["projection"] - out["projection_jump"] - out["projection_unprojected_gap"]
        # identity_defect is exactly 0 for symmetric M, K: keep the exact total consistent otherwise
        out["R_scheme"] += out["identity_defect"]
        return out

    def _impulse(self, A, B, k, v0, e0, dP, out) -> None:
        same = bool(np.array_equal(A.active[k + 1], B.active[k + 1]))
        if not same:                           # no split: the whole impulse term as a sign part
            out["impulse_unsplit"] = out["impulse"]
            return
        act = tuple(int(i) for i in np.flatnonzero(A.active[k + 1]))
        if not act:
            return
        h, th = self.h, self.th
        WA, H, G = self._set("impulse", act)
        E = [self.e[i] for i in act]
        D = [(1 - x) / (1 + x) for x in E]
        dPA = sub(dP, act)
        delta = -(H * (self.C * v0 * h + self.K * (e0 + v0 * (h * th)) * h))
        GdP = G * dPA
        out["slack"] = -HALF * sum((D[i] * dPA[i, 0] * delta[i, 0] for i in range(len(act))), ZERO)
        if not self.newton and len(act) > 1:
            # Glocker's term ΔPᵀΔγ̄_G, γ̄_G = γ̃ + ĜP/2, Δγ̃ = Δγ_k + δ/(1+E): a sign part (A3)
            dg0 = WA.transpose() * v0
            out["impulse_unsplit"] = sum((dPA[i, 0] * (dg0[i, 0] + delta[i, 0] / (1 + E[i]) + HALF * GdP[i, 0])
                                          for i in range(len(act))), ZERO)
            return
        out["delassus"] = -HALF * sum((D[i] * dPA[i, 0] * GdP[i, 0] for i in range(len(act))), ZERO)
        ya, yb = self._y(A, k, act, WA, E), self._y(B, k, act, WA, E)
        Pa = [q(A.P[k + 1, i]) for i in act]
        Pb = [q(B.P[k + 1, i]) for i in act]
        pos = lambda x: x if x > 0 else ZERO  # noqa: E731
        out["compl_sign"] = -HALF * sum(((1 + D[i]) * (pos(Pa[i]) * pos(yb[i]) + pos(Pb[i]) * pos(ya[i]))
                                         for i in range(len(act))), ZERO)

    def _y(self, X, k, act, WA, E) -> list:
        """y = γ_{k+1} + Eγ_k of member X on the active contacts (γ = Wᵀu + ν̇)."""
        g1 = WA.transpose() * qmat(X.u[k + 1])
        g0 = WA.transpose() * qmat(X.u[k])
        return [g1[j, 0] + q(self.nu_dot[k + 1, i]) + E[j] * (g0[j, 0] + q(self.nu_dot[k, i]))
                for j, i in enumerate(act)]

    def _projection(self, A, B, k, qam, qbm, out) -> None:
        if not (A.projected or B.projected):
            return
        idx = tuple(int(i) for i in np.flatnonzero(A.active[k + 1] & B.active[k + 1]))
        if not idx:
            return
        WI, Linv = self._set("projection", idx)
        nu = qmat(self.nu[k + 1, list(idx)])
        gA, gB = WI.transpose() * qam + nu, WI.transpose() * qbm + nu
        dg = gA - gB
        zero = fmpq_mat(len(idx), 1)
        dr = (zero if A.projected else gA) - (zero if B.projected else gB)
        out["projection_jump"] = -HALF * quad(dg, Linv)
        out["projection_unprojected_gap"] = HALF * quad(dr, Linv)
