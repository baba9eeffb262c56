"""Hard cases (issue 12 item 5) as a benchmark kind: ``hard``.

Each hard case is one :class:`HardCase` of kind ``"hard"`` (:func:`hard_cases`):
the system (a built-in scenario with overrides, or one of the builders of :data:`BUILDERS`
with its ``param.*`` values), the step and horizon, the time-stepping options (``run.store``,
``run.record_every`` in ``params``) and the reference its error is measured against
(``HardCase.reference``): ``"closed form"`` (:func:`observer.closed_form.closed_form_position`),
``"event solution"`` (the exact event-driven integrator sampled on the run's grid) or
``"none: <reason>"``.

:func:`run_hard` runs one case on the compiled time-stepping engine and returns one tidy row
(:func:`columns`): the run's state (``ok``, ``fallback``, ``stopped``, or ``refused`` when the
input is rejected with an :class:`~observer.errors.InputError` before any step, whose message
names the field), the stop reason, whether any returned number is NaN, the steps and CPU time,
the health numbers (largest complementarity residual recomputed from the applied impulse
against the run's tolerance, deepest penetration relative to the length scale, h·ω_max), and
the error against the reference.

Error norm (the work-precision suite's, :func:`bench.norms.trajectory_error`): on the
recorded rows t_k, ``e_k = max_i |q_i(t_k) − q_ref,i(t_k)|``; ``err_max = max_k e_k`` and
``err_mean`` its time average. Without a reference both are NaN and ``reference_note`` says
why.

What the cases ask of the toolkit (the acceptance line of issue 12): every case runs to the
end or stops with a clear status; none returns NaN; its error is reported. ``cond(W) = 1e10``
is *refused*: σ_min/σ_max(W) = 1e-10 is below √ε (:data:`observer.validation.W_SV_RTOL`), where
the Delassus matrices ``WᵀÂ⁻¹W`` (cond ≈ 1e20) are numerically singular and no contact
problem can be solved to tolerance; a clear ``InputError`` naming ``system.W`` is the right
answer, not a run.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

import observer
from bench.norms import trajectory_error
from observer.row_schema import CASE, HARD, TIMING
from observer.closed_form import closed_form_position
from observer.errors import InputError
from observer.scenario import Scenario
from observer.scenarios import SCENARIOS


KIND = "hard"
"""The case kind of this module (one row per case)."""

RUN_PREFIX = "run."
"""``params`` keys with this prefix are options of :func:`observer.simulate` (``store``,
``record_every``), not scenario overrides."""

NO_REFERENCE = "none: "
"""Prefix of ``HardCase.reference`` for a case without a reference; the reason follows."""

ERROR_NORM = "max over samples / time average of max_i |q_i − q_ref,i|"

METRICS: dict[str, Any] = HARD
"""The columns of a ``hard`` row beyond ``CASE`` and ``TIMING`` (:data:`observer.row_schema.HARD`,
declared with the other kinds' rows)."""


def columns() -> dict[str, Any]:
    """Every column of a ``hard`` row: ``CASE``, ``TIMING`` (:mod:`observer.row_schema`) and
    :data:`METRICS`."""
    return {**CASE, **TIMING, **METRICS}


# ------------------------------------------------------------------------------- builders
def two_mass(m2: float = 1.0, k2: float = 100.0) -> dict:
    """Two masses in series (ground spring k1 = 100 N/m, coupling spring k2), the lower one
    dropped 1 cm onto a stop (Newton, e = 0.5): the ratios k2/k1 and m2/m1 (m1 = 1 kg) set the
    stiffness and mass ratio of the hard cases."""
    k1 = 100.0
    return {
        "scenario": {"name": "two_mass", "description": f"two masses, m2 = {m2:g}, k2 = {k2:g}"},
        "system": {"M": [[1.0, 0.0], [0.0, m2]], "C": [[0.2, 0.0], [0.0, 0.2 * m2]],
                   "K": [[k1 + k2, -k2], [-k2, k2]], "W": [[1.0], [0.0]],
                   "forcing": {"constant": [-9.81, -9.81 * m2]}, "gap": {"offset": [0.01]}},
        "impact": {"law": "newton", "restitution": 0.5},
        "initial": {"q": [0.0, 0.0], "u": [0.0, 0.0]},
        "simulation": {"t_end": 0.5, "h": 1e-3}}


def bed(n: int = 200) -> dict:
    """n unit masses on a chain of springs (fixed ends, 50 N/m, plus 1 N/m to ground), all
    dropped together 2 cm onto n stops (Newton, e = 0.3): the n contacts close in the same
    step (a stack landing)."""
    n = int(n)
    K = 50.0 * (2.0 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)) + np.eye(n)
    return {
        "scenario": {"name": "bed", "description": f"{n} masses landing on {n} stops at once"},
        "system": {"M": np.eye(n).tolist(), "C": (0.1 * np.eye(n)).tolist(), "K": K.tolist(),
                   "W": np.eye(n).tolist(), "forcing": {"constant": [-9.81] * n},
                   "gap": {"offset": [0.02] * n}},
        "impact": {"law": "newton", "restitution": 0.3},
        "initial": {"q": [0.0] * n, "u": [0.0] * n},
        "simulation": {"t_end": 0.2, "h": 1e-3}}


def dependent_w(ratio: float = 1e-10) -> dict:
    """Two masses (the two_mass system, k2 = 100) with two contacts whose columns of W are
    nearly dependent: W = R·diag(1, ratio), R a rotation by 0.3 rad, so that
    σ_min/σ_max(W) = ``ratio`` (cond(W) = 1/ratio)."""
    c, s = np.cos(0.3), np.sin(0.3)
    W = np.array([[c, -s], [s, c]]) @ np.diag([1.0, float(ratio)])
    doc = two_mass()
    doc["scenario"] = {"name": "dependent_w", "description": f"cond(W) = {1 / ratio:.3g}"}
    doc["system"]["W"] = W.tolist()
    doc["system"]["gap"] = {"offset": [0.01, 0.01]}
    return doc


BUILDERS: dict[str, Callable[..., dict]] = {"two_mass": two_mass, "bed": bed,
                                            "dependent_w": dependent_w}
"""Systems of the hard cases that are not built-in scenarios: name → document builder
(keyword parameters = the case's ``param.*`` values)."""


# ---------------------------------------------------------------------------------- cases
@dataclass(frozen=True)
class HardCase:
    """One hard case: the case object of a suite (what :mod:`bench.run` and
    :func:`bench.runners.run_case` use of a :class:`bench.suites.Case`: ``kind``,
    ``case_id``, ``name``; plus ``scenario``, ``params``, ``h``, ``t_end``, ``overrides()``).

    Attributes
    ----------
    label : str
        The case's name, shown in the report.
    scenario : str
        A built-in scenario or a key of :data:`BUILDERS`.
    params : tuple of (key, value)
        Scenario overrides (built-ins), builder parameters (``param.*``) and simulate options
        (``run.store``, ``run.record_every``).
    h, t_end : float
    reference : str
        ``"closed form"``, ``"event solution"`` or ``"none: <reason>"``.
    quick : bool
        In the ``quick`` suite (the quick cases; their CPU time is in the bench results).
    description : str
        What makes the case hard (and how to read its error).
    kind, solver, seed, observers, law, integrator
        Fixed: the fields of :class:`bench.suites.Case` that :mod:`bench.run` and
        :mod:`bench.runners` read of any case (the master alone, pivoting, time-stepping).
    """

    label: str
    scenario: str
    params: tuple
    h: float
    t_end: float
    reference: str
    quick: bool = False
    description: str = ""
    kind: str = KIND
    solver: str = "pivoting"
    seed: int = 0
    observers: tuple = ()
    law: str | None = None
    integrator: str = "time-stepping"

    def __post_init__(self):
        if self.kind != KIND:
            raise ValueError(f"kind: a HardCase has kind {KIND!r}, got {self.kind!r}")

    @property
    def name(self) -> str:
        return self.label

    @property
    def case_id(self) -> str:
        """Stable identifier: kind, name and every setting that defines the run (not
        ``quick``, ``description`` nor the wording of a missing reference's reason), so that
        a changed run is a new case."""
        params = ",".join(f"{k}={v!r}" for k, v in self.params)
        reference = "none" if self.reference.startswith(NO_REFERENCE) else self.reference
        return (f"{self.kind}:{self.label}:{self.scenario}:params=({params}):h={self.h!r}:"
                f"t_end={self.t_end!r}:reference={reference}")

    def overrides(self) -> dict[str, Any]:
        """``params`` plus h and t_end as ``simulation.*`` keys."""
        return {**dict(self.params), "simulation.h": self.h, "simulation.t_end": self.t_end}


REFUSED_NO_REFERENCE = NO_REFERENCE + "the input is refused before any step"

BALL_STEPS = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7)
"""Step sizes of the bouncing-ball sweep (first impact at t = 0.4515 s included)."""


def _ball(h: float) -> HardCase:
    t_end = 0.5 if h >= 1e-5 else 0.46
    rec = max(1, int(round(1e-5 / h)))          # at most 5·10⁴ stored rows
    params = (("run.record_every", rec),) if rec > 1 else ()
    return HardCase(f"ball h = {h:g}", "bouncing_ball", params, h, t_end, "closed form",
                    h >= 1e-5, f"step size {h:g} s on the bouncing ball through its first impact")


HARD_CASES: tuple[HardCase, ...] = (
    HardCase("stiffness ratio 1e8", "two_mass", (("param.k2", 1e10),), 1e-3, 0.15,
             "event solution", False,
             "k2/k1 = 1e8 at h = 1e-3 s: h·ω_max ≈ 141, far outside the accurate regime; two "
             "impact clusters in 0.15 s (the event integrator's certified root search steps "
             "about 1/ω_max on the stiff mode and stalls at t = 0.179 s, where the lower mass "
             "settles onto the stop: 0.15 s is the horizon with an exact reference)"),
    HardCase("mass ratio 1e6", "two_mass", (("param.m2", 1e6),), 1e-3, 0.5, "event solution",
             True, "m2/m1 = 1e6: the light mass bounces under a heavy one"),
    HardCase("cond(W) 1e10", "dependent_w", (("param.ratio", 1e-10),), 1e-3, 0.5,
             REFUSED_NO_REFERENCE, True,
             "two contacts with σ_min/σ_max(W) = 1e-10: Delassus matrices of cond ≈ 1e20"),
    *(_ball(h) for h in BALL_STEPS),
    HardCase("1e8 steps (summary)", "impact_oscillator",
             (("run.store", "summary"), ("run.record_every", 10_000)), 1e-4, 1e4,
             "event solution", False,
             "10⁸ steps of the forced impact oscillator in summary mode (rows every 1 s); its "
             "impact sequence is sensitive (against the event solution at h = 1e-4: 1e-4 at "
             "10 s, 1e-2 at 40 s, O(1) after 60 s), so over 1e4 s the error measures that "
             "separation, not the step"),
    HardCase("20 contacts at once", "bed", (("param.n", 20),), 1e-3, 0.2, "event solution",
             True, "20 masses land on 20 stops in the same step (the quick version of the "
                   "200-contact case)"),
    HardCase("200 contacts at once", "bed", (("param.n", 200),), 1e-3, 0.2, "event solution",
             False, "200 masses land on 200 stops in the same step (its event reference: about "
                    "3000 events)"),
    HardCase("Zeno e = 0.99", "bouncing_ball", (("impact.restitution", 0.99),), 1e-3, 3.0,
             "closed form", True, "restitution 0.99: nearly elastic bounces; the impacts "
                                  "accumulate (rest) only at t_∞ = 89.9 s"),
    HardCase("Zeno e = 0.01", "bouncing_ball", (("impact.restitution", 0.01),), 1e-3, 3.0,
             "closed form", True, "restitution 0.01: the impacts accumulate within 9 ms of "
                                  "the first one (t_∞ = 0.4606 s), then persistent contact"),
    HardCase("grazing every period", "grazing", (), 1e-3, 60.0, "event solution", True,
             "the mass touches the wall with zero velocity once per forcing period (8 "
             "grazes in 60 s). Until the grazes the error is small (first 10 s: 2.2e-3, "
             "1.8e-4, 1.8e-6 at h = 1e-3, 1e-4, 1e-5); later grazes split the trajectories by "
             "O(0.1) at every h (a graze is structurally unstable: the slightest offset makes "
             "it a miss or a slow impact), so the error over 60 s measures that split"),
)
"""The hard cases, in report order."""


def hard_cases(full: bool = True) -> list[HardCase]:
    """The hard cases of a suite: all of them (``full``) or the quick ones."""
    return [hc for hc in HARD_CASES if full or hc.quick]


# --------------------------------------------------------------------------------- running
def split_params(case: HardCase) -> tuple[dict, dict, dict]:
    """``(scenario overrides, builder parameters, simulate options)`` of a hard case.

    Builder parameters are the ``param.*`` entries of a case whose system is a builder
    (:data:`BUILDERS`); for a built-in scenario they are overrides like any other.
    """
    overrides, build, run = {}, {}, {}
    for key, value in case.overrides().items():
        if key.startswith(RUN_PREFIX):
            run[key[len(RUN_PREFIX):]] = value
        elif case.scenario in BUILDERS and key.startswith("param."):
            build[key[len("param."):]] = value
        else:
            overrides[key] = value
    return overrides, build, run


def document(case: HardCase) -> dict:
    """The scenario document of a builder case (with the case's h and t_end)."""
    overrides, build, _ = split_params(case)
    doc = BUILDERS[case.scenario](**build)
    doc["simulation"].update({"h": case.h, "t_end": case.t_end})
    for key, value in overrides.items():
        if key not in ("simulation.h", "simulation.t_end"):
            raise InputError(key, f"builder {case.scenario!r} takes param.* and run.* only")
    return doc


def load(case: HardCase) -> Scenario:
    """The case's scenario (:class:`InputError` when its input is refused)."""
    if case.scenario in BUILDERS:
        return Scenario.from_dict(document(case), case.name)
    if case.scenario in SCENARIOS:
        return observer.load_scenario(case.scenario, split_params(case)[0])
    raise InputError("scenario", f"unknown hard-case system {case.scenario!r}; choose from "
                                 f"{', '.join([*BUILDERS, *SCENARIOS])}")


def _shape(case: HardCase, sc: Scenario | None) -> tuple[int, int, str]:
    """(n, m, law) of the case, from the scenario or, when it was refused, its document."""
    if sc is not None:
        return sc.system.n, sc.system.m, sc.law.law
    doc = document(case) if case.scenario in BUILDERS else {}
    sysd = doc.get("system", {})
    return (len(sysd.get("M", ())), len(sysd.get("W", [[]])[0]),
            str(doc.get("impact", {}).get("law", "")))


def base_columns(case: HardCase, sc: Scenario | None) -> dict[str, Any]:
    """The case's declared fields and effective settings (the ``CASE`` block of the row)."""
    n, m, law = _shape(case, sc)
    return {"kind": KIND, "scenario": case.scenario, "name": case.name,
            "params": ", ".join(f"{k}={v}" for k, v in case.params),
            "solver": case.solver, "law": law,
            "h": float(sc.h if sc is not None else case.h),
            "t_end": float(sc.t_end if sc is not None else case.t_end),
            "seed": case.seed, "N": None, "n": int(n), "m": int(m),
            "description": case.description}


def has_nan(res) -> bool:
    """Whether any returned number of the master (q, u, P) is NaN or infinite."""
    return not all(np.all(np.isfinite(a)) for a in (res.q, res.u, res.P))


def reference_positions(case: HardCase, sc: Scenario, res) -> tuple[np.ndarray | None, str, float]:
    """``(q_ref on res.t or None, note, CPU seconds)`` for the case's reference."""
    if case.reference.startswith(NO_REFERENCE):
        return None, case.reference[len(NO_REFERENCE):], float("nan")
    c0 = time.process_time()
    if case.reference == "closed form":
        q_ref = closed_form_position(sc, res.t)
        if q_ref is None:
            return None, f"{sc.name} has no closed form", float("nan")
        return q_ref, "closed form", time.process_time() - c0
    if case.reference != "event solution":
        raise InputError("reference", f"must be 'closed form', 'event solution' or "
                                      f"'{NO_REFERENCE}<reason>', got {case.reference!r}")
    spacing = float(res.t[1] - res.t[0]) if res.t.size > 1 else sc.h
    ev = observer.simulate(sc.with_overrides({"simulation.h": spacing}), integrator="event")
    cpu = time.process_time() - c0
    if not ev.status.ok:
        return None, f"the event solution did not finish: {ev.status.reason}", cpu
    k = res.t.size
    if ev.t.size < k or np.max(np.abs(ev.t[:k] - res.t)) > 1e-9 * max(1.0, float(res.t[-1])):
        return None, "the event solution's grid differs from the run's", cpu
    return ev.q[:k], (f"event solution (exact event-driven integrator, {len(ev.events)} events, "
                      f"sampled every {spacing:g} s)"), cpu


def error_columns(res, q_ref: np.ndarray | None) -> dict[str, float]:
    """``err_max`` and ``err_mean`` (module docstring) of the master against ``q_ref``; NaN
    without a reference."""
    if q_ref is None:
        return {"err_max": float("nan"), "err_mean": float("nan")}
    if res.t.size < 2:
        e = float(np.max(np.abs(res.q - q_ref)))
        return {"err_max": e, "err_mean": e}
    err = trajectory_error(res.t, res.q, q_ref)
    return {"err_max": err["err_max"], "err_mean": err["err_mean"]}


def health_columns(md: dict) -> dict[str, Any]:
    """The run's health numbers (:mod:`observer.health`) and whether its residual held."""
    hl = md.get("health") or {}
    res = float(hl.get("max_residual", float("nan")))
    tol = float(hl.get("residual_tol", float("nan")))
    return {"max_residual": res, "residual_tol": tol, "residual_held": bool(res <= tol),
            "penetration_rel": float(hl.get("penetration_rel", float("nan"))),
            "h_omega_max": float(hl.get("h_omega_max", float("nan"))),
            "warnings": "; ".join(hl.get("warnings") or ())}


def refused_row(case: HardCase, exc: InputError, cpu: float, wall: float) -> dict[str, Any]:
    """The row of a case whose input was refused: state ``refused``, the error as reason."""
    _, _, run = split_params(case)
    return {**base_columns(case, None), "status": "refused", "note": "",
            "stop_reason": f"InputError: {exc}", "has_nan": False, "steps": 0,
            "store": str(run.get("store", "full")), "record_every": int(run.get("record_every", 1)),
            "samples": 0, "max_residual": float("nan"), "residual_tol": float("nan"),
            "residual_held": None, "penetration_rel": float("nan"), "h_omega_max": float("nan"),
            "warnings": "", "reference": "none",
            "reference_note": case.reference[len(NO_REFERENCE):]
            if case.reference.startswith(NO_REFERENCE) else "refused before any step",
            "norm": ERROR_NORM, "err_max": float("nan"), "err_mean": float("nan"),
            "ref_cpu_time_s": float("nan"), "cpu_time_s": cpu, "wall_time_s": wall,
            "cpu_scope": "input validation"}


def run_hard(case: HardCase, ctx=None) -> list[dict[str, Any]]:
    """Run one hard case on the compiled engine; one row (:func:`columns`).

    ``ctx`` (a :class:`bench.runners.Context`) is accepted for the runner registry and not
    used. An :class:`~observer.errors.InputError` of the case's own input is its outcome
    (status ``refused``); any other exception propagates (the suite records the case as
    failed).
    """
    _, _, run = split_params(case)
    c0, w0 = time.process_time(), time.perf_counter()
    try:
        sc = load(case)
        res = observer.simulate(sc, **run)
    except InputError as exc:
        return [refused_row(case, exc, time.process_time() - c0, time.perf_counter() - w0)]
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    md = res.metadata
    q_ref, note, ref_cpu = reference_positions(case, sc, res)
    kind = case.reference if q_ref is not None else "none"
    return [{**base_columns(case, sc), "status": res.status.state.value, "note": "",
             "stop_reason": res.status.reason, "has_nan": has_nan(res), "steps": int(md["steps"]),
             "store": str(run.get("store", "full")),
             "record_every": int(md.get("record_every") or run.get("record_every", 1)),
             "samples": int(res.t.size), **health_columns(md), "reference": kind,
             "reference_note": note, "norm": ERROR_NORM, **error_columns(res, q_ref),
             "ref_cpu_time_s": ref_cpu, "cpu_time_s": cpu, "wall_time_s": wall,
             "cpu_scope": "scenario validation and the time-stepping run (master alone)"}]
