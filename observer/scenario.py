"""Scenarios: a system, its impact law, initial state and simulation settings, as one document.

A scenario is read from a TOML file (or built by a module in :mod:`observer.scenarios`)
into a nested dict, validated against :data:`SCHEMA` (unknown keys are errors) and
turned into a frozen :class:`Scenario`. :meth:`Scenario.to_dict` gives the document back,
so that ``python -m observer show NAME`` prints a file that ``run`` accepts unchanged.

TOML format (the contract; ``[observer]`` is used by the observers)::

    [scenario]          name, description
    [system]            M, C, K (n×n), W (n×m, column j is w_j): each a nested array, or a
                        sparse triplet table {shape = [n, m], rows, cols, values}
                        (0-based, repeated pairs summed; large systems stay sparse)
    [system.forcing]    constant (n), amplitude (n), omega, phase  : f = c + a∘cos(ωt + φ)
    [[system.forcing.harmonics]]  amplitude, omega, phase          : more cos terms
    [system.gap]        offset (m), amplitude (m), omega, phase    : ν = o + a∘sin(ωt + φ)
    [[system.gap.harmonics]]      amplitude, omega, phase          : more sin terms
    [impact]            law = "newton" | "poisson", restitution (scalar or m-vector)
    [initial]           q, u
    [simulation]        t_end, h, theta, solver, master_projection
    [observer]          q, u, coupling = [t_on, t_off], source = "master" | "log", log,
                        observers = ["jump", "nojump"]
    [observer.sensor]   threshold, latency, sampling_period, jitter, missed, false_rate, seed
                        (χ from a contact sensor, :mod:`observer.sensor`)
    [observer.model]    M, C, K, W (full, or {scale}, {factors}, {relative_std, seed}),
                        forcing, gap, impact, error_metric: the observers' own model
                        (:mod:`observer.plant_model`)

``phase`` may be a scalar or a vector.
"""

from __future__ import annotations

import copy
import tomllib
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from observer.errors import InputError, InputWarning
from observer.impact import ImpactLaw
from observer.model import Harmonic, LinearSystem, harmonic_table
from observer.plant_model import MODEL_SCHEMA, build_model, plain_table
from observer.sensor import Sensor
from observer.solver_registry import solver_factory
from observer import sparse as sps
from observer.validation import (MAX_DEPTH, as_array, as_matrix, as_scalar, check_step_count,
                                 check_step_parameters)

_HARMONIC = {"amplitude": None, "omega": None, "phase": None}
SCHEMA: dict = {
    "scenario": {"name": None, "description": None},
    "system": {
        "M": None, "C": None, "K": None, "W": None,
        "forcing": {"constant": None, **_HARMONIC, "harmonics": [_HARMONIC]},
        "gap": {"offset": None, **_HARMONIC, "harmonics": [_HARMONIC]},
    },
    "impact": {"law": None, "restitution": None},
    "initial": {"q": None, "u": None},
    "simulation": {"t_end": None, "h": None, "theta": None, "solver": None, "master_projection": None},
    "observer": {"q": None, "u": None, "coupling": None, "source": None, "log": None,
                 "observers": None,
                 "sensor": {"threshold": None, "latency": None, "sampling_period": None, "jitter": None,
                            "missed": None, "false_rate": None, "seed": None},
                 "model": MODEL_SCHEMA},
}
REQUIRED = ("system.M", "system.C", "system.K", "system.W", "impact.law", "impact.restitution",
            "initial.q", "initial.u", "simulation.t_end", "simulation.h")

FIELDS: dict[str, tuple[str, str, str, str]] = {
    # dotted key (``[]`` marks an array of tables) -> (type, unit, default, meaning); the
    # documentation's TOML reference is generated from SCHEMA, REQUIRED and this table
    # (tests/docs/test_docs.py keeps the three in step)
    "scenario.name": ("string", "", "the file's stem", "name shown in results and reports"),
    "scenario.description": ("string", "", '""', "one line of prose"),
    "system.M": ("n×n matrix", "kg (or kg·m²)", "required", "mass matrix, M = Mᵀ ≻ 0"),
    "system.C": ("n×n matrix", "N·s/m", "required", "damping matrix, ½(C + Cᵀ) ≻ 0"),
    "system.K": ("n×n matrix", "N/m", "required", "stiffness matrix, K = Kᵀ ≻ 0"),
    "system.W": ("n×m matrix", "1", "required",
                 "contact directions: column j is w_j, gap g_j = w_jᵀq + ν_j(t)"),
    "system.forcing.constant": ("n-vector or scalar", "N", "0", "constant part c of f(t)"),
    "system.forcing.amplitude": ("n-vector or scalar", "N", "0", "amplitude a of a∘cos(ωt + φ)"),
    "system.forcing.omega": ("number ≥ 0", "rad/s", "0", "angular frequency ω of the forcing"),
    "system.forcing.phase": ("n-vector or scalar", "rad", "0", "phase φ of the forcing"),
    "system.forcing.harmonics[].amplitude": ("n-vector or scalar", "N", "0", "amplitude of one more cos term"),
    "system.forcing.harmonics[].omega": ("number ≥ 0", "rad/s", "0", "its angular frequency"),
    "system.forcing.harmonics[].phase": ("n-vector or scalar", "rad", "0", "its phase"),
    "system.gap.offset": ("m-vector or scalar", "m", "0", "constant part o of ν(t)"),
    "system.gap.amplitude": ("m-vector or scalar", "m", "0", "amplitude a of a∘sin(ωt + φ)"),
    "system.gap.omega": ("number ≥ 0", "rad/s", "0", "angular frequency ω of the gap motion"),
    "system.gap.phase": ("m-vector or scalar", "rad", "0", "phase φ of the gap motion"),
    "system.gap.harmonics[].amplitude": ("m-vector or scalar", "m", "0", "amplitude of one more sin term"),
    "system.gap.harmonics[].omega": ("number ≥ 0", "rad/s", "0", "its angular frequency"),
    "system.gap.harmonics[].phase": ("m-vector or scalar", "rad", "0", "its phase"),
    "impact.law": ('"newton" or "poisson"', "", "required", "impact law (a key of IMPACT_LAWS)"),
    "impact.restitution": ("m-vector or scalar in [0, 1]", "1", "required", "restitution coefficients"),
    "initial.q": ("n-vector", "m (or rad)", "required", "master's initial position, g(q0, 0) ≥ 0"),
    "initial.u": ("n-vector", "m/s (or rad/s)", "required", "master's initial velocity"),
    "simulation.t_end": ("number > 0", "s", "required", "end of the run (at least one step)"),
    "simulation.h": ("number > 0", "s", "required", "time step"),
    "simulation.theta": ("number in [0.5, 1]", "1", "0.5", "Moreau–Jean θ"),
    "simulation.solver": ("string", "", '"pivoting"', "contact solver (a key of CONTACT_SOLVERS)"),
    "simulation.master_projection": ("boolean", "", "false",
                                     "project the master's positions on its own closed set"),
    "observer.q": ("n-vector", "m (or rad)", "initial.q", "observers' initial position"),
    "observer.u": ("n-vector", "m/s (or rad/s)", "initial.u", "observers' initial velocity"),
    "observer.coupling": ("[t_on, t_off]", "s", "the whole run", "interval in which the observers are coupled"),
    "observer.source": ('"master", "log" or "self"', "", '"master"', "where the switching signal χ comes from"),
    "observer.log": ("file path", "", "none (required with source = \"log\")",
                     "closing log (contact, t_close, t_open), relative to the TOML file"),
    "observer.observers": ("array of design names", "", '["jump", "nojump"]',
                           "observer designs to run (keys of OBSERVER_DESIGNS)"),
    # [observer.sensor]: χ from a contact sensor (observer/sensor.py, docs/guide/sensors.md)
    "observer.sensor.threshold": ("number ≥ 0", "m", "0", "gap δ at or below which a contact is seen "
                                  "closed (0: the master's closed set; not with source = \"log\")"),
    "observer.sensor.latency": ("number ≥ 0", "s", "0", "delay d of every reported closing and opening"),
    "observer.sensor.sampling_period": ("number > 0", "s", "none (every step)",
                                        "χ read at t = j·T and held in between"),
    "observer.sensor.jitter": ("number ≥ 0", "s", "0", "standard deviation σ of each endpoint's time error"),
    "observer.sensor.missed": ("number in [0, 1]", "1", "0", "probability that a closing or impact is not seen"),
    "observer.sensor.false_rate": ("number ≥ 0", "1/s", "0", "rate λ of false impacts (Poisson)"),
    "observer.sensor.seed": ("integer ≥ 0", "", "0", "seed of the sensor's missed, false and jitter draws"),
    **{f"observer.model.{k}": (f"{shape} matrix or perturbation table", unit, f"the plant's system.{k}",
                               f"observers' {k}: in full, or {{scale}}, {{factors}}, {{relative_std, seed}} "
                               "of the plant's (guide: model error)")
       for k, shape, unit in (("M", "n×n", "kg (or kg·m²)"), ("C", "n×n", "N·s/m"), ("K", "n×n", "N/m"),
                              ("W", "n×m", "1"))},
    **{f"observer.model.{key}": (kind, unit, f"system.{key}", f"observers' {meaning} (replaces the plant's key)")
       for key, (kind, unit, meaning) in {
           "forcing.constant": ("n-vector or scalar", "N", "constant part of f(t)"),
           "forcing.amplitude": ("n-vector or scalar", "N", "forcing amplitude"),
           "forcing.omega": ("number ≥ 0", "rad/s", "forcing angular frequency"),
           "forcing.phase": ("n-vector or scalar", "rad", "forcing phase"),
           "forcing.harmonics[].amplitude": ("n-vector or scalar", "N", "forcing terms (all of them)"),
           "forcing.harmonics[].omega": ("number ≥ 0", "rad/s", "their angular frequencies"),
           "forcing.harmonics[].phase": ("n-vector or scalar", "rad", "their phases"),
           "gap.offset": ("m-vector or scalar", "m", "gap offset, constant part of ν(t)"),
           "gap.amplitude": ("m-vector or scalar", "m", "gap motion amplitude"),
           "gap.omega": ("number ≥ 0", "rad/s", "gap motion angular frequency"),
           "gap.phase": ("m-vector or scalar", "rad", "gap motion phase"),
           "gap.harmonics[].amplitude": ("m-vector or scalar", "m", "gap motion terms (all of them)"),
           "gap.harmonics[].omega": ("number ≥ 0", "rad/s", "their angular frequencies"),
           "gap.harmonics[].phase": ("m-vector or scalar", "rad", "their phases"),
           "impact.law": ('"newton" or "poisson"', "", "impact law"),
           "impact.restitution": ("m-vector or scalar in [0, 1]", "1", "restitution coefficients"),
       }.items()},
    "observer.model.error_metric": ('"plant" or "model"', "", '"plant"',
                                    "whose M and K measure V and the errors against the plant's state"),
}
"""The documented fields of a scenario document: every leaf of :data:`SCHEMA`, with its type,
unit, default and meaning (``required`` for the keys of :data:`REQUIRED`)."""


def schema_fields(schema: Any = None, prefix: str = "") -> list[str]:
    """The dotted keys of every leaf of ``schema`` (default :data:`SCHEMA`), in document order;
    an array of tables contributes ``KEY[].FIELD``."""
    schema = SCHEMA if schema is None else schema
    keys: list[str] = []
    for key, sub in schema.items():
        name = f"{prefix}.{key}" if prefix else key
        if sub is None:
            keys.append(name)
        elif isinstance(sub, list):
            keys += schema_fields(sub[0], name + "[]")
        else:
            keys += schema_fields(sub, name)
    return keys


INITIAL_GAP_TOL = 1e-9
"""Largest accepted initial penetration, relative to max(1, max|ν(0)|, max|Wᵀq0|)."""


def check_keys(doc: Any, schema: Any, prefix: str = "") -> None:
    """Raise :class:`InputError` on any key of ``doc`` that ``schema`` does not know."""
    if isinstance(schema, list):
        if not isinstance(doc, list):
            raise InputError(prefix, "must be an array of tables")
        for i, item in enumerate(doc):
            check_keys(item, schema[0], f"{prefix}[{i}]")
        return
    if schema is None:
        return
    if not isinstance(doc, dict):
        raise InputError(prefix, "must be a table")
    for key, value in doc.items():
        name = f"{prefix}.{key}" if prefix else key
        if key not in schema:
            known = ", ".join(sorted(schema))
            raise InputError(name, f"unknown key (known keys here: {known})")
        check_keys(value, schema[key], name)


def _get(doc: dict, dotted: str, default: Any = KeyError) -> Any:
    node: Any = doc
    for part in dotted.split("."):
        if not isinstance(node, dict) or part not in node:
            if default is KeyError:
                raise InputError(dotted, "required key is missing")
            return default
        node = node[part]
    return node


def parse_value(text: str) -> Any:
    """Parse a ``--set`` value as a TOML value (number, array, bool, quoted string) or a bare string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text
    except RecursionError:
        raise InputError("--set", f"value {text[:40]!r}... nested deeper than {MAX_DEPTH} levels") from None


def check_overrides(overrides: Any) -> dict[str, Any]:
    """``overrides`` as a dict of dotted string keys (``{"simulation.h": 1e-3}``), or raise
    :class:`InputError` naming ``overrides``."""
    if overrides is None:
        return {}
    if not isinstance(overrides, Mapping):
        raise InputError("overrides", f"must be a dict of dotted keys to values, such as "
                         f"{{'simulation.h': 1e-3}}, got {type(overrides).__name__}")
    for key in overrides:
        if not isinstance(key, str):
            raise InputError("overrides", f"keys must be dotted strings such as 'simulation.h', "
                             f"got {key!r}")
    return dict(overrides)


def apply_overrides(doc: dict, overrides: dict[str, Any]) -> dict:
    """Return a copy of ``doc`` with dotted keys set (``{"simulation.h": 1e-3}``); keys are checked later.

    Only the tables on the path of an override are copied (the input is never modified);
    the values, matrices included, are shared, so the cost does not grow with their size.
    """
    doc = dict(doc)
    for key, value in check_overrides(overrides).items():
        parts = key.split(".")
        if not all(part.strip() for part in parts):
            raise InputError(key or "--set", f"empty key component in {key!r} (expected a dotted "
                             "key such as simulation.h)")
        node = doc
        for part in parts[:-1]:
            child = node.get(part, {})
            if not isinstance(child, dict):
                raise InputError(key, "cannot set a key inside a non-table value")
            node[part] = child = dict(child)
            node = child
        node[parts[-1]] = parse_value(value) if isinstance(value, str) else value
    return doc


@dataclass(frozen=True)
class Scenario:
    """A complete, validated simulation case.

    Attributes
    ----------
    name, description : str
    system : LinearSystem
    law : ImpactLaw
    q0, u0 : ndarray, shape (n,)
        Initial state of the master (g(q0, 0) ≥ 0 up to :data:`INITIAL_GAP_TOL`).
    t_end, h, theta : float
    solver : str
        Contact solver name.
    master_projection : bool
        Use the position-projected master (K-metric projection on its own closed set).
    observer : dict
        The raw ``[observer]`` table (validated by :mod:`observer.observers`).
    model : ObserverModel or None
        The observers' own model, from ``[observer.model]`` (:mod:`observer.plant_model`);
        None: the observers carry the plant's.
    """

    name: str
    description: str
    system: LinearSystem
    law: ImpactLaw
    q0: np.ndarray
    u0: np.ndarray
    t_end: float
    h: float
    theta: float = 0.5
    solver: str = "pivoting"
    master_projection: bool = False
    observer: dict = field(default_factory=dict)
    source: str = ""
    model: Any = field(default=None, compare=False, repr=False)

    # -- construction ----------------------------------------------------------------------
    @staticmethod
    def from_dict(doc: dict, source: str = "", system: LinearSystem | None = None) -> "Scenario":
        """Validate a scenario document (see module docstring) and build the scenario.

        ``system``: the already validated system of ``doc["system"]`` (:meth:`with_overrides`
        when no ``system.*`` key changes: its checks are not repeated)."""
        if not isinstance(doc, dict):
            raise InputError("scenario", f"the document must be a table (a dict), got "
                             f"{type(doc).__name__}")
        check_keys(doc, SCHEMA)
        for key in REQUIRED:
            _get(doc, key)
        sysd = doc["system"]
        M = as_matrix("system.M", sysd["M"], (None, None))
        n = M.shape[0]
        if M.shape != (n, n) or n == 0:
            raise InputError("system.M", f"must be a non-empty square matrix, got shape "
                             f"{M.shape[0]}x{M.shape[1]}")
        check_dimensions(sysd, n)
        W = as_matrix("system.W", sysd["W"], (n, None))
        m = W.shape[1]
        if m == 0:
            raise InputError("system.W", "needs at least one contact column")
        if not isinstance(sysd.get("gap", {}), dict) or "offset" not in sysd.get("gap", {}):
            warnings.warn(f"system.gap.offset: not given, so every contact's offset is 0: the "
                          f"{m} contact(s) close where Wᵀq = 0 (a table [system.gap] with "
                          f"offset = [...] sets the distances at q = 0)", InputWarning, stacklevel=3)
        forcing = harmonic_table("system.forcing", sysd.get("forcing", {}), n, "cos", "constant")
        gap = harmonic_table("system.gap", sysd.get("gap", {}), m, "sin", "offset")
        if system is None:
            system = LinearSystem(M, sysd["C"], sysd["K"], W, forcing, gap)
        law = ImpactLaw.build(doc["impact"]["law"], doc["impact"]["restitution"], m)
        q0 = as_array("initial.q", doc["initial"]["q"], (n,))
        u0 = as_array("initial.u", doc["initial"]["u"], (n,))
        simd = doc["simulation"]
        h, theta = check_step_parameters(simd["h"], simd.get("theta", 0.5))
        t_end = as_scalar("simulation.t_end", simd["t_end"], positive=True)
        if t_end < h:
            raise InputError("simulation.t_end", f"must be at least one step h = {h!r}, got {t_end!r}")
        check_step_count(h, t_end)
        check_angles("system.forcing", sysd.get("forcing", {}), forcing, t_end)
        check_angles("system.gap", sysd.get("gap", {}), gap, t_end)
        solver = simd.get("solver", "pivoting")
        solver_factory(solver, field="simulation.solver")
        projection = simd.get("master_projection", False)
        if not isinstance(projection, bool):
            raise InputError("simulation.master_projection", f"must be true or false, got {projection!r}")
        if projection:
            system.require_definite_stiffness("simulation.master_projection")
        check_initial_gap("initial.q", system, q0)
        check_finite_energy("initial", system, q0, u0)
        Sensor.from_table(doc.get("observer", {}).get("sensor"))
        meta = doc.get("scenario", {})
        observer = dict(doc.get("observer", {}))
        model = (build_model(observer["model"], doc, system, law, projection) if "model" in observer
                 else None)
        return Scenario(str(meta.get("name", Path(source).stem if source else "custom")),
                        str(meta.get("description", "")), system, law, q0, u0, t_end, h, theta,
                        solver, projection, observer, source, model)

    def to_dict(self) -> dict:
        """The scenario as a TOML-ready document (inverse of :meth:`from_dict`): dense
        matrices as nested lists, sparse ones as banded or triplet tables, the shorter
        (:func:`observer.sparse.sparse_document`; never densified)."""
        return self._document(plain=True)

    def _document(self, plain: bool) -> dict:
        """The document; ``plain=False`` keeps the matrices and the initial state as the arrays
        they are (what :meth:`with_overrides` hands back to :meth:`from_dict`: no round trip
        through Python lists)."""
        s = self.system

        def mat(A):
            if not plain:
                return A
            return sps.sparse_document(A) if sps.is_sparse(A) else A.tolist()

        def vec(x):              # long periodic vectors compact ({n, pattern, ...}), else lists
            return sps.vector_document(x) if plain else x

        def harmonic(hm: Harmonic, const_key: str) -> dict:
            d: dict = {const_key: vec(hm.constant)}
            terms = [{k: vec(v) if isinstance(v, list) else v for k, v in t.items()} for t in hm.terms()]
            if terms:
                d.update(terms[0])
                if len(terms) > 1:
                    d["harmonics"] = terms[1:]
            return d

        doc = {
            "scenario": {"name": self.name, "description": self.description},
            "system": {"M": mat(s.M), "C": mat(s.C), "K": mat(s.K), "W": mat(s.W),
                       "forcing": harmonic(s.forcing, "constant"), "gap": harmonic(s.gap, "offset")},
            "impact": {"law": self.law.law, "restitution": vec(self.law.restitution.tolist())
                       if not self.law.is_global else float(self.law.restitution[0])},
            "initial": {"q": vec(self.q0), "u": vec(self.u0)},
            "simulation": {"t_end": self.t_end, "h": self.h, "theta": self.theta,
                           "solver": self.solver, "master_projection": self.master_projection},
        }
        if self.observer:
            doc["observer"] = copy.deepcopy(self.observer)
            for key in ("q", "u"):
                if isinstance(doc["observer"].get(key), (list, np.ndarray)):
                    doc["observer"][key] = vec(doc["observer"][key])
            if plain and "model" in doc["observer"]:
                doc["observer"]["model"] = plain_table(doc["observer"]["model"])
        return doc

    def with_overrides(self, overrides: dict[str, Any]) -> "Scenario":
        """A new scenario with dotted-key overrides applied to its document."""
        overrides = check_overrides(overrides)
        same = not any(k == "system" or k.startswith("system.") for k in overrides)
        return Scenario.from_dict(apply_overrides(self._document(plain=False), overrides), self.source,
                                  self.system if same else None)

    def parameters(self) -> dict:
        """Flat metadata describing the run settings (for results and reports)."""
        return {"scenario": self.name, "n": self.system.n, "m": self.system.m, "h": self.h,
                "theta": self.theta, "t_end": self.t_end, "law": self.law.law,
                "restitution": self.law.restitution.tolist(), "solver": self.solver,
                "master_projection": self.master_projection}


def _rows(value: Any) -> int | None:
    """The row count of a system matrix as the document gives it (a nested list, an array, a
    sparse matrix or a sparse table), without converting it; None when it has none."""
    if isinstance(value, Mapping):
        shape = value.get("shape")
        return shape[0] if isinstance(shape, (list, tuple)) and shape and isinstance(shape[0], int) else None
    if sps.is_sparse(value) or isinstance(value, np.ndarray):
        return int(value.shape[0]) if np.ndim(value) else None
    return len(value) if isinstance(value, (list, tuple)) else None


def check_dimensions(sysd: dict, n: int) -> None:
    """Raise unless C, K and W have the n rows of the n×n M, naming the matrices that disagree
    (a 2×2 M with a 3×3 K and C is an M of the wrong size, not a W of the wrong shape)."""
    rows = {"system.M": n, **{f"system.{k}": _rows(sysd[k]) for k in ("C", "K", "W")}}
    off = {f: r for f, r in rows.items() if r is not None and r != n}
    if not off:
        return
    counts = {r: sum(v == r for v in rows.values()) for r in set(rows.values()) if r is not None}
    common = max(counts, key=lambda r: (counts[r], r == n))
    wrong = [f for f, r in rows.items() if r is not None and r != common]
    agree = [f for f, r in rows.items() if r == common]

    def size(f):
        return f"{rows[f]} rows" if f == "system.W" else f"{rows[f]}x{rows[f]}"
    raise InputError(wrong[0], f"the system matrices disagree on the number of coordinates n: "
                     + ", ".join(f"{f} {'has' if f == 'system.W' else 'is'} {size(f)}" for f in wrong)
                     + " but "
                     + ", ".join(f"{f} {'has' if f == 'system.W' else 'is'} {size(f)}" for f in agree)
                     + " (M, C, K are n×n, W has n rows)")


def check_finite_energy(prefix: str, system: LinearSystem, q: np.ndarray, u: np.ndarray) -> None:
    """Raise unless the state's kinetic ½uᵀMu and elastic ½qᵀKq energies are finite numbers.

    Every number of a run (V, its parts, the energy balance) is a quadratic form of the
    states: a finite state whose energy overflows (``u = 1e200``) would hand back inf/NaN.
    Errors name ``PREFIX.u`` or ``PREFIX.q``.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        kinetic = 0.5 * float(u @ (system.M @ u))
        elastic = 0.5 * float(q @ (system.K @ q))
        gaps = q @ system.W
    if not np.isfinite(kinetic):
        raise InputError(f"{prefix}.u", f"kinetic energy ½uᵀMu overflows ({kinetic}): the state is too large")
    if not (np.isfinite(elastic) and np.all(np.isfinite(gaps))):
        raise InputError(f"{prefix}.q", f"elastic energy ½qᵀKq or the gaps overflow ({elastic}): "
                         "the state is too large")


def check_angles(field_name: str, d: dict, signal: Harmonic, t_end: float) -> None:
    """Raise unless every term's angle ω·t + phase stays finite up to ``t_end`` (an overflowing
    angle makes cos and sin NaN); the error names the term's ``omega``."""
    names = ([field_name] if any(k in d for k in ("amplitude", "omega", "phase")) else []) + \
        [f"{field_name}.harmonics[{j}]" for j in range(len(d.get("harmonics", [])))]
    with np.errstate(over="ignore"):
        for name, w, p in zip(names, signal.omega, signal.phase):
            angle = abs(w) * t_end + float(np.max(np.abs(p), initial=0.0))
            if not np.isfinite(angle):
                raise InputError(f"{name}.omega", f"the angle omega·t + phase overflows by t_end = "
                                 f"{t_end!r} (omega = {float(w)!r})")


def check_initial_gap(field_name: str, system: LinearSystem, q0: np.ndarray, t0: float = 0.0) -> None:
    """Raise if the initial state penetrates a contact by more than :data:`INITIAL_GAP_TOL`."""
    g = system.gaps(q0, t0)
    scale = max(1.0, float(np.max(np.abs(system.nu(t0)))), float(np.max(np.abs(q0 @ system.W))))
    if np.min(g) < -INITIAL_GAP_TOL * scale:
        j = int(np.argmin(g))
        raise InputError(field_name, f"initial state penetrates contact {j}: g = {g[j]:.6g} < 0")


BUILDER_FAILURES = (np.linalg.LinAlgError, ZeroDivisionError, FloatingPointError, OverflowError,
                    MemoryError)
"""Failures of a built-in's document builder (numerical, or a system too large to build),
reported as bad ``param.*`` values."""


def check_builder_parameters(name: str, params: dict[str, Any]) -> dict[str, Any]:
    """Validate ``param.*`` values of built-in ``name`` against its defaults; return them.

    A parameter must exist; a numeric default needs a finite number (an integer default an
    integer), a string default a string. Ranges are the builder's and the model's to check.
    """
    from observer.scenarios import SCENARIOS
    defaults = SCENARIOS[name].PARAMETERS
    out = {}
    for key, value in params.items():
        field_name = f"param.{key}"
        if key not in defaults:
            raise InputError(field_name, f"unknown parameter of scenario {name!r} "
                             f"(known: {', '.join(defaults)})")
        default = defaults[key]
        if isinstance(default, str):
            if not isinstance(value, str):
                raise InputError(field_name, f"must be a string, got {value!r}")
        elif isinstance(default, (int, float)) and not isinstance(default, bool):
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise InputError(field_name, f"must be a number, got {value!r}")
            value = as_scalar(field_name, value)
            if isinstance(default, int):
                if value != int(value):
                    raise InputError(field_name, f"must be an integer, got {value!r}")
                value = int(value)
        check_build_memory(name, key, value)
        out[key] = value
    return out


def check_build_memory(name: str, key: str, value: Any) -> None:
    """Raise before building when a size parameter's memory estimate exceeds the memory
    available: a scenario module's ``MEMORY_PER_UNIT`` maps a parameter (the chain's ``N``) to
    the bytes its build takes per unit (measured, with a margin); none, no check. Without it
    a huge ``param.N`` was killed by the kernel (exit 137, nothing said)."""
    from observer.scenarios import SCENARIOS
    from observer import memory
    per = getattr(SCENARIOS[name], "MEMORY_PER_UNIT", {}).get(key)
    avail = memory.available_memory()
    if per is None or avail is None or value * per <= avail:
        return
    raise InputError(f"param.{key}", f"{key} = {value} needs about {value * per / 2 ** 30:.3g} GiB to "
                     f"build scenario {name!r} ({per} bytes per unit, estimated) but "
                     f"{avail / 2 ** 30:.3g} GiB are available")


def builtin_scenario_document(name: str, params: dict[str, Any] | None = None) -> dict:
    """The document of built-in ``name`` built with ``params``; bad values become :class:`InputError`.

    A numerical failure of the builder (a singular K for the static equilibrium, a division
    by zero...) is reported on the parameters that were set (``param.k1: ...``).
    """
    from observer.scenarios import builtin_document
    params = check_builder_parameters(name, dict(params or {}))
    try:
        return builtin_document(name, params)
    except BUILDER_FAILURES as exc:
        raise InputError(_param_fields(params), f"scenario {name!r} cannot be built with "
                         f"{_param_text(params)}: {type(exc).__name__}: {exc}") from None


def _param_fields(params: dict[str, Any]) -> str:
    return ", ".join(f"param.{k}" for k in params) or "param"


def _param_text(params: dict[str, Any]) -> str:
    return ", ".join(f"{k} = {v!r}" for k, v in params.items()) or "its default parameters"


def load_scenario(name_or_path: "str | Path | Scenario",
                  overrides: dict[str, Any] | None = None) -> Scenario:
    """Load a built-in scenario by name or a TOML file by path, with dotted-key overrides.

    Keys ``param.NAME`` set a built-in's builder parameter (e.g. ``{"param.N": 5}`` for
    ``rocking_chain``); every other key addresses the TOML document
    (``{"simulation.h": 1e-3, "impact.law": "newton"}``). String values are parsed as
    TOML values, so CLI ``--set`` strings work unchanged. A model error caused by the
    builder parameters (``param.m1 = 0`` makes M singular) names the parameters.
    """
    from observer.scenarios import SCENARIOS
    from observer.tomlio import read_toml
    overrides = check_overrides(overrides)
    if isinstance(name_or_path, Scenario):
        return name_or_path.with_overrides(overrides) if overrides else name_or_path
    params = {k[len("param."):]: (parse_value(v) if isinstance(v, str) else v)
              for k, v in overrides.items() if k.startswith("param.")}
    rest = {k: v for k, v in overrides.items() if not k.startswith("param.")}
    name = str(name_or_path)
    if not name.strip():
        raise InputError("scenario", "empty name: give a built-in scenario "
                         f"({', '.join(SCENARIOS)}) or a .toml file")
    if name in SCENARIOS:
        doc, source = builtin_scenario_document(name, params), name
    elif name.endswith(".toml") or Path(name).exists():
        if params:
            raise InputError("param." + next(iter(params)),
                             "builder parameters apply only to built-in scenarios")
        doc, source = read_toml(name), name
    else:
        raise InputError("scenario", f"{name!r} is neither a built-in scenario "
                         f"({', '.join(SCENARIOS)}) nor an existing .toml file")
    try:
        return Scenario.from_dict(apply_overrides(doc, rest), source)
    except InputError as exc:
        if not params or exc.field in rest:
            raise
        raise InputError(_param_fields(params), f"scenario {name!r} built with "
                         f"{_param_text(params)} is invalid: {exc}") from None
