"""Declared benchmark grids: :class:`Case`, :class:`Suite` and the registry :data:`SUITES`.

A suite is data, not code: a name, a description and a tuple of cases, each case one point
of the grid (scenario × observers × contact solver × impact law × step size × seed × ...).
Running the suite is :func:`bench.run.run_suite`; the kinds of cases are

``observers``       jump vs no-jump observer on one scenario (one row per observer);
``work_precision``  error against a stated reference vs CPU time, one step size;
``robustness``      both designs with χ from a contact sensor (latency, jitter, missed and
                    false detections, threshold δ, sampling period) at one level, as a
                    paired ensemble over several masters × initial errors;
``scaling``         the master of ``rocking_chain`` for one N: CPU time per step, memory;
``checks``          the proof-step checks of :mod:`proofs_checks` on one scenario;
``peers``           one problem in Siconos and in the toolkit (:mod:`bench.peers`): time per
                    step of both, their ratio, the largest trajectory difference;
``ensemble``        n initial errors per design against one master (:func:`observer.ensemble`),
                    one row per (design, member): the built-ins, the random-system family and
                    robustness to a perturbed χ with both the perturbation and the errors sampled.

``quick`` is a first look (minutes on a laptop, the first compile and warm-up included; the
report gives its measured time and machine), ``full`` the real numbers (several times longer, Siconos peers and the
micro-benchmarks included), ``peers`` the Siconos comparison alone, ``smoke`` a seconds-long
grid for the tests. Suites also say whether and how to run the pytest-benchmark micro-benchmarks
of ``bench/micro``. Every time loop runs on the compiled engine (the default of
:func:`observer.simulate`) except where a case asks for a contact solver the kernel does not
have (``solver`` other than ``"pivoting"``: the numpy engine, :func:`engine_for`).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any, Callable, Iterator

from observer.engines import INTEGRATORS
from observer.impact import IMPACT_LAWS
from observer.metrics import RHOS  # noqa: F401  (the one threshold list; rows hold one column per ρ)
from observer.observers import OBSERVER_DESIGNS
from observer.scenarios import SCENARIOS, info

KINDS = ("observers", "work_precision", "robustness", "scaling", "checks", "hard", "ensemble", "peers")


@dataclass(frozen=True)
class Case:
    """One point of a benchmark grid.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    scenario : str
        Built-in scenario name (:data:`observer.SCENARIOS`).
    label : str
        Variant name shown in reports (e.g. ``"persistent"`` for double_mass with F = 0);
        defaults to the scenario name.
    params : tuple of (key, value)
        Overrides for :func:`observer.load_scenario` (``"param.N"``, ``"impact.law"``, ...).
    observers : tuple of str
        Observer designs to run (``"jump"``, ``"nojump"``).
    solver : str
        Contact solver (:data:`observer.CONTACT_SOLVERS`).
    law : str or None
        Impact law override (``"newton"``/``"poisson"``); None keeps the scenario's.
    h, t_end : float or None
        Step and horizon; None keeps the scenario's.
    seed : int
        Seed of the case's random generator (robustness: the masters, the initial errors and the
        sensors' seeds, :func:`bench.perturb.sensor_seed`; checks).
    slave_offset : tuple or None
        ``((dq...), (du...))``: observer initial state = master initial state + offset, for
        scenarios without an ``[observer]`` table; None uses the scenario's table.
    integrator : str
        ``"time-stepping"`` (Moreau–Jean) or ``"event"`` (the exact event-driven integrator).
    engine : str or None
        The engine of the case's runs (:data:`observer.engines.ENGINES`, as
        :func:`observer.simulate`'s ``engine``); None: the registry's choice for the case's
        solver (:func:`engine_for`), or the event engine for ``integrator="event"``.
    target : str
        work_precision: ``"master"`` or an observer name whose trajectory error is measured.
    reference : str
        work_precision: ``"closed form"`` or ``"event solution"`` (the exact event-driven
        run of the same scenario, sampled on the run's grid).
    h_record : float or None
        work_precision: the error is measured on the grid of spacing max(h, h_record) (a
        power-of-two multiple of h: the run and its reference keep every k-th step), so that
        runs down to h = 1e-6 store at most a few 10⁵ samples; None keeps every step.
    perturbation : str
        robustness: one of :data:`bench.perturb.KINDS`.
    size : float
        robustness: size of the perturbation (s, probability, 1/s or m): the value of its
        sensor setting (:data:`bench.perturb.SETTINGS`).
    memory : bool
        scaling: also measure the peak traced memory (a second, traced run).
    members : int
        ensemble, robustness: initial errors per design (the same for every design: paired).
    paths : int
        ensemble: members per design (the first ``paths``) whose V(t) is kept, thinned
        (:func:`bench.runners.ensemble_paths`), for the report's V(t) bands.
    masters : int
        ensemble, robustness: master trajectories (the scenario's and ``masters − 1`` initial states sampled
        around it, :func:`observer.compare.master_scenarios`), ``members`` split evenly over
        them; the rows' ``master`` column is the cluster the report's intervals resample.
    """

    kind: str
    scenario: str
    label: str = ""
    params: tuple = ()
    observers: tuple = ("jump", "nojump")
    solver: str = "pivoting"
    law: str | None = None
    h: float | None = None
    t_end: float | None = None
    seed: int = 0
    slave_offset: tuple | None = None
    integrator: str = INTEGRATORS[0]
    engine: str | None = None
    target: str = "master"
    reference: str = ""
    h_record: float | None = None
    perturbation: str = "none"
    size: float = 0.0
    memory: bool = True
    members: int = 0
    paths: int = 0
    masters: int = 1

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"unknown case kind {self.kind!r}; choose from {KINDS}")
        from observer.engines import check_engine_name

        check_engine_name(self.engine)

    @property
    def name(self) -> str:
        """Display name: the label, else the scenario."""
        return self.label or self.scenario

    @property
    def case_id(self) -> str:
        """Stable identifier: kind, name and every field that differs from its default.

        Two declarations of the same grid point give the same id in every session, which
        is what makes a suite resumable.
        """
        parts = [self.kind, self.name]
        defaults = Case(self.kind, self.scenario)
        for f in fields(self):
            if f.name in ("kind", "scenario", "label"):
                continue
            v = getattr(self, f.name)
            if v != getattr(defaults, f.name):
                parts.append(f"{f.name}={_canon(v)}")
        return ":".join(parts)

    def overrides(self) -> dict[str, Any]:
        """Scenario overrides of this case (params, law, h, t_end)."""
        out = dict(self.params)
        if self.law is not None:
            out["impact.law"] = self.law
        if self.h is not None:
            out["simulation.h"] = self.h
        if self.t_end is not None:
            out["simulation.t_end"] = self.t_end
        return out


def _canon(v: Any) -> str:
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (tuple, list)):
        return "(" + ",".join(_canon(x) for x in v) + ")"
    return str(v)


def engine_for(solver: str) -> str:
    """The engine a case with contact solver ``solver`` runs on: the one
    :func:`observer.engines.choose` gives a time-stepping run of the built-in
    ``impact_oscillator`` with that solver (the compiled engine when it has the solver, else
    the numpy one: the kernel would silently solve with its own pivoting method). The
    registry's own refusals decide it; no list of solvers or engines is kept here."""
    from observer.engines import choose
    from observer.engines.base import RunDescription
    from observer.scenario import load_scenario

    sc = load_scenario("impact_oscillator", {"simulation.solver": solver})
    return choose(RunDescription(sc, "time-stepping"))[0].name


@dataclass(frozen=True)
class Suite:
    """A named grid of cases, plus how to run the micro-benchmarks.

    Attributes
    ----------
    name, description : str
    cases : tuple of Case
    micro : tuple of str or None
        Extra pytest arguments for ``bench/micro`` (None: no micro-benchmarks).
    settings : dict
        Human-readable settings shown in the report (horizons, sweeps, thresholds).
    """

    name: str
    description: str
    cases: tuple = ()
    micro: tuple | None = None
    settings: dict = field(default_factory=dict)

    def __post_init__(self):
        ids = [c.case_id for c in self.cases]
        dup = {i for i in ids if ids.count(i) > 1}
        if dup:
            raise ValueError(f"suite {self.name!r} declares duplicate cases: {sorted(dup)[:3]}")

    def of_kind(self, kind: str) -> list[Case]:
        return [c for c in self.cases if c.kind == kind]


# --------------------------------------------------------------------------------- observers
def _pick(pair, full: bool):
    """A (quick, full) pair's entry (a scalar is both)."""
    return pair[1 if full else 0] if isinstance(pair, tuple) else pair


def observer_cases(full: bool) -> list[Case]:
    """Every registered observer design on every scenario's declared observer settings
    (``SUITE["observers"]`` of its module, :func:`observer.scenarios.info`), time-stepped and
    (unless the scenario declares ``SUITE["exact"] = False``) exact: the "exact" rows have no
    discretisation floor.

    Scenarios without an ``[observer]`` table declare an explicit initial offset of the
    observers; designs whose projection needs K ≻ 0 are skipped where K is singular (the
    runner records why).
    """
    designs = tuple(OBSERVER_DESIGNS)
    cases = []
    for name in SCENARIOS:
        exact = info(name).suite.get("exact", True)
        for spec in info(name).suite.get("observers") or ():
            for integrator in ("time-stepping", "event") if exact else ("time-stepping",):
                cases.append(Case("observers", name, label=spec.get("label", ""),
                                  params=tuple(spec.get("params", ())), observers=designs,
                                  h=_pick(spec.get("h"), full), t_end=_pick(spec.get("t_end"), full),
                                  slave_offset=spec.get("slave_offset"), integrator=integrator))
    return cases


# ---------------------------------------------------------------------------- work-precision
def _sweep(h_max: float, count: int) -> list[float]:
    return [h_max / 2 ** j for j in range(count)]


WP_SIZES = {"quick": {"pivoting": 5, "reference": 3, "event solution": 5, "event solution reference": 3},
            "full": {"pivoting": 12, "reference": 7, "event solution": 13, "event solution reference": 5}}
"""Step sizes per sweep (halving). ``full``: the compiled runs go from 2e-3 s (1-DOF) and
4e-3 s (double_mass) down to 2e-3/2¹¹ = 4e-3/2¹² ≈ 9.8e-7 s; the cvxpy/OSQP reference solver
(orders of magnitude slower per step than the compiled engine) stops earlier: 7 and 5
sizes in ``full``, the 3 largest steps in ``quick``."""

H_RECORD = {"closed form": 2e-3 / 2 ** 6, "event solution": 4e-3 / 2 ** 9}
"""Spacing of the grid the error is measured on (``Case.h_record``) by the runs of smaller h,
in every suite: 3.1e-5 s against a closed form (1-DOF; ≤ 3.2·10⁵ samples over 10 s) and
7.8e-6 s against the event solution (sampled on that grid; double_mass: 1.3·10⁵ samples over
1 s, grazing 2.6·10⁶ over 20 s). Storing every step of grazing's h = 3.9e-6 s run (5·10⁶
samples) costs more CPU time and memory than the run itself."""


def _h_record(h: float, reference: str) -> float | None:
    """The case's ``h_record``: :data:`H_RECORD` of its reference when h is smaller."""
    grid = H_RECORD[reference]
    return grid if h < grid else None


def _wp_targets(spec: dict) -> tuple[str, ...]:
    targets = spec.get("targets", ("master",))
    if "observers" in targets:
        targets = ("master",) + tuple(OBSERVER_DESIGNS)
    return tuple(targets)


def _reference_laws(full: bool) -> tuple[str, ...]:
    """Impact laws of the cvxpy/OSQP reference-solver sweeps (numpy engine: the costly runs of
    the sweeps). ``full``: every registered law. ``quick``: the first (Newton) alone — on
    every sweep the suites declare, Poisson's runs repeat Newton's to round-off (one contact:
    Poisson's compression/expansion split of one impulse is Newton's law; the chain N = 4 of
    its sweep, e = 0.9 on every contact, at most two impulses per step: measured equal to
    1e-16, ``tests/bench/test_suites.py``)."""
    laws = tuple(IMPACT_LAWS)
    return laws if full else laws[:1]


def _wp_closed_form(name: str, spec: dict, sizes: dict, full: bool) -> list[Case]:
    cases = []
    ref_laws = _reference_laws(full)
    for law in IMPACT_LAWS:
        for solver in ("pivoting", "reference") if law in ref_laws else ("pivoting",):
            for h in _sweep(spec["h0"], sizes[solver]):
                h_rec = _h_record(h, "closed form")
                cases.append(Case("work_precision", name, law=law, solver=solver, h=h,
                                  t_end=spec["t_end"], observers=(), reference="closed form",
                                  h_record=h_rec))
        # the exact integrator against the same closed form: its error and its cost
        cases.append(Case("work_precision", name, law=law, h=spec["h0"], t_end=spec["t_end"],
                          observers=(), reference="closed form", integrator="event"))
    return cases


def _wp_sizes(spec: dict, sizes: dict, full: bool) -> dict:
    """The sweep lengths of one scenario: :data:`WP_SIZES`, with the compiled sweep's length
    replaced by the scenario's own ``SUITE["work_precision"]["sizes"]["quick" | "full"]`` if
    it declares one (grazing, rocking_chain: errors that jump with where an impact falls on
    the grid need more halvings for a fitted order)."""
    own = (spec.get("sizes") or {}).get("full" if full else "quick")
    return sizes if own is None else {**sizes, "pivoting": own, "event solution": own}


def _wp_event_reference(name: str, spec: dict, sizes: dict, full: bool) -> list[Case]:
    sizes = _wp_sizes(spec, sizes, full)
    params = tuple(spec.get("params", ()))
    hs = _sweep(spec["h0"], sizes["event solution"])
    targets = _wp_targets(spec)
    ref_laws = _reference_laws(full)
    cases = []
    for law in IMPACT_LAWS:
        sweeps = [("pivoting", hs, targets)]
        if law in ref_laws:
            sweeps.append(("reference", hs[:sizes["event solution reference"]],
                           targets if full else ("master",)))
        for solver, sweep, tg in sweeps:
            for target in tg:
                for h in sweep:
                    h_rec = _h_record(h, "event solution")
                    cases.append(Case("work_precision", name, law=law, solver=solver, h=h,
                                      t_end=spec["t_end"], params=params,
                                      observers=() if target == "master" else (target,),
                                      target=target, reference="event solution", h_record=h_rec))
    return cases


def work_precision_cases(full: bool) -> list[Case]:
    """Error vs CPU time over ≥ 5 (``full``: ≥ 8, down to ≈ 1e-6 s) step sizes (halving) on
    the compiled engine, for every registered impact law, and the same with the cvxpy/OSQP
    reference solver over the largest steps (:data:`WP_SIZES`), for every scenario that
    declares a sweep (``SUITE["work_precision"]``):

    * with a closed form (``reference`` in its module): the master against it;
    * otherwise the master and each declared target against the exact event-driven solution
      of the same scenario (master and observers), sampled on the run's grid; with the
      cvxpy/OSQP reference solver ``quick`` runs the master only, ``full`` every target.

    Scenarios with a closed form also get one row of the exact event-driven integrator
    (its error against the closed form, and its cost).
    """
    sizes = WP_SIZES["full" if full else "quick"]
    cases: list[Case] = []
    for name in SCENARIOS:
        meta = info(name)
        spec = meta.suite.get("work_precision")
        if spec:
            build = _wp_closed_form if meta.reference is not None else _wp_event_reference
            cases += build(name, spec, sizes, full)
    return cases


# ------------------------------------------------------------------------------- robustness
ROBUSTNESS_LEVELS = {
    "quick": {"delay": (2e-4, 1e-3, 5e-3, 2e-2), "jitter": (1e-5, 1e-4, 1e-3, 1e-2),
              "missed": (0.01, 0.03, 0.1, 0.3), "false": (0.1, 0.3, 1.0, 3.0),
              "threshold": (1e-6, 1e-5, 1e-4, 1e-3), "sampling": (2e-4, 1e-3, 5e-3, 2e-2)},
    "full": {"delay": (1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2, 2e-2),
             "jitter": (1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2),
             "missed": (0.01, 0.03, 0.1, 0.2, 0.3, 0.5), "false": (0.1, 0.3, 1.0, 3.0, 10.0),
             "threshold": (1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2),
             "sampling": (1e-4, 5e-4, 1e-3, 5e-3, 1e-2, 2e-2)},
}
"""Levels of each sensor perturbation (:data:`bench.perturb.SETTINGS`), spanning decades. A
latency moves χ by whole steps (:mod:`observer.sensor`), so its levels start at one step
(quick h = 2e-4 s, full 1e-4 s); jitter, being drawn per endpoint, acts below a step too."""
RANDOM_KINDS = ("jitter", "missed", "false")
"""The perturbations that draw random numbers (the sensor's seed matters)."""
ROBUSTNESS_ENSEMBLE = {"quick": {"masters": 5, "members": 20}, "full": {"masters": 10, "members": 100}}
"""Masters and initial errors (in all, split evenly over the masters) of every robustness point:
the same masters and errors at every level of every kind (the case seed is 0 throughout)."""
ROBUSTNESS_RUN = {"quick": (2e-4, 8.0), "full": (1e-4, 10.0)}
"""(h, T) of the robustness runs (double_mass, coupled over the whole run)."""
BAND = (0.1, 0.9)
"""Quantiles of the band the suites' metadata declares (``band``; the robustness section now
gives cluster bootstrap intervals over masters instead)."""


def robustness_cases(full: bool) -> list[Case]:
    """double_mass (coupled from t = 0) with χ from a contact sensor (:mod:`bench.perturb`): per
    kind and level of :data:`ROBUSTNESS_LEVELS` (and the ideal sensor) one paired ensemble of
    :data:`ROBUSTNESS_ENSEMBLE` masters × initial errors, both designs."""
    key = "full" if full else "quick"
    h, T = ROBUSTNESS_RUN[key]
    kw = dict(h=h, t_end=T, **ROBUSTNESS_ENSEMBLE[key])
    cases = [Case("robustness", "double_mass", **kw)]
    for kind, sizes in ROBUSTNESS_LEVELS[key].items():
        cases += [Case("robustness", "double_mass", perturbation=kind, size=size, **kw) for size in sizes]
    return cases


# ---------------------------------------------------------------------------------- scaling
SCALING_N = {"quick": (5, 10, 20, 50, 100, 200),
             "full": (5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000, 10_000, 20_000, 50_000, 100_000)}
"""Chain sizes. The full suite goes to N = 10⁵ blocks (issue 23: from n = 513 the kernel keeps
the contacts' data as banded factors, nothing of size n × m or m × m)."""
SCALING_FIT_FROM = 10
"""The per-step exponent is fitted from N = 10 to the largest N (issue 9: ≤ 1.1 up to 1000)."""
SCALING_RECORD_VALUES = 1 << 24
"""Above this many stored state values (steps × 2n), a scaling case keeps every ``h_record``
(0.1 s) only: N = 10⁵ over 4 s would otherwise store 4001 × 4 rows of 2·10⁵ values (26 GB)."""


def scaling_cases(full: bool) -> list[Case]:
    """rocking_chain master (no observers) for N = 5 … 200 (``full``: … 10⁵), h = 1e-3 s.

    Contacts close from t ≈ 1 s on (the ground motion has to build up), so the horizon
    covers 1 s (quick) or 3 s (full) of contact activity after that. Runs whose trajectories
    would exceed :data:`SCALING_RECORD_VALUES` store one row every 0.1 s (``h_record``).
    """
    key = "full" if full else "quick"
    T, h = (4.0 if full else 2.0), 1e-3
    return [Case("scaling", "rocking_chain", params=(("param.N", N),), observers=(), h=h, t_end=T,
                 h_record=0.1 if (T / h) * 4 * N > SCALING_RECORD_VALUES else None)
            for N in SCALING_N[key]]


# ------------------------------------------------------------------------------------ peers
PEER_CASES = (("impact_oscillator", 1e-4, 100.0, None), ("double_mass", 1e-4, 10.0, None),
              ("rocking_chain", 1e-4, 2.0, 10))
"""(problem, h, T, N): 10⁶ steps of the forced oscillator (the size issue 9 measured), 10⁵ of double_mass's master
(Newton law, dropped from 1 mm), 2·10⁴ of the ground-frame chain with N = 10 (its contacts
close after ≈ 1 s); :mod:`bench.peers` builds the problems."""


def peer_cases() -> list[Case]:
    """One ``peers`` case per problem of :data:`PEER_CASES` (master only, Newton law)."""
    return [Case("peers", name, params=(("param.N", N),) if N else (), observers=(), law="newton",
                 h=h, t_end=T) for name, h, T, N in PEER_CASES]


def check_scenarios(full: bool = True) -> tuple[str, ...]:
    """Scenarios whose proof checks a suite runs: those declaring ``SUITE["checks"]`` as
    ``"quick"`` (every suite) or ``"full"`` (the full suite only: the chain's A3 search and PSD
    checks enumerate many active sets, the longest of the checks)."""
    levels = ("quick", "full") if full else ("quick",)
    return tuple(n for n in SCENARIOS if info(n).suite.get("checks") in levels)


def hard_cases(full: bool = True) -> list:
    """The hard cases of :mod:`bench.hard` (``quick``: those taking < 2 s together)."""
    from bench import hard

    return hard.hard_cases(full)


def check_cases(full: bool = True) -> list[Case]:
    """One :func:`proofs_checks.run_checks` call per scenario of :func:`check_scenarios` (seed 0)."""
    return [Case("checks", s, observers=()) for s in check_scenarios(full)]


# ------------------------------------------------------------------------------ ensembles
ENSEMBLE_MEMBERS = {"quick": 100, "full": 1000}
"""Initial errors per design of every built-in scenario's ensemble (issue 22)."""
ENSEMBLE_PARAMS = {"rocking_chain": {"quick": ((("param.N", 10),),),
                                     "full": tuple((("param.N", N),) for N in (4, 6, 8, 10))}}
"""Builder overrides of the ensembles, one ensemble per entry (a swept parameter): the chain at
the paper's N = 10 (20 DOF); the full suite sweeps N = 4, 6, 8, 10. At N = 4 the master closes
no contact inside the coupling window [4, 8] s (its closings all fall before t = 2.9 s), so
every design runs uncoupled there and the designs cannot differ; at N = 10 they do."""
ENSEMBLE_MASTERS = {"quick": 5, "full": 10}
"""Master trajectories of every built-in scenario's ensemble (its members split evenly over
them) except :data:`ONE_MASTER`: the intervals of the report's claims resample masters."""
ONE_MASTER = ("grazing", "bouncing_ball (Zeno)")
"""Ensembles kept on the scenario's own master: grazing's graze is a property of that master's
initial state (a perturbed master hits or misses the contact), and the K = 0 ball is no claim's
evidence (its evidence is the position error)."""
ENSEMBLE_GRIDS = {"grazing": {"quick": (5e-4,), "full": (2e-3, 5e-4, 2.5e-4)}}
"""Time steps of extra ensembles beside the declared one (the grid sensitivity: grazing's
kick jumps with where the graze falls on the grid, so its comparison is shown with h swept)."""
PROJECTED = ("double_mass", "random_system")
"""Scenarios whose ensembles are also run with the projected master (docs/theory/scheme.md §6: the matched
master of the jump observers, whose discrete V has no floor from the master's penetration):
the evidence of the K-metric question without the discretisation artifact."""
ENSEMBLE_PATHS = 20
"""Members per design of every built-in's ensemble whose V(t) the results keep (thinned to
:data:`bench.runners.PATH_POINTS` samples): the report's V(t) band (median, 10–90 %) per
scenario. The random systems and the perturbed-χ ensembles keep none (their evidence is the
settling and rise statistics; 100 more figures would only slow the page)."""
RANDOM_SYSTEMS = {"quick": 4, "full": 50}
"""Random systems (seeds 0, 1, …) of the ``random_system`` family per suite."""
RANDOM_MEMBERS = {"quick": 100, "full": 100}
"""Members per random system, split evenly over :data:`RANDOM_MASTERS` master trajectories."""
RANDOM_MASTERS = 5
RANDOM_SETTINGS = (2.5e-4, 10.0)
"""(h, t_end) of the random systems' ensembles (at h = 5e-4 s some systems penetrate by 1.3 % of
their clearance, above the run-health bound of 1 %)."""
ENSEMBLE_ROBUSTNESS = {
    "quick": {"levels": {"jitter": (1e-3,)}, "seeds": 1, "members": 100},
    "full": {"levels": {"delay": (1e-4, 5e-4, 1e-3, 5e-3, 1e-2, 2e-2, 5e-2),
                        "jitter": (1e-4, 5e-4, 1e-3, 5e-3, 1e-2, 2e-2), "missed": (0.05, 0.1, 0.2, 0.3, 0.5)},
             "seeds": 3, "members": 100},
}
"""Robustness to an imperfect χ as ensembles (double_mass, coupled from t = 0, jump and
nojump): per level and seed one perturbed closing log (``perturb_log`` seeded by the case's
seed) and the members' initial errors (sampled from the same seed): the levels the robustness
suite had before it became paired ensembles over masters (:func:`robustness_cases`), kept so
that these ensembles' case ids and rows stay as they were."""


def random_family(count: int) -> list[tuple[int, int, int]]:
    """(seed, dof, contacts) of the first ``count`` random systems: dof cycles through 2…8,
    contacts through 1…min(4, dof)."""
    out = []
    for seed in range(count):
        dof = 2 + seed % 7
        out.append((seed, dof, 1 + seed % min(4, dof)))
    return out


def _variant_label(name: str, over: tuple) -> str:
    return name + " (" + ", ".join(f"{k.split('.')[-1]} = {v}" for k, v in over) + ")"


def _ensemble_spec_cases(name: str, spec: dict, key: str, designs) -> list[Case]:
    h, T = _pick(spec.get("h"), False), _pick(spec.get("t_end"), False)    # quick's, in both suites
    variants = ENSEMBLE_PARAMS.get(name, {}).get(key, ((),))
    grids = () if spec.get("label") else ENSEMBLE_GRIDS.get(name, {}).get(key, ())
    out = []
    for over in variants:
        params = tuple({**dict(spec.get("params", ())), **dict(over)}.items())
        label = spec.get("label", "") or (_variant_label(name, over) if over else name)
        masters = 1 if any(x in (label, name) for x in ONE_MASTER) else ENSEMBLE_MASTERS[key]
        kw = dict(observers=designs, t_end=T, slave_offset=spec.get("slave_offset"), members=ENSEMBLE_MEMBERS[key],
                  paths=ENSEMBLE_PATHS, masters=masters)
        out.append(Case("ensemble", name, label=label, params=params, h=h, **kw))
        out += [Case("ensemble", name, label=f"{label} (h = {g:g})", params=params, h=g, **{**kw, "paths": 0})
                for g in grids if g != h]
        if name in PROJECTED and not spec.get("label"):
            out.append(Case("ensemble", name, label=f"{label} (projected master)",
                            params=params + (("simulation.master_projection", True),), h=h, **kw))
    return out


def _random_ensembles(count: int, members: int) -> list[Case]:
    """The first ``count`` systems of the random family, plain and projected master, each on
    :data:`RANDOM_MASTERS` masters."""
    h, T = RANDOM_SETTINGS
    cases = []
    for seed, dof, m in random_family(count):
        params = (("param.seed", seed), ("param.dof", dof), ("param.contacts", m))
        label = f"random_system (seed {seed}, {dof} DOF, {m} contact{'s' if m > 1 else ''})"
        for extra, suffix in (((), ""), ((("simulation.master_projection", True),), " (projected master)")):
            cases.append(Case("ensemble", "random_system", label=label + suffix, params=params + extra,
                              observers=tuple(OBSERVER_DESIGNS), h=h, t_end=T, members=members,
                              masters=RANDOM_MASTERS))
    return cases


def _builtin_ensembles(key: str) -> list[Case]:
    cases: list[Case] = []
    for name in SCENARIOS:
        if name != "random_system":
            for spec in info(name).suite.get("observers") or ():
                cases += _ensemble_spec_cases(name, spec, key, tuple(OBSERVER_DESIGNS))
    return cases


def ensemble_cases(full: bool) -> list[Case]:
    """Ensembles of initial errors (issue 22), every registered design, time-stepping:

    * every built-in scenario's declared observers settings (``SUITE["observers"]``; h and
      t_end of the quick suite in both: double_mass's full h = 1e-4 over 20 s would cost 4×
      per member; the chain with :data:`ENSEMBLE_PARAMS` (N = 10; full: N swept), grazing also on
      the steps of :data:`ENSEMBLE_GRIDS`), with :data:`ENSEMBLE_MEMBERS` members
      (100; full: 1000) sampled on the energy sphere of the scenario's own initial error, those
      of :data:`PROJECTED` also with the projected master;
    * :data:`RANDOM_SYSTEMS` systems of the ``random_system`` family (2; full: 50), 100 members
      each, with the plain and with the projected master;
    * robustness to a perturbed χ (:data:`ENSEMBLE_ROBUSTNESS`).
    """
    key = "full" if full else "quick"
    cases = _builtin_ensembles(key) + _random_ensembles(RANDOM_SYSTEMS[key], RANDOM_MEMBERS[key])
    rob = ENSEMBLE_ROBUSTNESS[key]
    for kind, sizes in rob["levels"].items():
        for size in sizes:
            for seed in range(rob["seeds"] if kind in RANDOM_KINDS else 1):
                cases.append(Case("ensemble", "double_mass", label="double_mass (perturbed χ)",
                                  h=2e-4, t_end=8.0, perturbation=kind, size=size, seed=seed,
                                  members=rob["members"]))
    return cases


K_METRIC_SYSTEMS = 50
"""Random systems of the ``k_metric`` suite (the README's K-metric finding): the first 50 of
the family, as the full suite's. (An earlier finding used the first 34: its run on 2 shared
cores was stopped there for time, no system was refused.)"""


def k_metric_cases() -> list[Case]:
    """The evidence of the K-metric question (README, "The K-metric finding"): the built-ins'
    ensembles of the quick suite (100 members per design) and the first
    :data:`K_METRIC_SYSTEMS` random systems × 100 members, plain and projected master."""
    return _builtin_ensembles("quick") + _random_ensembles(K_METRIC_SYSTEMS, RANDOM_MEMBERS["full"])


# --------------------------------------------------------------------------------- micro
MICRO_QUICK = ("--benchmark-min-rounds=5", "--benchmark-max-time=0.02", "--benchmark-warmup=on",
               "--benchmark-warmup-iterations=1", "-k", "(compiled and not rocking_chain) or pivoting")
MICRO_FULL = ("--benchmark-min-rounds=20", "--benchmark-max-time=0.5", "--benchmark-warmup=on")
"""pytest arguments of the micro-benchmarks. ``quick`` times the compiled loops of the small
scenarios (the chain's take longest) and the pivoting contact solver (each benchmark warms up
first: compile and caches excluded); ``full``
every benchmark (both engines, every solver) with ≥ 5 rounds (the loop benchmarks fix
their own rounds, :data:`bench.micro` ``LOOP_ROUNDS``)."""


def _settings(full: bool) -> dict:
    key = "full" if full else "quick"
    obs = observer_cases(full)
    sz = WP_SIZES[key]
    sweeps = []
    for name in SCENARIOS:
        meta = info(name)
        spec = meta.suite.get("work_precision")
        if spec:
            ref = "closed form" if meta.reference is not None else "event solution"
            count = _wp_sizes(spec, sz, full)["pivoting" if ref == "closed form" else "event solution"]
            where = "".join(f", {k.split('.')[-1]} = {v}" for k, v in spec.get("params", ()))
            sweeps.append(f"{name}: {count} step sizes halving from {spec['h0']:g} s down to "
                          f"{spec['h0'] / 2 ** (count - 1):.3g} s, T = {spec['t_end']:g} s{where}, "
                          f"against its {ref}")
    sw = ("compiled runs: " + "; ".join(sweeps) + f"; cvxpy/OSQP reference solver (numpy "
          f"engine): {sz['reference']} sizes (closed form), {sz['event solution reference']} "
          "(event solution)" + ("" if full else ", Newton's law only (Poisson's runs repeat "
                                "Newton's to round-off on these sweeps; full runs both)"))
    sw += (f"; errors on a grid of spacing max(h, {H_RECORD['closed form']:.3g} s) against a "
           f"closed form, max(h, {H_RECORD['event solution']:.3g} s) against the event solution")
    rob = ROBUSTNESS_ENSEMBLE[key]
    return {
        "engine": "compiled (numba kernel; compile time measured once per run, apart) for every "
                  "run with the pivoting solver; numpy engine for the other contact solvers",
        "observers": "; ".join(f"{c.name}: h = {c.h:g} s, T = {c.t_end:g} s" for c in obs),
        "synchronization thresholds ρ": ", ".join(f"{r:g}" for r in RHOS),
        "work-precision sweep": sw,
        "robustness": (f"double_mass, h = {ROBUSTNESS_RUN[key][0]:g} s, T = {ROBUSTNESS_RUN[key][1]:g} s; "
                       f"χ from a contact sensor, per level {rob['masters']} masters × "
                       f"{rob['members'] // rob['masters']} initial errors, both designs paired; levels "
                       + "; ".join(f"{k} {', '.join(f'{v:g}' for v in vs)}"
                                   for k, vs in ROBUSTNESS_LEVELS[key].items())),
        "scaling": "rocking_chain master, h = 1e-3 s, " + ("T = 4 s" if full else "T = 2 s")
                   + ", N = " + ", ".join(str(n) for n in SCALING_N[key])
                   + f"; exponent fitted from N = {SCALING_FIT_FROM}",
        "checks": ", ".join(check_scenarios(full)),
        "peers": ("; ".join(f"{p}: h = {h:g} s, {int(round(T / h))} steps" for p, h, T, _ in PEER_CASES)
                  if full else "not in this suite (python -m bench run peers)"),
        "micro-benchmarks": " ".join(MICRO_FULL if full else MICRO_QUICK),
        "hard cases": "; ".join(f"{c.name}: h = {c.h:g} s, T = {c.t_end:g} s" for c in hard_cases(full)),
        "ensembles": (f"{ENSEMBLE_MEMBERS[key]} initial errors per design on the energy sphere of "
                      f"each built-in's own error, over {ENSEMBLE_MASTERS[key]} masters (one: "
                      f"{', '.join(ONE_MASTER)}; projected master too: {', '.join(PROJECTED)}); "
                      f"{RANDOM_SYSTEMS[key]} random systems × {RANDOM_MEMBERS[key]} members over "
                      f"{RANDOM_MASTERS} masters, plain and projected master "
                      f"(h = {RANDOM_SETTINGS[0]:g} s, T = {RANDOM_SETTINGS[1]:g} s); perturbed χ: "
                      + ", ".join(f"{k} {v}" for k, v in ENSEMBLE_ROBUSTNESS[key]["levels"].items())
                      + f" × {ENSEMBLE_ROBUSTNESS[key]['seeds']} seeds × "
                        f"{ENSEMBLE_ROBUSTNESS[key]['members']} members"),
    }


def _suite(name: str, description: str, full: bool, kinds: tuple[str, ...], micro: bool) -> Suite:
    builders = {"observers": observer_cases, "work_precision": work_precision_cases,
                "robustness": robustness_cases, "scaling": scaling_cases,
                "checks": check_cases, "hard": hard_cases, "ensemble": ensemble_cases,
                "peers": lambda full: peer_cases()}
    cases: list[Case] = []
    for k in kinds:
        cases += builders[k](full)
    return Suite(name, description, tuple(cases),
                 (MICRO_FULL if full else MICRO_QUICK) if micro else None, _settings(full))


def smoke_suite() -> Suite:
    """Seconds-long grid with one or two cases of every kind (used by the tests)."""
    cases = (
        Case("observers", "double_mass", h=1e-3, t_end=1.0),
        Case("observers", "bouncing_ball", label="bouncing_ball (Zeno)", h=1e-3, t_end=1.0,
             slave_offset=((0.2,), (-1.0,))),
        Case("work_precision", "bouncing_ball", law="newton", h=2e-3, t_end=1.0, observers=(),
             reference="closed form"),
        Case("work_precision", "bouncing_ball", law="newton", h=1e-3, t_end=1.0, observers=(),
             reference="closed form"),
        Case("work_precision", "bouncing_ball", law="newton", h=5e-4, t_end=1.0, observers=(),
             reference="closed form", h_record=1e-3),
        Case("robustness", "double_mass", h=1e-3, t_end=1.0, masters=2, members=2),
        Case("robustness", "double_mass", h=1e-3, t_end=1.0, perturbation="delay", size=5e-3,
             masters=2, members=2),
        Case("scaling", "rocking_chain", params=(("param.N", 2),), observers=(), h=1e-3, t_end=0.2),
        Case("scaling", "rocking_chain", params=(("param.N", 4),), observers=(), h=1e-3, t_end=0.2),
        Case("checks", "bouncing_ball", observers=()),
        *[c for c in hard_cases(False) if c.name == "Zeno e = 0.01"],
    )
    return Suite("smoke", "tiny grid of every kind, for tests (seconds)", cases, None,
                 {"note": "smoke test settings; numbers are not meaningful"})


_SUITE_BUILDERS: dict[str, Callable[[], Suite]] = {
    "observers": lambda: _suite("observers", "every observer design across scenarios (full "
                                "settings)", True, ("observers",), False),
    "work_precision": lambda: _suite("work_precision", "error vs CPU time, fitted orders (full "
                                     "settings)", True, ("work_precision",), False),
    "robustness": lambda: _suite("robustness", "observers under imperfect switching signals "
                                 "(full settings)", True, ("robustness",), False),
    "scaling": lambda: _suite("scaling", "rocking_chain N = 5 … 10⁵: CPU time per step and "
                              "memory", True, ("scaling",), False),
    "peers": lambda: _suite("peers", "Siconos and the toolkit on the same problems: time per "
                            "step, trajectory difference (needs python3-siconos)", True,
                            ("peers",), False),
    "micro": lambda: Suite("micro", "pytest-benchmark: time loops on both engines, contact "
                           "solves", (), MICRO_FULL, {"micro-benchmarks": " ".join(MICRO_FULL)}),
    "quick": lambda: _suite("quick", "first look: small version of every suite (minutes "
                            "once the kernel is compiled)", False, KINDS[:-1], True),
    "full": lambda: _suite("full", "every suite with the real numbers, Siconos peers included "
                           "(several times quick)", True, KINDS, True),
    "ensembles": lambda: _suite("ensembles", "ensembles of initial errors: every built-in and "
                                "design (1000 members), 50 random systems, perturbed χ (full "
                                "settings)", True, ("ensemble",), False),
    "k_metric": lambda: Suite("k_metric", "the K-metric question: built-ins (100 members per "
                              "design) and 50 random systems, plain and projected master",
                              tuple(k_metric_cases()), None, _settings(False)),
    "hard": lambda: _suite("hard", "hard cases: status, NaN, residual and error against the "
                           "reference (issue 12 item 5)", True, ("hard",), False),
    "smoke": smoke_suite,
}


class _Suites(Mapping):
    """Suite name → :class:`Suite`, built from the registries (scenarios, observer designs,
    impact laws) when looked up, so that a design or scenario registered later is in it."""

    def __getitem__(self, name: str) -> Suite:
        return _SUITE_BUILDERS[name]()

    def __iter__(self) -> Iterator[str]:
        return iter(_SUITE_BUILDERS)

    def __len__(self) -> int:
        return len(_SUITE_BUILDERS)


SUITES: Mapping[str, Suite] = _Suites()
"""Registry: suite name → :class:`Suite`."""


def get_suite(name: str) -> Suite:
    """The registered suite ``name`` (``KeyError`` with the known names otherwise)."""
    try:
        return SUITES[name]
    except KeyError:
        raise KeyError(f"unknown suite {name!r}; choose from {', '.join(SUITES)}") from None
