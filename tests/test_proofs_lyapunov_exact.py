"""The three-valued Lyapunov verdict (:mod:`proofs_checks.exact_step`, :func:`proofs_checks.lyapunov.check_lyapunov_decrease`).

References are independent of the code under test: ΔV and the scheme residual term
R = v_θᵀρ_u + e_θᵀKρ_q are recomputed here with Python's ``fractions.Fraction`` from the
float states (exact), the classifier is driven by hand-built exact parts at its boundaries
(a rise equal to round-off plus slack, and 2⁻¹⁰⁰ more), and the known-bad systems (an
indefinite C̄, the Euclidean projection metric) must come out violated.
"""

from __future__ import annotations

import json
import subprocess
import sys
from fractions import Fraction as F

import numpy as np
import pytest
from flint import fmpq

import proofs_checks as pc
from observer.model import LinearSystem
from proofs_checks import lyapunov as ly
from proofs_checks.exact_step import ExactSteps, classify
from proofs_checks.runs import replay

pytestmark = pytest.mark.filterwarnings("ignore:penetration .* reduce h")


@pytest.fixture(scope="module")
def newton():
    """double_mass, Newton e = 0.3, h = 1e-2, 2 s (python engine): the slack makes V rise."""
    sc = pc.load("double_mass", {"impact.law": "newton", "impact.restitution": 0.3})
    specs = pc.CheckContext(sc, pc.CheckSettings(h=1e-2, t_end=2.0)).slave_specs()
    return replay(sc, h=1e-2, t_end=2.0, slaves=specs, engine="python")


@pytest.fixture(scope="module")
def dm_short():
    sc = pc.load("double_mass", {"simulation.t_end": 0.5})
    return sc, pc.CheckContext(sc).slave_specs()


def _fr(x) -> F:
    return F(float(x))


def _frv(a) -> list:
    return [F(float(x)) for x in np.ravel(a)]


def _mv(A, x):
    return [sum(A[i][j] * x[j] for j in range(len(x))) for i in range(len(A))]


def _dot(x, y):
    return sum(a * b for a, b in zip(x, y))


def _reference(run, a, b, k):
    """ΔV and R = v_θᵀρ_u + e_θᵀKρ_q of step k in Fractions (module docstring of exact_step)."""
    s = run.system
    M, C, K, W = ([_frv(row) for row in X] for X in (s.M, s.C, s.K, s.W))
    h, th = _fr(run.h), _fr(run.theta)
    A, B = run.slaves[a], run.slaves[b]
    sub = lambda x, y: [p - q for p, q in zip(x, y)]                        # noqa: E731
    lin = lambda c1, x, c2, y: [c1 * p + c2 * q for p, q in zip(x, y)]       # noqa: E731
    v0, v1 = sub(_frv(A.u[k]), _frv(B.u[k])), sub(_frv(A.u[k + 1]), _frv(B.u[k + 1]))
    e0, e1 = sub(_frv(A.q[k]), _frv(B.q[k])), sub(_frv(A.q[k + 1]), _frv(B.q[k + 1]))
    em = sub(_frv(A.q_pre[k + 1]), _frv(B.q_pre[k + 1]))
    dP = sub(_frv(A.P[k + 1]), _frv(B.P[k + 1]))
    V = lambda v, e: (_dot(v, _mv(M, v)) + _dot(e, _mv(K, e))) / 2          # noqa: E731
    v_th, e_th = lin(1 - th, v0, th, v1), lin(1 - th, e0, th, em)
    WdP = _mv(W, dP)
    rho_u = [a_ + h * b_ + h * c_ - d_ for a_, b_, c_, d_ in
             zip(_mv(M, sub(v1, v0)), _mv(C, v_th), _mv(K, e_th), WdP)]
    rho_q = [d - h * v for d, v in zip(sub(em, e0), v_th)]
    return V(v1, e1) - V(v0, e0), _dot(v_th, rho_u) + _dot(e_th, _mv(K, rho_q))


def test_exact_identity_holds_with_the_scheme_residual(newton):
    """On every closed step of the jump pair and on a few free ones: ΔV and R equal the
    Fraction reference exactly, and ΔV = damping + impulse + numerical + projection + R with
    no defect at all (M, K symmetric)."""
    run = newton
    ex = ExactSteps(run)
    A, B = run.slaves["jump_a"], run.slaves["jump_b"]
    closed = np.flatnonzero(A.active[1:].any(axis=1))
    steps = list(closed[:12]) + [0, 1, 50]
    assert len(closed) >= 3
    for k in steps:
        p = ex.parts(A, B, int(k))
        dV, R = _reference(run, "jump_a", "jump_b", int(k))
        assert p["total"] == fmpq(dV.numerator, dV.denominator)
        assert p["R_scheme"] == fmpq(R.numerator, R.denominator)
        assert p["identity_defect"] == 0
        assert p["total"] == p["damping"] + p["impulse"] + p["numerical"] + p["projection"] + p["R_scheme"]
        # the split of the impulse and projection parts is exact by construction of the remainders
        assert p["impulse"] == p["compl_sign"] + p["delassus"] + p["slack"] + p["impulse_unsplit"] + p["R_impulse"]
        assert p["compl_sign"] <= 0 and p["delassus"] <= 0 and p["projection_jump"] <= 0


def test_exact_identity_on_two_coupled_poisson_contacts():
    """One rocking block (two coupled contacts, Glocker's Poisson step): the same exact identity;
    the impulse part is Glocker's term (kept whole) plus the slack plus the exact remainder."""
    sc = pc.load("rocking_chain", {"param.N": 1, "initial.u": [-0.5, 0.3]})
    specs = pc.CheckContext(sc, pc.CheckSettings(h=2e-3, t_end=0.6)).slave_specs()
    run = replay(sc, h=2e-3, t_end=0.6, slaves=specs, engine="python")
    ex = ExactSteps(run)
    A, B = run.slaves["nojump_a"], run.slaves["nojump_b"]
    two = np.flatnonzero(A.active[1:].sum(axis=1) == 2)
    assert two.size >= 1
    for k in list(two[:6]) + [0]:
        p = ex.parts(A, B, int(k))
        dV, R = _reference(run, "nojump_a", "nojump_b", int(k))
        assert p["total"] == fmpq(dV.numerator, dV.denominator)
        assert p["R_scheme"] == fmpq(R.numerator, R.denominator) and p["identity_defect"] == 0
        assert p["delassus"] == 0 and p["compl_sign"] == 0 or k == 0
        assert p["impulse"] == p["impulse_unsplit"] + p["slack"] + p["R_impulse"]


def _parts(rise, roundoff, slack, **signs):
    """Exact parts with the given rise = total − gap, round-off and slack (signs fill the rest)."""
    z = fmpq(0)
    p = {k: z for k in ("damping", "numerical", "compl_sign", "delassus", "projection_jump", "impulse_unsplit",
                        "R_scheme", "R_impulse", "R_projection", "projection_unprojected_gap")}
    p.update({k: fmpq(v) if not isinstance(v, fmpq) else v for k, v in signs.items()})
    p["R_scheme"] = roundoff
    p["slack"] = slack
    p["total"] = rise
    return p


TINY = fmpq(1, 2 ** 100)


@pytest.mark.parametrize("rise,kind", [
    (fmpq(0), "none"), (-TINY, "none"),
    (fmpq(3, 10 ** 17), "roundoff"),                              # = round-off
    (fmpq(3, 10 ** 17) + TINY, "slack"),
    (fmpq(3, 10 ** 17) + fmpq(1, 1000), "slack"),                 # = round-off + slack
    (fmpq(3, 10 ** 17) + fmpq(1, 1000) + TINY, "violated"),       # 2⁻¹⁰⁰ beyond: near miss
])
def test_classify_at_its_boundaries(rise, kind):
    vd = classify(_parts(rise, fmpq(3, 10 ** 17), fmpq(1, 1000), damping=fmpq(1, 7)))
    assert vd.kind == kind
    assert vd.unexplained == rise - fmpq(3, 10 ** 17) - fmpq(1, 1000)
    if kind == "violated":
        assert vd.cause == "damping"


def test_classify_negative_roundoff_and_slack_explain_nothing():
    vd = classify(_parts(TINY, -fmpq(1, 10), -fmpq(1, 10)))
    assert vd.kind == "violated" and vd.unexplained == TINY


def test_classify_caps_the_roundoff_at_the_a_priori_bound():
    """A residual beyond the float round-off bound is not round-off (wrong scheme/projection)."""
    ro = fmpq(1, 1000)
    ok = classify(_parts(ro, ro, fmpq(0)), allowance=2e-3)
    assert ok.kind == "roundoff"
    bad = classify(_parts(ro, ro, fmpq(0)), allowance=1e-3 * (1 - 1e-12))
    assert bad.kind == "violated" and bad.cause == "roundoff"


def test_slack_rise_holds_up_to_the_slack_and_its_exact_witness(newton):
    r = ly.check_lyapunov_decrease(newton, order_factors=())
    assert r.passed is True and r.evidence == "bounded"
    assert r.verdict == "holds up to the discrete slack (order not fitted)"
    lab = next(lab for lab in r.witness["pairs"] if r.witness[f"{lab}: steps_slack"])
    k = r.witness[f"{lab}: slack_step"]
    w = r.witness[f"{lab}: slack_step_exact"]
    assert w["rise/V"] > 0 and w["slack/V"] >= w["rise/V"] - max(w["roundoff/V"], 0.0)
    # the rise is ΔV of the float states (no unprojected gap in this pair), exactly
    a, b = {"jump pair": ("jump_a", "jump_b"), "no-jump pair": ("nojump_a", "nojump_b")}[lab]
    dV, _ = _reference(newton, a, b, k)
    assert dV > 0
    assert float(dV) == pytest.approx(w["rise/V"] * float(ly.decrement_parts(newton, a, b)["V"][k]), rel=1e-12)


def test_indefinite_damping_is_violated_exactly_with_a_near_miss(dm_short):
    sc, specs = dm_short
    s = sc.system
    C = np.array([[1.0, -3.0], [-3.0, 2.0]])                    # symmetric, λ_min < 0
    bad = LinearSystem(s.M, C, s.K, s.W, s.forcing, s.gap, check=False)
    run = replay(sc, slaves=specs, system=bad)
    r = ly.check_lyapunov_decrease(run, order_factors=())
    assert r.passed is False and r.evidence == "violated" and r.verdict.startswith("violated: V rises at step")
    assert r.verdict.endswith("exactly")
    assert "damping term positive" in r.reason
    assert r.witness["steps_violated"] > 0
    # near miss: the unexplained rise against the tolerance (identity-type criteria opened)
    u = r.witness["max_dV_unexplained"]
    assert u > 0
    kw = dict(identity_tolerance=1.0, order_factors=())
    assert ly.check_lyapunov_decrease(run, tolerance=0.999 * u, **kw).passed is False
    assert ly.check_lyapunov_decrease(run, tolerance=1.001 * u, **kw).passed is True


def test_euclidean_projection_is_violated(dm_short):
    sc, specs = dm_short
    run = replay(sc, slaves=specs, metric=np.eye(2))
    r = ly.check_lyapunov_decrease(run, order_factors=())
    assert r.passed is False and r.evidence == "violated"
    assert "K-metric projection" in r.reason
    assert r.witness["max_dV_unexplained"] > 1e-3


def test_the_k_metric_twin_holds(dm_short):
    sc, specs = dm_short
    r = ly.check_lyapunov_decrease(replay(sc, slaves=specs), order_factors=())
    assert r.passed is True and r.witness["steps_violated"] == 0


def test_findings_line():
    ok = {"check": "mass_spd", "scenario": "x", "passed": True, "verdict": None}
    slack = {"check": "lyapunov_decrease", "scenario": "x", "passed": True,
             "verdict": "holds up to the discrete slack (order ≈ 1)"}
    exact = dict(slack, verdict="holds exactly: no rise of V beyond round-off")
    bad = dict(slack, passed=False, verdict="violated: ...")
    assert ly.findings_line([ok, exact]) == "all 2 checks hold on 1 scenario(s); no finding"
    line = ly.findings_line([ok, slack])
    assert line.startswith("all 2 checks hold on 1 scenario(s); the only finding is the proven discrete slack")
    assert "x: holds up to the discrete slack (order ≈ 1)" in line and "\n" not in line
    assert ly.findings_line([ok, bad]) == "1 check(s) violated: lyapunov_decrease on x"


def test_cli_double_mass_lyapunov_holds_up_to_the_slack(tmp_path):
    """Acceptance: ``python -m proofs_checks double_mass`` (its h = 1e-4): lyapunov_decrease
    "holds up to the discrete slack (order ≈ 1)", exit 0."""
    out = tmp_path / "r.json"
    proc = subprocess.run([sys.executable, "-m", "proofs_checks", "double_mass", "--only", "lyapunov_decrease",
                           "--json", str(out)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "holds up to the discrete slack (order ≈ 1)" in proc.stdout
    (res,) = json.loads(out.read_text())["results"]
    assert res["evidence"] == "bounded" and res["verdict"] == "holds up to the discrete slack (order ≈ 1)"
    assert 0.9 <= res["witness"]["slack_order_impulse_slack"] <= 1.1
