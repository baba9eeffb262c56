"""The observers' own model: a plant that differs from the model the observers carry.

The paper's observers (eqs. (7)-(11)) are replicas of the plant, eqs. (1)-(3). A practitioner's
observer carries a *nominal* model ``(M̂, Ĉ, K̂, Ŵ, f̂, ν̂, law)`` while the plant is
``(M, C, K, W, f, ν, law)``. The ``[observer.model]`` table of a scenario (or the ``model=``
keyword of :func:`observer.simulate`, :func:`observer.ensemble` and :func:`observer.compare`)
gives that model: each of M, C, K, W in full (a nested array) or as a relative perturbation
of the plant's, and the forcing, the gap offset ν and the impact law as tables whose keys
replace the plant's.

Semantics (:mod:`observer.engines.timestepping`, :mod:`observer.engines.compiled.members`):
the master is the true plant; each observer advances the nominal model driven by χ from the
plant (its closed set, or a log); V and the position/velocity errors are measured against
the plant's state, in the quadratic forms of the plant's M and K (``error_metric = "plant"``,
the default) or of the model's (``"model"``); the result's ``metadata["observer_model"]`` says
which. With no model table every code path is today's (bitwise).

Perturbations of a matrix A of the plant (the same keys for M, C, K and W)::

    K = { scale = 1.01 }                   # Â = 1.01·A (scale > 0)
    K = { factors = [[...], [...]] }       # Â = A ∘ F (entrywise; F of A's shape)
    K = { relative_std = 0.01, seed = 3 }  # Â = A ∘ (1 + σZ), Z standard normal

The random perturbation draws Z from ``numpy.random.default_rng(seed)`` (the seed is
required: results are reproducible); for M, C and K, Z is symmetric (its upper triangle
drawn row by row, mirrored), so Â is exactly symmetric and keeps A's zeros. A draw that
leaves M not positive definite, C or K not positive semi-definite, or K not positive
definite where the plant's is, is **refused** (an :class:`~observer.errors.InputError`
naming ``observer.model.K``), never resampled: choose another seed or a smaller size.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from observer.errors import InputError

MATRICES = ("M", "C", "K", "W")
"""The model's matrices, each given in full or as a perturbation of the plant's."""
SYMMETRIC = ("M", "C", "K")
"""The matrices a random perturbation keeps symmetric."""
PERTURBATION_KEYS = ("scale", "factors", "relative_std", "seed")
"""The keys of a perturbation table (exactly one of scale, factors, relative_std; seed goes
with relative_std)."""
ERROR_METRICS = ("plant", "model")
"""Whose M and K measure V and the errors (``error_metric``)."""
PREFIX = "observer.model"

_HARMONIC = {"amplitude": None, "omega": None, "phase": None}
MODEL_SCHEMA: dict = {
    "M": None, "C": None, "K": None, "W": None,
    "forcing": {"constant": None, **_HARMONIC, "harmonics": [_HARMONIC]},
    "gap": {"offset": None, **_HARMONIC, "harmonics": [_HARMONIC]},
    "impact": {"law": None, "restitution": None},
    "error_metric": None,
}
"""The keys of ``[observer.model]`` (the scenario's :data:`observer.scenario.SCHEMA` holds it)."""


@dataclass(frozen=True)
class ObserverModel:
    """The observers' nominal model, validated.

    Attributes
    ----------
    system : LinearSystem
        The model's M, C, K, W, forcing and gap (eqs. (1)-(3) with the model's data).
    law : ImpactLaw
        The model's impact law and restitution.
    error_metric : {"plant", "model"}
        Whose M and K measure V = ½vᵀMv + ½eᵀKe (paper eq. (16)) and the errors.
    given : tuple of str
        The keys of the table that were given (the rest are the plant's).
    """

    system: Any
    law: Any
    error_metric: str
    given: tuple

    def metric_system(self, plant) -> Any:
        """The system whose M and K measure V: ``plant`` or :attr:`system`."""
        return plant if self.error_metric == "plant" else self.system

    def require_projection(self, slaves) -> None:
        """Raise unless the model's K-metric projection (eqs. (13)-(14)) is computable for every
        observer of ``slaves`` with position jumps in the K metric (the model's K ≻ 0 and
        WᵀK⁻¹W well conditioned; errors name ``observer.model.K`` or ``observer.model.W``)."""
        for s in slaves:
            if s.position_jumps and s.metric == "K":
                try:
                    self.system.require_definite_stiffness(f"the observer {s.name!r} (position jumps in the "
                                                           "K metric)")
                except InputError as exc:
                    raise _renamed(exc, "system", PREFIX) from None
                return

    def metadata(self, plant) -> dict:
        """What the result's ``metadata["observer_model"]`` records: the given keys, the metric
        and, per matrix, the relative difference ‖Â − A‖_F / ‖A‖_F (0 for the plant's own)."""
        from observer.sparse import dense

        rel = {}
        for name in MATRICES:
            A, B = dense(getattr(plant, name)), dense(getattr(self.system, name))
            size = float(np.linalg.norm(A))
            rel[name] = float(np.linalg.norm(B - A)) / size if size > 0 else float(np.linalg.norm(B))
        return {"given": list(self.given), "error_metric": self.error_metric,
                "metric": f"V and the errors against the plant's state, in the {self.error_metric}'s M and K",
                "relative_difference": rel}


def perturbed(name: str, A: np.ndarray, spec: Any) -> np.ndarray:
    """The model's matrix ``name`` from the plant's ``A`` and the table's value ``spec``: a
    full matrix (A's shape), or a perturbation table (module docstring).

    Raises
    ------
    InputError
        Naming ``observer.model.NAME`` (or its key): a wrong shape, a non-finite entry, an
        unknown key, scale ≤ 0, relative_std < 0, a missing or negative seed.
    """
    from observer.sparse import BANDED_KEYS, TRIPLET_KEYS, dense
    from observer.validation import as_array, as_matrix, as_scalar

    field = f"{PREFIX}.{name}"
    tables = set(TRIPLET_KEYS) | set(BANDED_KEYS)
    if not isinstance(spec, dict) or (spec and set(spec) <= tables):
        return np.array(dense(as_matrix(field, spec, A.shape)), dtype=float)
    unknown = sorted(set(spec) - set(PERTURBATION_KEYS))
    if unknown:
        raise InputError(f"{field}.{unknown[0]}", f"unknown key (known keys here: {', '.join(PERTURBATION_KEYS)})")
    kinds = [k for k in ("scale", "factors", "relative_std") if k in spec]
    if len(kinds) != 1:
        raise InputError(field, f"give exactly one of scale, factors, relative_std (got {kinds or list(spec)})")
    kind = kinds[0]
    if "seed" in spec and kind != "relative_std":
        raise InputError(f"{field}.seed", "goes with relative_std only")
    if kind == "scale":
        return as_scalar(f"{field}.scale", spec["scale"], positive=True) * A
    if kind == "factors":
        return A * as_array(f"{field}.factors", spec["factors"], A.shape)
    sigma = as_scalar(f"{field}.relative_std", spec["relative_std"], low=0.0)
    if "seed" not in spec:
        raise InputError(f"{field}.seed", "required with relative_std (results are reproducible)")
    seed = spec["seed"]
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"{field}.seed", f"must be a non-negative integer, got {seed!r}")
    Z = np.random.default_rng(int(seed)).standard_normal(A.shape)
    if name in SYMMETRIC:
        Z = np.triu(Z) + np.triu(Z, 1).T
    return A * (1.0 + sigma * Z)


def _renamed(exc: InputError, plant_prefix: str, model_prefix: str) -> InputError:
    """``exc`` with its field moved from the plant's table to the model's (``system.K`` →
    ``observer.model.K``)."""
    field = exc.field
    if field.startswith(plant_prefix):
        field = model_prefix + field[len(plant_prefix):]
    return InputError(field, exc.problem)


def build_model(table: Any, doc: dict, system, law, master_projection: bool = False) -> ObserverModel:
    """Validate ``[observer.model]`` (``table``) against the plant (``system``, ``law`` and the
    scenario document ``doc`` they came from) and build the :class:`ObserverModel`.

    The forcing, gap and impact tables' keys replace the plant's keys (``[observer.model.gap]
    offset = [...]`` keeps the plant's gap harmonics); W keeps the plant's number of contacts
    (χ is the plant's). Every error names ``observer.model.*``; the table's keys are checked
    with the scenario's (:data:`MODEL_SCHEMA` is part of :data:`observer.scenario.SCHEMA`).
    """
    from observer.impact import ImpactLaw
    from observer.model import LinearSystem, harmonic_table
    from observer.sparse import dense, is_sparse

    if not isinstance(table, dict):
        raise InputError(PREFIX, f"must be a table, got {type(table).__name__}")
    if system.sparse or any(is_sparse(getattr(system, k)) for k in MATRICES):
        raise InputError(PREFIX, f"needs a dense plant (n = {system.n} is held sparse)")
    metric = table.get("error_metric", "plant")
    if metric not in ERROR_METRICS:
        raise InputError(f"{PREFIX}.error_metric", f"must be one of {list(ERROR_METRICS)}, got {metric!r}")
    mats = {k: perturbed(k, dense(getattr(system, k)), table[k]) if k in table else getattr(system, k)
            for k in MATRICES}
    sysd = doc.get("system", {})
    merged = {key: {**(sysd.get(key) or {}), **table.get(key, {})} for key in ("forcing", "gap")}
    try:
        forcing = harmonic_table("system.forcing", merged["forcing"], system.n, "cos", "constant")
        gap = harmonic_table("system.gap", merged["gap"], system.m, "sin", "offset")
        model = LinearSystem(mats["M"], mats["C"], mats["K"], mats["W"], forcing, gap)
    except InputError as exc:
        raise _renamed(exc, "system", PREFIX) from None
    if "K" in table and system.is_stiffness_definite() and not model.is_stiffness_definite():
        raise InputError(f"{PREFIX}.K", "must be positive definite, as the plant's K is (smallest "
                         f"eigenvalue {model.stiffness_eigenvalue_range()[0]:.3g}): the perturbation "
                         "is refused, not resampled (another seed or a smaller size)")
    if master_projection:
        try:
            model.require_definite_stiffness("simulation.master_projection")
        except InputError as exc:
            raise _renamed(exc, "system", PREFIX) from None
    impact = {**doc.get("impact", {}), **table.get("impact", {})}
    try:
        model_law = ImpactLaw.build(impact.get("law", law.law), impact.get("restitution", law.restitution), system.m)
    except InputError as exc:
        raise _renamed(exc, "impact", f"{PREFIX}.impact") from None
    return ObserverModel(model, model_law, metric, tuple(k for k in MODEL_SCHEMA if k in table))


def plain_table(value: Any) -> Any:
    """``value`` (the ``[observer.model]`` table as the API may give it: NumPy arrays and
    scalars inside) as plain lists, floats and ints, for the TOML document."""
    if isinstance(value, dict):
        return {k: plain_table(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain_table(v) for v in value]
    if isinstance(value, (np.ndarray, np.generic)):
        return value.tolist()
    return value


def model_scenario(sc):
    """The nominal scenario of ``sc``: its model's system and law in place of the plant's, the
    rest (initial state, grid, solver, ``[observer]`` without its model) unchanged; the
    observers of a run of it are the model's observers."""
    model = sc.model
    observer = {k: v for k, v in sc.observer.items() if k != "model"}
    return dataclasses.replace(sc, system=model.system, law=model.law, observer=observer, model=None)


def with_model(sc, model: Any):
    """``sc`` with ``[observer.model]`` set to ``model`` (the ``model=`` keyword; None: ``sc``
    unchanged, the code path of a run without a model)."""
    if model is None:
        return sc
    return sc.with_overrides({PREFIX: model})
