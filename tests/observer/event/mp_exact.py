"""An independent high-precision event-driven reference (mpmath, DPS digits) of the master's
exact flow, for systems with a constant gap offset ν and harmonic forcing (issue 19).

It shares no code with :mod:`observer.event`: the augmented state ``z = (q, u, cos ω_k t,
sin ω_k t, …, 1)`` follows ``ż = A_P z`` with A_P built here from M, C, K, W and the forcing
(the contacts P held: their force λ_P keeps ``W_Pᵀu̇ = 0``); ``z(t + s) = Σ_k A_P^k z s^k/k!``
(the Taylor series, summed to DPS + 5 digits over steps with ‖A_P‖·s ≤ 1). The next event is
the first s > 0 where a gap of an open contact or a force of a held contact crosses zero
downwards, isolated on the same series: an interval is cleared when the value exceeds the sum
of the series' remaining terms over it, or when the function is monotone there (|f'| above
the bound of its change) without a downward sign change; a bracketed root is refined by
bisection-safeguarded Newton to ``ROOT_TOL`` relative. Impacts: generalized Newton
(eq. (5)) by enumeration of the LCP on the held set and the landing contact; a contact whose
γ⁺ is below ``v_hold`` (relative to the motion) is held if the acceleration LCP gives the
held set positive forces, after its remaining Zeno tail ``2γ⁺/(α(1 − e))`` (docs/theory/oracles.md §1)
flown on the held flow (≤ 2·v_hold/(α(1 − e)) s, error O(α̇/α·tail²)). Keep v_hold ≤ 1e-12
where two contacts' accumulations interleave (a contact held while the other still bounces
re-launches: 1e-9 made the reference penetrate on one such system).
"""

from __future__ import annotations

import itertools

import mpmath as mp
import numpy as np

DPS = 30
ROOT_TOL = mp.mpf(10) ** -25


def _m(a):
    """An object array of mpf (mpmath numbers) from floats (exact: a float is a dyadic)."""
    return np.vectorize(lambda v: mp.mpf(float(v)), otypes=[object])(np.asarray(a, dtype=float))


def _solve(A, b):
    """Solve A x = b (object arrays of mpf) with mpmath's LU."""
    x = mp.lu_solve(mp.matrix(A.tolist()), mp.matrix(list(b)))
    return np.array([x[i] for i in range(len(b))], dtype=object)


class Reference:
    """The exact flow of ``system`` (a :class:`observer.model.LinearSystem` with constant ν)
    with restitution e (per contact), from q0, u0 at t0; :meth:`run` lists the events."""

    def __init__(self, system, e, q0, u0, t0=0.0, v_hold=1e-12, dps=DPS, held=()):
        self.dps = dps
        with mp.workdps(dps):
            if np.any(np.asarray(system.gap.amplitude) != 0.0):
                raise ValueError("the reference takes a constant gap offset only")
            self.n, self.m = system.n, system.m
            self.M, self.C, self.K = _m(system.M), _m(system.C), _m(system.K)
            self.W, self.nu = _m(system.W), _m(system.gap.constant)
            self.f0 = _m(system.forcing.constant)
            self.amp, self.ph = _m(system.forcing.amplitude), _m(system.forcing.phase)
            self.om = _m(system.forcing.omega)
            self.e = _m(np.broadcast_to(np.asarray(e, dtype=float), (self.m,)))
            self.Minv = np.array(mp.inverse(mp.matrix(self.M.tolist())).tolist(), dtype=object)
            self.t = mp.mpf(float(t0))
            F = len(self.om)
            osc = []
            for k in range(F):
                osc += [mp.cos(self.om[k] * self.t), mp.sin(self.om[k] * self.t)]
            self.z = np.array(list(_m(q0)) + list(_m(u0)) + osc + [mp.mpf(1)], dtype=object)
            self.N = self.z.size
            self.v_hold = mp.mpf(v_hold)
            self.held: list[int] = sorted(held)
            self._A: dict = {}

    # -- the flow ----------------------------------------------------------------------------
    def _force_map(self):
        """(n × N) map of z to the applied force f(t) − Kq − Cu."""
        n, N = self.n, self.N
        Fm = np.full((n, N), mp.mpf(0), dtype=object)
        Fm[:, :n], Fm[:, n:2 * n] = -self.K, -self.C
        for k in range(len(self.om)):        # a cos(ωt + φ) = a cos φ cos ωt − a sin φ sin ωt
            for i in range(n):
                Fm[i, 2 * n + 2 * k] += self.amp[k, i] * mp.cos(self.ph[k, i])
                Fm[i, 2 * n + 2 * k + 1] -= self.amp[k, i] * mp.sin(self.ph[k, i])
        Fm[:, -1] = self.f0
        return Fm

    def force_rows(self, P):
        """Rows (|P| × N) of the held contacts' forces λ_P(z): W_Pᵀ u̇ = 0."""
        if not P:
            return np.zeros((0, self.N), dtype=object)
        WP = self.W[:, P]
        G = WP.T @ self.Minv @ WP
        Fm = self._force_map()
        return np.array([_solve(G, -(WP.T @ self.Minv @ Fm)[:, c]) for c in range(self.N)],
                        dtype=object).T

    def A(self, P):
        """ż = A_P z with the contacts P held."""
        key = tuple(P)
        if key not in self._A:
            n, N = self.n, self.N
            A = np.full((N, N), mp.mpf(0), dtype=object)
            for i in range(n):
                A[i, n + i] = mp.mpf(1)
            Fm = self._force_map()
            if P:
                Fm = Fm + self.W[:, P] @ self.force_rows(P)
            A[n:2 * n, :] = self.Minv @ Fm
            for k in range(len(self.om)):
                c, s = 2 * n + 2 * k, 2 * n + 2 * k + 1
                A[c, s], A[s, c] = -self.om[k], self.om[k]
            self._A[key] = A
        return self._A[key]

    def gap_rows(self):
        R = np.full((self.m, self.N), mp.mpf(0), dtype=object)
        R[:, :self.n] = self.W.T
        R[:, -1] = self.nu
        return R

    def vel_rows(self):
        R = np.full((self.m, self.N), mp.mpf(0), dtype=object)
        R[:, self.n:2 * self.n] = self.W.T
        return R

    @staticmethod
    def _series(A, z, h):
        """The Taylor terms V_k = A^k z / k! until V_k h^k falls below 10^-(dps+5)·|z|."""
        V, k = [z], 0
        scale = max(abs(v) for v in z)
        while True:
            k += 1
            V.append(A @ V[-1] / k)
            if max(abs(v) for v in V[-1]) * h ** k <= mp.mpf(10) ** (-mp.mp.dps - 5) * scale \
                    and k > 2:
                return V

    # -- events ----------------------------------------------------------------------------
    def _rows(self):
        open_ = [j for j in range(self.m) if j not in self.held]
        Rg = self.gap_rows()[open_]
        Rf = self.force_rows(self.held)
        return list(zip([("g", j) for j in open_] + [("f", j) for j in self.held],
                        list(Rg) + list(Rf)))

    def next_event(self, t_end, skip):
        """Advance to the first downward zero before t_end (→ (kind, contact)) or to t_end
        (→ None). ``skip``: rows (kind, contact) at a zero at the start: no root counted on
        their first ``s_min`` (where their Taylor model is below 100 round-offs)."""
        A = self.A(self.held)
        rows = self._rows()
        norm = max(sum(abs(a) for a in row) for row in A) + 1
        hmax = 1 / norm
        s_min = {}
        for key, r in rows:
            if key in skip:
                V = self._series(A, self.z, hmax)
                f = [r @ v for v in V]
                noise = mp.mpf(10) ** (2 - self.dps) * sum(abs(a * b) for a, b in zip(r, self.z))
                k = next(k for k in range(1, len(f)) if abs(f[k]) > noise)
                s_min[key] = (noise / abs(f[k])) ** (mp.mpf(1) / k)
        s0, hs, V, cap = mp.mpf(0), hmax / 64, None, 0
        while True:
            left = t_end - self.t - s0
            if left <= 0:                                 # z is at t + s0 = t_end
                self.t = t_end
                return None
            if V is None or hs > cap:
                cap = min(2 * hs, hmax)
                V = self._series(A, self.z, cap)
            hs = min(hs, cap, left)
            z_end = sum((v * hs ** k for k, v in enumerate(V[1:], 1)), V[0])
            verdict, roots = "ok", []
            for key, r in rows:
                f = [r @ v for v in V]
                if key in s_min and s0 + hs <= s_min[key]:
                    continue
                change = sum(abs(c) * hs ** k for k, c in enumerate(f[1:], 1))
                if f[0] > change:
                    continue
                slope = sum(k * abs(c) * hs ** (k - 1) for k, c in enumerate(f[2:], 2))
                f_end = r @ z_end
                if abs(f[1]) > slope:                     # monotone on [s0, s0 + hs]
                    if f[1] < 0 and f[0] <= 0 and key[0] == "g":
                        raise RuntimeError(f"gap {key[1]} negative at t = {self.t + s0}")
                    if f[1] < 0 and f_end <= 0 < f[0]:
                        roots.append((self._root(f, hs), key))
                    continue
                verdict = "split"
            if verdict == "split":                        # a row undecided: shorter step
                hs /= 2
                if hs < mp.mpf(10) ** (-self.dps) * (abs(self.t) + 1):
                    raise RuntimeError(f"no root isolation at t = {self.t}")
                continue
            if roots:
                s, key = min(roots)
                self.z = sum((v * s ** k for k, v in enumerate(V[1:], 1)), V[0])
                self.t += s0 + s
                return key
            s0 += hs
            self.z, V = z_end, None
            hs *= 2

    @staticmethod
    def _root(f, hs):
        """The zero of Σ f_k σ^k on (0, hs] (monotone, f(0) > 0 ≥ f(hs)): safeguarded Newton."""
        lo, hi, s = mp.mpf(0), hs, hs / 2
        for _ in range(400):
            val = sum(c * s ** k for k, c in enumerate(f))
            if val > 0:
                lo = s
            else:
                hi = s
            d = sum(k * c * s ** (k - 1) for k, c in enumerate(f[1:], 1))
            s_new = s - val / d if d != 0 else (lo + hi) / 2
            if not lo < s_new < hi:
                s_new = (lo + hi) / 2
            if abs(s_new - s) <= ROOT_TOL * abs(s_new) or hi - lo <= ROOT_TOL * hi:
                return s_new
            s = s_new
        raise RuntimeError("root refinement did not converge")

    def _at(self, A, z, s):
        out = z
        while s > 0:
            norm = max(sum(abs(a) for a in row) for row in A) + 1
            h = min(s, 1 / norm)
            V = self._series(A, out, h)
            out = sum((v * h ** k for k, v in enumerate(V[1:], 1)), V[0])
            s -= h
        return out

    # -- impacts and contact sets ----------------------------------------------------------
    def _newton(self, A):
        """Generalized Newton on the contacts A (enumeration of the LCP)."""
        WA = self.W[:, A]
        G = WA.T @ self.Minv @ WA
        gm = self.vel_rows()[A] @ self.z
        tiny = mp.mpf(10) ** (5 - self.dps)
        for S in itertools.product([0, 1], repeat=len(A)):
            idx = [i for i in range(len(A)) if S[i]]
            lam = np.full(len(A), mp.mpf(0), dtype=object)
            if idx:
                sol = _solve(G[np.ix_(idx, idx)], np.array([-(1 + self.e[A[i]]) * gm[i]
                                                           for i in idx], dtype=object))
                lam[idx] = sol
            gp = gm + G @ lam
            if all(lam[i] >= -tiny and gp[i] + self.e[A[i]] * gm[i] >= -tiny
                   for i in range(len(A))):
                return gm, lam
        raise AssertionError("no LCP solution")

    def _positive_forces(self, P):
        return all(v > 0 for v in self.force_rows(P) @ self.z) if P else True

    def _project(self, P):
        """Remove the gaps' and velocities' round-off on the held set P (M-metric)."""
        if not P:
            return
        n, WP = self.n, self.W[:, P]
        G = WP.T @ self.Minv @ WP
        g = self.gap_rows()[P] @ self.z
        v = self.vel_rows()[P] @ self.z
        self.z[:n] = self.z[:n] - self.Minv @ WP @ _solve(G, g)
        self.z[n:2 * n] = self.z[n:2 * n] - self.Minv @ WP @ _solve(G, v)

    def _rest(self, rest, v, j):
        """Hold ``rest`` after an impact of j that left it bouncing at v ≤ v_hold (None: no
        tail): the remaining Zeno tail of j, ``2v/(α(1 − e))`` for its contact acceleration
        −α on the flow before the hold (docs/theory/oracles.md §1; its error O(α̇/α·tail²) is far below
        ROOT_TOL for v ≤ 1e-9), is flown on the held flow."""
        tail = mp.mpf(0)
        if v is not None and v > 0:
            alpha = -(self.vel_rows()[j] @ (self.A(self.held) @ self.z))
            if alpha > 0:
                tail = 2 * v / (alpha * (1 - self.e[j]))
        self._project(rest)
        if tail > 0:
            self.z = self._at(self.A(rest), self.z, tail)
            self.t += tail
            self._project(rest)

    def run(self, t_end, max_events=10_000):
        """Events ``(t, kind, contact, γ⁻, γ⁺)`` (mpf) until t_end; kinds ``impact``,
        ``stick`` (held from then on), ``liftoff``. The state stays in :attr:`z`."""
        out, skip = [], set()
        with mp.workdps(self.dps):
            t_end = mp.mpf(float(t_end))
            scale = max(abs(v) for v in self.vel_rows() @ self.z) + 1
            while len(out) < max_events:
                key = self.next_event(t_end, skip)
                if key is None:
                    return out
                kind, j = key
                if kind == "f":
                    self.held = [c for c in self.held if c != j]
                    out.append((self.t, "liftoff", j, mp.mpf(0), mp.mpf(0)))
                    skip = {("g", j)}
                    continue
                A = sorted(set(self.held) | {j})
                gm, lam = self._newton(A)
                self.z[self.n:2 * self.n] += self.Minv @ self.W[:, A] @ lam
                gp = self.vel_rows()[A] @ self.z
                for c, a, b in zip(A, gm, gp):
                    if c == j:
                        out.append((self.t, "impact", c, a, b))
                    elif b > 0:
                        out.append((self.t, "liftoff", c, a, b))
                rest = [c for c, b in zip(A, gp) if b <= self.v_hold * scale]
                if rest and self._positive_forces(rest):
                    self._rest(rest, gp[A.index(j)] if rest == sorted(set(self.held) | {j})
                               else None, j)
                    out += [(self.t, "stick", c, mp.mpf(0), mp.mpf(0))
                            for c in rest if c not in self.held]
                    self.held = rest
                else:
                    self.held = [c for c, b in zip(A, gp) if c in self.held and b <= 0]
                    self._project(self.held)
                skip = {("g", c) for c in A if c not in self.held}
        raise RuntimeError("event cap reached")
