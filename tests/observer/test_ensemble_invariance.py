"""The results of :func:`observer.ensemble` are a property of the motion, not of the coordinates
(issue 22): double_mass (2 DOF, 1 contact, 6 s at h = 1e-3, 16 members × the four designs on
the energy sphere), run

(a) translated, q → q + c with ν → ν − Wᵀc and f → f + Kc (the same motion, docs/theory/oracles.md §5);
(b) in other units, lengths × α and times × β (M kept: K/β², C/β, f·α/β², ω/β, ν·α, u·α/β,
    h·β), so that V (an energy, paper (16)) scales by α²/β² and times by β;

and compares every member's row with the original run's, design by design.

Tolerances (round-off, stated once): the initial errors are drawn on the energy sphere of
each run's own matrices, so (b) changes them by the scaling alone and (a) not at all; a
translation then adds a round-off of about ε·|c| to both q and q̂, so to e = q̂ − q an error
ε·|c| that is relative ε·|c|/|e|: ≤ 1e-12 relative at t = 0 (|e| ≈ 0.02, |c| ≤ 100), growing
as e shrinks. Hence V_on and V_max to 1e-10 relative, V_end to 1e-10·V_on, the largest
relative one-step rise (taken at small V) to 1e-4 relative + 1e-6, settling and first-passage
times to one step h (a crossing of ρ·V(t_on) moves by a step only when V lies within the
round-off of the threshold), the same members never settling, the same number of rises.
"""

from __future__ import annotations

import numpy as np
from hypothesis import Phase, given, settings
from hypothesis import strategies as st

import observer
from observer.scenario import Scenario

DESIGNS = ("jump", "nojump", "jump_mass", "jump_identity")
N_MEMBERS = 16
T_END, H = 6.0, 1e-3
SETTINGS = settings(max_examples=4, deadline=None, derandomize=True, database=None,
                    phases=[Phase.explicit, Phase.reuse, Phase.generate])
V_RTOL = 1e-10
RISE_RTOL, RISE_ATOL = 1e-4, 1e-6

BASE = observer.load_scenario("double_mass").to_dict()


def build(c=None, alpha: float = 1.0, beta: float = 1.0, projected: bool = False) -> Scenario:
    """double_mass over T_END at H, translated by ``c`` and in units (α, β)."""
    s = dict(BASE["system"])
    M, K, C, W = (np.array(s[k], dtype=float) for k in "MKCW")
    c = np.zeros(M.shape[0]) if c is None else np.asarray(c, dtype=float)
    f = np.array(s["forcing"]["constant"]) + K @ c
    nu = np.array(s["gap"]["offset"]) - W.T @ c
    s.update(C=(C / beta).tolist(), K=(K / beta ** 2).tolist(), gap={"offset": (nu * alpha).tolist()},
             forcing={**s["forcing"], "constant": (f * alpha / beta ** 2).tolist(),
                      "amplitude": (np.array(s["forcing"]["amplitude"]) * alpha / beta ** 2).tolist(),
                      "omega": s["forcing"]["omega"] / beta})
    q = lambda x: ((np.array(x, dtype=float) + c) * alpha).tolist()          # noqa: E731
    u = lambda x: (np.array(x, dtype=float) * alpha / beta).tolist()         # noqa: E731
    doc = {**BASE, "system": s,
           "initial": {"q": q(BASE["initial"]["q"]), "u": u(BASE["initial"]["u"])},
           "observer": {**BASE["observer"], "q": q(BASE["observer"]["q"]), "u": u(BASE["observer"]["u"]),
                        "coupling": [0.0, T_END * beta]},
           "simulation": {**BASE["simulation"], "t_end": T_END * beta, "h": H * beta,
                          "master_projection": projected}}
    return Scenario.from_dict(doc)


def run(sc: Scenario, seed: int):
    return observer.ensemble(sc, DESIGNS, n=N_MEMBERS, seed=seed, workers=1).set_index(["design", "member"])


def assert_same_rows(a, b, v_scale: float = 1.0, t_scale: float = 1.0) -> None:
    """Rows ``b`` (in other coordinates; V in units of ``v_scale``, times of ``t_scale``) equal
    the rows ``a`` to the module's tolerances."""
    assert (a["status"] == "ok").all() and (b["status"] == "ok").all()
    b = b.loc[a.index]
    V_on = a["V_on"].to_numpy()
    np.testing.assert_allclose(b["V_on"] / v_scale, V_on, rtol=V_RTOL, atol=0)
    np.testing.assert_allclose(b["V_max"] / v_scale, a["V_max"], rtol=V_RTOL, atol=0)
    np.testing.assert_array_less(np.abs(b["V_end"] / v_scale - a["V_end"]), V_RTOL * V_on)
    np.testing.assert_allclose(b["max_rise_rel"], a["max_rise_rel"], rtol=RISE_RTOL, atol=RISE_ATOL)
    np.testing.assert_array_equal(b["rises"], a["rises"])
    times = [col for col in a.columns if col.startswith(("t_settle_", "t_sync_"))]
    assert len(times) >= 8
    for col in times:
        ta, tb = a[col].to_numpy(dtype=float), b[col].to_numpy(dtype=float) / t_scale
        np.testing.assert_array_equal(np.isinf(ta), np.isinf(tb), err_msg=col)
        fin = np.isfinite(ta)
        np.testing.assert_allclose(tb[fin], ta[fin], rtol=0, atol=H * (1 + 1e-9), err_msg=col)


@SETTINGS
@given(c=st.lists(st.sampled_from([-100.0, -7.5, 3.25, 100.0]), min_size=2, max_size=2),
       alpha=st.sampled_from([1e-3, 1e3, 2.0 ** 10]), beta=st.sampled_from([1e-3, 10.0, 0.1]),
       projected=st.booleans(), seed=st.integers(0, 2 ** 16))
def test_ensemble_rows_are_invariant_under_translation_and_units(c, alpha, beta, projected, seed):
    """Every member's row of every design (plain or projected master) under a translation of
    the coordinates and under a change of units (module docstring: what and to what tolerance)."""
    a = run(build(projected=projected), seed)
    # the property compares something: the members decay and some settle at ρ = 1e-6
    assert (a["V_end"] < 1e-2 * a["V_on"]).all()
    assert np.isfinite(a["t_settle_1e-06"]).any()
    assert_same_rows(a, run(build(c=c, projected=projected), seed))
    assert_same_rows(a, run(build(alpha=alpha, beta=beta, projected=projected), seed),
                     v_scale=alpha ** 2 / beta ** 2, t_scale=beta)
