"""Declared benchmark grids: :class:`Case`, :class:`Suite` and the registry :data:`SUITES`.

A suite is data, not code: a name, a description and a tuple of cases, each case one point
of the grid (scenario × observers × contact solver × impact law × step size × seed × ...).
Running the suite is :func:`bench.run.run_suite`; the kinds of cases are

``observers``       jump vs no-jump observer on one scenario (one row per observer);
``work_precision``  error against a stated reference vs CPU time, one step size;
``robustness``      observers driven by a perturbed closing log (delay, jitter, missed
                    impacts, false closings);
``scaling``         the master of ``rocking_chain`` for one N: CPU time per step, memory;
``checks``          the proof-step checks of :mod:`proofs_checks` on one scenario;
``peers``           one problem in Siconos and in the toolkit (:mod:`bench.peers`): time per
                    step of both, their ratio, the largest trajectory difference.

``quick`` is a first look (≤ 30 s on 2 cores once the kernel is compiled), ``full`` the real
numbers (≤ 10 minutes), ``peers`` the Siconos comparison alone, ``smoke`` a seconds-long grid
for the tests. Suites also say whether and how to run the pytest-benchmark micro-benchmarks
of ``bench/micro``. Every time loop runs on the compiled engine (the default of
:func:`observer.simulate`) except where a case asks for a contact solver the kernel does not
have (``solver`` other than ``"pivoting"``: the numpy engine, :func:`engine_for`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

KINDS = ("observers", "work_precision", "robustness", "scaling", "checks", "peers")

RHOS = (1e-3, 1e-5, 1e-6, 1e-9)
"""Synchronization thresholds: for each ρ the rows hold the settling time (V stays ≤ ρ·V(t_on)
until the end of the coupling window) and the first-passage time (first V ≤ ρ·V(t_on))."""


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
        Seed of the case's random generator (robustness perturbations, checks).
    slave_offset : tuple or None
        ``((dq...), (du...))``: observer initial state = master initial state + offset, for
        scenarios without an ``[observer]`` table; None uses the scenario's table.
    target : str
        work_precision: ``"master"`` or an observer name whose trajectory error is measured.
    reference : str
        work_precision: ``"closed form"`` or ``"h/16 run"``.
    h_ref : float or None
        work_precision: step of the reference run (h_min/16 of the sweep).
    h_record : float or None
        work_precision: the error is measured on the grid of spacing max(h, h_record) (a
        power-of-two multiple of h: the run and its reference keep every k-th step), so that
        runs down to h = 1e-6 store at most a few 10⁵ samples; None keeps every step.
    perturbation : str
        robustness: one of :data:`bench.perturb.KINDS`.
    size : float
        robustness: size of the perturbation (s, fraction or 1/s).
    memory : bool
        scaling: also measure the peak traced memory (a second, traced run).
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
    target: str = "master"
    reference: str = ""
    h_ref: float | None = None
    h_record: float | None = None
    perturbation: str = "none"
    size: float = 0.0
    memory: bool = True

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"unknown case kind {self.kind!r}; choose from {KINDS}")

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


COMPILED_SOLVERS = ("pivoting",)
"""Contact solvers the compiled kernel has (its exact closed form / block pivoting); the
others (lemke, nnls, the cvxpy + OSQP reference) exist only in the numpy engine."""


def engine_for(solver: str) -> str:
    """The engine a case with contact solver ``solver`` runs on: ``"compiled"`` (the default
    of :func:`observer.simulate`) when the kernel has the solver, else ``"python"`` — the
    kernel would silently solve with its own pivoting method."""
    return "compiled" if solver in COMPILED_SOLVERS else "python"


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
def observer_cases(full: bool) -> list[Case]:
    """Jump vs no-jump on double_mass, rocking_chain (N = 10), bouncing_ball (Zeno), grazing,
    impact_oscillator and a persistent-contact case (double_mass with F = 0).

    Scenarios without an ``[observer]`` table get an explicit initial offset of the
    observers. bouncing_ball has K = 0, so only the no-jump observer applies there.
    """
    h_dm, T_dm = (1e-4, 20.0) if full else (2e-4, 10.0)
    h_ch = 1e-4 if full else 2e-4
    h_1 = 1e-4 if full else 1e-3
    return [
        Case("observers", "double_mass", h=h_dm, t_end=T_dm),
        Case("observers", "rocking_chain", params=(("param.N", 10),), h=h_ch, t_end=8.0),
        Case("observers", "bouncing_ball", label="bouncing_ball (Zeno)", h=h_1, t_end=6.0,
             slave_offset=((0.2,), (-1.0,))),
        Case("observers", "grazing", h=h_1 if full else 1e-3, t_end=40.0,
             slave_offset=((0.1,), (0.0,))),
        Case("observers", "impact_oscillator", h=h_1 if full else 1e-3, t_end=20.0,
             slave_offset=((0.1,), (0.0,))),
        Case("observers", "double_mass", label="persistent contact (double_mass, F = 0)",
             params=(("param.F", 0.0),), h=1e-4 if full else 5e-4, t_end=20.0 if full else 10.0,
             slave_offset=((0.01, 0.0), (0.0, 0.0))),
    ]


# ---------------------------------------------------------------------------- work-precision
def _sweep(h_max: float, count: int) -> list[float]:
    return [h_max / 2 ** j for j in range(count)]


WP_SIZES = {"quick": {"pivoting": 5, "reference": 3, "double_mass": 5, "double_mass_reference": 3},
            "full": {"pivoting": 12, "reference": 7, "double_mass": 13, "double_mass_reference": 5}}
"""Step sizes per sweep (halving). ``full``: the compiled runs go from 2e-3 s (1-DOF) and
4e-3 s (double_mass) down to 2e-3/2¹¹ = 4e-3/2¹² ≈ 9.8e-7 s; the cvxpy/OSQP reference solver
(~1 ms per contact solve, and the numpy engine's ≈ 25 µs per step) stops earlier: 7 and 5
sizes in ``full``, the 3 largest steps in ``quick``."""

H_RECORD = {"closed form": 2e-3 / 2 ** 6, "h/16 run": 4e-3 / 2 ** 9}
"""Spacing of the grid the error is measured on (``Case.h_record``) in the ``full`` sweeps:
3.1e-5 s (1-DOF, closed form; ≤ 3.2·10⁵ samples over 10 s) and 7.8e-6 s (double_mass; the
h/16 reference at 6.1e-8 s keeps every 128th step)."""


def work_precision_cases(full: bool) -> list[Case]:
    """Error vs CPU time over ≥ 5 (``full``: ≥ 8, down to ≈ 1e-6 s) step sizes (halving) on
    the compiled engine, for both impact laws, and the same with the cvxpy/OSQP reference
    solver over the largest steps (:data:`WP_SIZES`).

    * bouncing_ball, impact_oscillator: the master against its closed form;
    * double_mass: the master and each observer against a run at h_ref = h_min/16
      (pivoting solver, same law); with the cvxpy/OSQP reference solver (~100× slower per
      contact solve, and only in the numpy engine) ``quick`` runs the master only, ``full``
      the master and each observer.
    """
    sizes = WP_SIZES["full" if full else "quick"]
    cases: list[Case] = []
    for scen, T, h0 in (("bouncing_ball", 3.0, 2e-3), ("impact_oscillator", 10.0, 2e-3)):
        for law in ("newton", "poisson"):
            for solver in ("pivoting", "reference"):
                for h in _sweep(h0, sizes[solver]):
                    h_rec = H_RECORD["closed form"] if full and h < H_RECORD["closed form"] else None
                    cases.append(Case("work_precision", scen, law=law, solver=solver, h=h, t_end=T,
                                      observers=(), reference="closed form", h_record=h_rec))
    T = 1.0
    hs = _sweep(4e-3, sizes["double_mass"])
    h_ref = hs[-1] / 16
    h_rec = H_RECORD["h/16 run"] if full else None
    for law in ("newton", "poisson"):
        for target in ("master", "jump", "nojump"):
            for h in hs:
                cases.append(Case("work_precision", "double_mass", law=law, h=h, t_end=T,
                                  observers=() if target == "master" else (target,),
                                  target=target, reference="h/16 run", h_ref=h_ref, h_record=h_rec))
        ref_hs = hs[:sizes.get("double_mass_reference", len(hs))]
        for target in ("master", "jump", "nojump") if full else ("master",):
            for h in ref_hs:
                cases.append(Case("work_precision", "double_mass", law=law, solver="reference", h=h,
                                  t_end=T, observers=() if target == "master" else (target,),
                                  target=target, reference="h/16 run", h_ref=h_ref, h_record=h_rec))
    return cases


# ------------------------------------------------------------------------------- robustness
ROBUSTNESS_LEVELS = {
    "quick": {"delay": (1e-3, 5e-3, 2e-2), "jitter": (1e-3, 5e-3),
              "missed": (0.1, 0.3), "false": (1.0, 5.0)},
    "full": {"delay": (1e-4, 5e-4, 1e-3, 5e-3, 1e-2, 2e-2, 5e-2),
             "jitter": (1e-4, 5e-4, 1e-3, 5e-3, 1e-2, 2e-2),
             "missed": (0.05, 0.1, 0.2, 0.3, 0.5), "false": (0.5, 1.0, 2.0, 5.0, 10.0)},
}
RANDOM_KINDS = ("jitter", "missed", "false")
ROBUSTNESS_SEEDS = {"quick": 3, "full": 20}
"""Seeds per point of the random perturbations (a delay is deterministic: one run)."""
BAND = (0.1, 0.9)
"""Quantiles of the band the report draws over the seeds of a point (with the median)."""


def robustness_cases(full: bool) -> list[Case]:
    """double_mass (coupled from t = 0) with χ from the master's own closing log, perturbed.

    Random perturbations are repeated over :data:`ROBUSTNESS_SEEDS` seeds (20 in ``full``);
    the report shows their median and the 10–90 % band (:data:`BAND`).
    """
    key = "full" if full else "quick"
    h, T = (1e-4, 10.0) if full else (2e-4, 8.0)
    seeds = tuple(range(ROBUSTNESS_SEEDS[key]))
    cases = [Case("robustness", "double_mass", h=h, t_end=T)]
    for kind, sizes in ROBUSTNESS_LEVELS[key].items():
        for size in sizes:
            for seed in (seeds if kind in RANDOM_KINDS else (0,)):
                cases.append(Case("robustness", "double_mass", h=h, t_end=T, perturbation=kind,
                                  size=size, seed=seed))
    return cases


# ---------------------------------------------------------------------------------- scaling
SCALING_N = {"quick": (5, 10, 20, 50, 100, 200), "full": (5, 10, 20, 50, 100, 200, 500, 1000)}
SCALING_FIT_FROM = 10
"""The per-step exponent is fitted from N = 10 to the largest N (issue 9: ≤ 1.1 up to 1000)."""


def scaling_cases(full: bool) -> list[Case]:
    """rocking_chain master (no observers) for N = 5 … 200 (``full``: … 1000), h = 1e-3 s.

    Contacts close from t ≈ 1 s on (the ground motion has to build up), so the horizon
    covers 1 s (quick) or 3 s (full) of contact activity after that.
    """
    key = "full" if full else "quick"
    T = 4.0 if full else 2.0
    return [Case("scaling", "rocking_chain", params=(("param.N", N),), observers=(), h=1e-3, t_end=T)
            for N in SCALING_N[key]]


# ------------------------------------------------------------------------------------ peers
PEER_CASES = (("impact_oscillator", 1e-4, 20.0, None), ("double_mass", 1e-4, 10.0, None),
              ("rocking_chain", 1e-4, 2.0, 10))
"""(problem, h, T, N): 2·10⁵ steps of the forced oscillator, 10⁵ of double_mass's master
(Newton law, dropped from 1 mm), 2·10⁴ of the ground-frame chain with N = 10 (its contacts
close after ≈ 1 s); :mod:`bench.peers` builds the problems."""


def peer_cases() -> list[Case]:
    """One ``peers`` case per problem of :data:`PEER_CASES` (master only, Newton law)."""
    return [Case("peers", name, params=(("param.N", N),) if N else (), observers=(), law="newton",
                 h=h, t_end=T) for name, h, T, N in PEER_CASES]


CHECK_SCENARIOS = ("double_mass", "rocking_chain", "bouncing_ball", "impact_oscillator", "grazing")
QUICK_CHECK_SCENARIOS = ("double_mass", "bouncing_ball", "impact_oscillator", "grazing")
"""The quick suite leaves out the chain's checks (≈ 20 s of CPU: its A3 search and PSD checks
enumerate many active sets); ``full`` runs all."""


def check_cases(full: bool = True) -> list[Case]:
    """One :func:`proofs_checks.run_checks` call per built-in scenario (seed 0)."""
    return [Case("checks", s, observers=()) for s in (CHECK_SCENARIOS if full else QUICK_CHECK_SCENARIOS)]


# --------------------------------------------------------------------------------- micro
MICRO_QUICK = ("--benchmark-min-rounds=5", "--benchmark-max-time=0.02", "--benchmark-warmup=on",
               "--benchmark-warmup-iterations=1", "-k", "(compiled and not rocking_chain) or pivoting")
MICRO_FULL = ("--benchmark-min-rounds=20", "--benchmark-max-time=0.5", "--benchmark-warmup=on")
"""pytest arguments of the micro-benchmarks. ``quick`` times the compiled loops of the small
scenarios (the chain's take ≈ 4 s) and the pivoting contact solver (each benchmark warms up
first: compile and caches excluded); ``full``
every benchmark (both engines, every solver) with ≥ 5 rounds (the loop benchmarks fix
their own rounds, :data:`bench.micro` ``LOOP_ROUNDS``)."""


def _settings(full: bool) -> dict:
    key = "full" if full else "quick"
    obs = observer_cases(full)
    sz = WP_SIZES[key]
    sw = (f"compiled runs: {sz['pivoting']} step sizes halving from 2e-3 s (1-DOF; T = 3 s ball, "
          f"10 s oscillator; closed form) down to {2e-3 / 2 ** (sz['pivoting'] - 1):.3g} s, and "
          f"{sz['double_mass']} from 4e-3 s (double_mass, T = 1 s, against an h/16 run) down to "
          f"{4e-3 / 2 ** (sz['double_mass'] - 1):.3g} s; cvxpy/OSQP reference solver (numpy engine): "
          f"{sz['reference']} sizes (1-DOF), {sz.get('double_mass_reference', sz['double_mass'])} "
          f"(double_mass)")
    if full:
        sw += (f"; errors on a grid of spacing max(h, {H_RECORD['closed form']:.3g} s) (1-DOF), "
               f"max(h, {H_RECORD['h/16 run']:.3g} s) (double_mass)")
    nseeds = ROBUSTNESS_SEEDS[key]
    return {
        "engine": "compiled (numba kernel; compile time measured once per run, apart) for every "
                  "run with the pivoting solver; numpy engine for the other contact solvers",
        "observers": "; ".join(f"{c.name}: h = {c.h:g} s, T = {c.t_end:g} s" for c in obs),
        "synchronization thresholds ρ": ", ".join(f"{r:g}" for r in RHOS),
        "work-precision sweep": sw,
        "robustness": ("double_mass, " + ("h = 1e-4 s, T = 10 s" if full else "h = 2e-4 s, T = 8 s")
                       + f", {nseeds} seeds per random perturbation (median and "
                         f"{100 * BAND[0]:.0f}–{100 * BAND[1]:.0f} % band), delay deterministic"),
        "scaling": "rocking_chain master, h = 1e-3 s, " + ("T = 4 s" if full else "T = 2 s")
                   + ", N = " + ", ".join(str(n) for n in SCALING_N[key])
                   + f"; exponent fitted from N = {SCALING_FIT_FROM}",
        "checks": ", ".join(CHECK_SCENARIOS if full else QUICK_CHECK_SCENARIOS),
        "peers": ("; ".join(f"{p}: h = {h:g} s, {int(round(T / h))} steps" for p, h, T, _ in PEER_CASES)
                  if full else "not in this suite (python -m bench run peers)"),
        "micro-benchmarks": " ".join(MICRO_FULL if full else MICRO_QUICK),
    }


def _suite(name: str, description: str, full: bool, kinds: tuple[str, ...], micro: bool) -> Suite:
    builders = {"observers": observer_cases, "work_precision": work_precision_cases,
                "robustness": robustness_cases, "scaling": scaling_cases,
                "checks": check_cases, "peers": lambda full: peer_cases()}
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
        Case("robustness", "double_mass", h=1e-3, t_end=1.0),
        Case("robustness", "double_mass", h=1e-3, t_end=1.0, perturbation="delay", size=5e-3),
        Case("scaling", "rocking_chain", params=(("param.N", 2),), observers=(), h=1e-3, t_end=0.2),
        Case("scaling", "rocking_chain", params=(("param.N", 4),), observers=(), h=1e-3, t_end=0.2),
        Case("checks", "bouncing_ball", observers=()),
    )
    return Suite("smoke", "tiny grid of every kind, for tests (seconds)", cases, None,
                 {"note": "smoke test settings; numbers are not meaningful"})


ALL_KINDS = ("observers", "work_precision", "robustness", "scaling", "checks")

SUITES: dict[str, Suite] = {
    "observers": _suite("observers", "jump vs no-jump observers across scenarios (full settings)",
                        True, ("observers",), False),
    "work_precision": _suite("work_precision", "error vs CPU time, fitted orders (full settings)",
                             True, ("work_precision",), False),
    "robustness": _suite("robustness", "observers under imperfect switching signals (full settings)",
                         True, ("robustness",), False),
    "scaling": _suite("scaling", "rocking_chain N = 5 … 1000: CPU time per step and memory",
                      True, ("scaling",), False),
    "peers": _suite("peers", "Siconos and the toolkit on the same problems: time per step, "
                             "trajectory difference (needs python3-siconos)", True, ("peers",), False),
    "micro": Suite("micro", "pytest-benchmark: time loops on both engines, contact solves",
                   (), MICRO_FULL, {"micro-benchmarks": " ".join(MICRO_FULL)}),
    "quick": _suite("quick", "first look: small version of every suite (≤ 30 s on 2 cores, kernel "
                             "compiled)", False, ALL_KINDS, True),
    "full": _suite("full", "every suite with the real numbers, Siconos peers included (≤ 10 "
                           "minutes on 2 cores)", True, ALL_KINDS + ("peers",), True),
    "smoke": smoke_suite(),
}
"""Registry: suite name → :class:`Suite`."""


def get_suite(name: str) -> Suite:
    """The registered suite ``name`` (``KeyError`` with the known names otherwise)."""
    try:
        return SUITES[name]
    except KeyError:
        raise KeyError(f"unknown suite {name!r}; choose from {', '.join(SUITES)}") from None
