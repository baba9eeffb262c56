"""Impact-time state observers: slaves with switched kinematic or geometric unilateral constraints.

An observer is a replica of the master model whose constraints are switched on by the
Boolean signal χ (paper eqs. (7)-(11)). Both designs share the master's step
(:class:`observer.stepping.MoreauJean`), one source of truth for the impact laws:

* ``nojump`` — switched *kinematic* constraints (the earlier observer, paper ref. [4]):
  while χ_i = 1, γ_i ≥ 0 with the master's impact law; positions are never corrected.
* ``jump`` — switched *geometric* constraints (the paper's new observer): additionally,
  while χ_i = 1 the gap is held at zero by the K-metric projection
  ``q ← q − K⁻¹W_I L_I⁻¹ g_I`` (eqs. (13)-(14)); needs K ≻ 0.

The error Lyapunov function is ``V = ½vᵀMv + ½eᵀKe`` (paper (16) with the ½ on both
terms; docs/theory/index.md §2 erratum 2), e = q_s − q_m, v = u_s − u_m.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from observer.errors import InputError
from observer.model import LinearSystem
from observer.sparse import dense, quadratic_rows
from observer.switching import SOURCES
from observer.validation import as_array

METRICS = ("K", "mass", "identity")
"""Projection metrics of the position jumps: N = K (the paper's, eqs. (13)-(14)), N = M, N = I."""


@dataclass(frozen=True)
class ObserverDesign:
    """An observer design: what the slave does while χ_i = 1, and how plots show it.

    Attributes
    ----------
    name : str
        Stable name (``--observers``, result columns ``{name}_q0``, ``V_{name}``).
    position_jumps : bool
        Switched geometric constraints: the gap of each closed contact is set to zero by the
        projection ``q⁺ = q⁻ − N⁻¹W_I(W_IᵀN⁻¹W_I)⁻¹g_I`` in the metric N (paper (13)-(14) for
        N = K); without, switched kinematic constraints only.
    metric : {"K", "mass", "identity"} or None
        The projection metric N (None without position jumps).
    label, color, linestyle : str
        How figures and tables show the design.
    """

    name: str
    position_jumps: bool
    metric: str | None
    label: str
    color: str
    linestyle: str = "-"

    def __post_init__(self) -> None:
        if self.position_jumps != (self.metric is not None) or (self.metric not in METRICS + (None,)):
            raise ValueError(f"observer design {self.name!r}: metric {self.metric!r} does not match "
                             f"position_jumps={self.position_jumps}")

    @property
    def needs_spd_K(self) -> bool:
        """Only the K-metric projection needs K ≻ 0 (L_I = W_IᵀK⁻¹W_I)."""
        return self.metric == "K"

    def metric_matrix(self, system: LinearSystem) -> np.ndarray | None:
        """The metric N as a matrix (None: K, the stepper's own cached projection)."""
        if self.metric == "mass":
            return dense(system.M)
        if self.metric == "identity":
            return np.eye(system.n)
        return None


OBSERVER_DESIGNS: dict[str, ObserverDesign] = {d.name: d for d in (
    ObserverDesign("jump", True, "K", "jump (K metric)", "tab:blue"),
    ObserverDesign("nojump", False, None, "no-jump", "tab:red", "--"),
    ObserverDesign("jump_mass", True, "mass", "jump (M metric)", "tab:green", "-."),
    ObserverDesign("jump_identity", True, "identity", "jump (identity metric)", "tab:purple", ":"),
)}
"""Registry of observer designs: add a design here (one entry) and it runs everywhere
(simulation, proof checks, suites, report)."""

DEFAULT_OBSERVERS = ("jump", "nojump")
"""The paper's two designs: what a run uses when nothing else is asked."""

RATIOS: tuple[tuple[str, str], ...] = (("nojump", "jump"), ("jump", "jump_mass"),
                                        ("jump", "jump_identity"))
"""Settling-time ratios the report shows, as (baseline, candidate): baseline / candidate."""

@dataclass(frozen=True)
class Slave:
    """One observer: a name, its design and its initial state (any state, also one with g < 0)."""

    name: str
    position_jumps: bool
    q0: np.ndarray
    u0: np.ndarray
    design: ObserverDesign | None = None

    @property
    def metric(self) -> str | None:
        """The projection metric (K when built without a registered design)."""
        if self.design is not None:
            return self.design.metric
        return "K" if self.position_jumps else None


@dataclass(frozen=True)
class ObserverConfig:
    """The ``[observer]`` table: initial state, coupling window, χ source, log file."""

    q0: np.ndarray
    u0: np.ndarray
    coupling: tuple[float, float] | None
    source: str
    log: str | None
    observers: tuple[str, ...]

    @staticmethod
    def from_table(table: dict, n: int, q_master: np.ndarray, u_master: np.ndarray,
                   base_dir: str | None = None) -> "ObserverConfig":
        q0 = as_array("observer.q", table["q"], (n,)) if "q" in table else q_master.copy()
        u0 = as_array("observer.u", table["u"], (n,)) if "u" in table else u_master.copy()
        coupling = None
        if "coupling" in table:
            coupling = check_coupling(table["coupling"])
        source = table.get("source", "master")
        if source not in SOURCES:
            raise InputError("observer.source", f"must be one of {list(SOURCES)}, got {source!r}")
        log = table.get("log")                    # a path, or a DataFrame (a sensed log)
        if source == "log" and (log is None or isinstance(log, str) and not log):
            raise InputError("observer.log", "source = \"log\" needs a log file path")
        if isinstance(log, str) and base_dir is not None:
            from pathlib import Path
            p = Path(log)
            if not p.is_absolute() and not p.exists() and (Path(base_dir) / p).exists():
                log = str(Path(base_dir) / p)
        names = table.get("observers", DEFAULT_OBSERVERS)
        if not isinstance(names, (list, tuple)):
            raise InputError("observer.observers", f"must be an array of design names, got {names!r}")
        names = tuple(design_name(name) for name in names)
        for name in names:
            check_observer_name(name)
        return ObserverConfig(q0, u0, coupling, source, log, names)


def check_coupling(value: Any) -> tuple[float, float]:
    """The coupling window ``[t_on, t_off]`` (finite numbers, t_on ≤ t_off) as a tuple, or
    :class:`InputError` naming ``observer.coupling`` (the same for the TOML table and the API)."""
    c = as_array("observer.coupling", value, (2,))
    if c[1] < c[0]:
        raise InputError("observer.coupling", f"t_off = {c[1]} < t_on = {c[0]}")
    return float(c[0]), float(c[1])


DESIGN_ALIASES = {"no_jump": "nojump", "no-jump": "nojump", "no jump": "nojump", "jumps": "jump"}
"""Old or prose spellings of design names that a user may have written: accepted with a
:class:`DeprecationWarning` and read as the registered name (one name per concept)."""


def design_name(name: Any, field: str = "observer.observers") -> Any:
    """The registered spelling of a design name: an alias of :data:`DESIGN_ALIASES` becomes its
    design's name, with a :class:`DeprecationWarning` naming ``field``; anything else is
    returned unchanged (and validated by :func:`check_observer_name`)."""
    if isinstance(name, str) and name not in OBSERVER_DESIGNS and name in DESIGN_ALIASES:
        import warnings
        new = DESIGN_ALIASES[name]
        warnings.warn(f"{field}: observer design {name!r} is spelled {new!r}; the old spelling "
                      "will be removed", DeprecationWarning, stacklevel=3)
        return new
    return name


def check_observer_name(name: Any) -> None:
    """Raise unless ``name`` is a registered observer."""
    if not isinstance(name, str) or name not in OBSERVER_DESIGNS:
        raise InputError("observer.observers",
                         f"unknown observer {name!r}; choose from {sorted(OBSERVER_DESIGNS)}")


def lyapunov(system: LinearSystem, q_s: np.ndarray, u_s: np.ndarray, q_m: np.ndarray,
             u_m: np.ndarray) -> np.ndarray:
    """V = ½(u_s−u_m)ᵀM(u_s−u_m) + ½(q_s−q_m)ᵀK(q_s−q_m), time-major (N+1,) output."""
    v = u_s - u_m
    e = q_s - q_m
    return 0.5 * quadratic_rows(v, system.M) + 0.5 * quadratic_rows(e, system.K)


def lyapunov_decrements(system: LinearSystem, h: float, a: dict, b: dict) -> dict[str, np.ndarray]:
    """Per-step parts of ΔV between trajectories ``a`` and ``b`` (dicts with q, u, P, sigma).

    For θ = ½ the scheme gives exactly (discrete twin of eq. (17))::

        V_{k+1} − V_k = −h v̄ᵀCv̄  +  (Wᵀv̄)ᵀ(P_a − P_b)  +  [½‖e⁺‖²_K − ½‖e⁻‖²_K]

    with v̄ = (v_k + v_{k+1})/2 and e⁻ the error before the step's position projections
    (from the dicts' ``q_pre`` when both have it, as for a projection in another metric;
    else e⁻ = e⁺ − K⁻¹W(Σ_a − Σ_b), the K-metric projection). Returns arrays of shape (N+1,) (row k+1 = step k) named
    ``damping``, ``impulse``, ``projection``, ``total`` (= ΔV) and ``residual``
    (ΔV minus the three parts: round-off for θ = ½).
    """
    v = a["u"] - b["u"]
    e = a["q"] - b["q"]
    vbar = 0.5 * (v[1:] + v[:-1])
    out = {k: np.zeros(v.shape[0]) for k in ("damping", "impulse", "projection", "total", "residual")}
    out["damping"][1:] = -h * quadratic_rows(vbar, system.C)
    out["impulse"][1:] = np.einsum("ki,ki->k", vbar @ system.W, a["P"][1:] - b["P"][1:])
    dsig = _sigma(a, v.shape) - _sigma(b, v.shape)
    if "q_pre" in a and "q_pre" in b:          # any projection metric: the recorded pre-jump states
        e_pre = a["q_pre"][1:] - b["q_pre"][1:]
        out["projection"][1:] = 0.5 * (quadratic_rows(e[1:], system.K)
                                       - quadratic_rows(e_pre, system.K))
    elif np.any(dsig):                         # the K metric: e⁻ = e⁺ − K⁻¹WΔΣ
        de = (np.linalg.solve(system.K, system.W @ dsig[1:].T).T if not system.sparse
              else spla.splu(sp.csc_matrix(system.K)).solve(np.asarray(system.W @ dsig[1:].T)).T)
        e_pre = e[1:] - de
        out["projection"][1:] = 0.5 * (quadratic_rows(e[1:], system.K)
                                       - quadratic_rows(e_pre, system.K))
    V = lyapunov(system, a["q"], a["u"], b["q"], b["u"])
    out["total"][1:] = np.diff(V)
    out["residual"] = out["total"] - out["damping"] - out["impulse"] - out["projection"]
    return out


def _sigma(traj: dict, shape: tuple[int, int]) -> np.ndarray:
    s = traj.get("sigma")
    if s is None:
        return np.zeros((shape[0], traj["P"].shape[1]))
    return s


def make_slaves(cfg: ObserverConfig, observers: list) -> list[Slave]:
    """Observer names become slaves started from the ``[observer]`` state; Slave objects pass."""
    out: list[Slave] = []
    for ob in observers:
        if isinstance(ob, Slave):
            out.append(ob)
            continue
        ob = design_name(ob)
        check_observer_name(ob)
        design = OBSERVER_DESIGNS[ob]
        out.append(Slave(ob, design.position_jumps, cfg.q0, cfg.u0, design))
    names = [s.name for s in out]
    if len(set(names)) != len(names):
        raise InputError("observer.observers", f"observer names must be unique, got {names}")
    return out
