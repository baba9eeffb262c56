"""Simulation results: time-major arrays, a tidy DataFrame view, CSV/Parquet output.

Array layout (everywhere in the toolkit): time-major, ``shape (N+1, n)`` for N steps.
Row 0 is the initial state; row k+1 of ``P`` and ``active`` belongs to the step
t_k → t_{k+1} (the impulse of that step and the closed set it used).

pandas is imported only when a DataFrame is first needed: the tables of a result
(:attr:`SimulationResult.summary`, :attr:`SimulationResult.events`) may be given as a
:class:`LazyFrame` and are built on first read, so that a run whose tables nobody reads
(e.g. a long ``store="summary"`` run) does not load pandas and pyarrow.
"""

from __future__ import annotations

import enum
import functools
import json
import platform
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np

from observer.errors import InputError
from observer.io import events_path, jsonable, read_frame, read_result, remove_events, write_frame  # noqa: F401
from observer.metrics import RHOS
from observer.model import LinearSystem

if TYPE_CHECKING:
    import pandas as pd


@functools.lru_cache(maxsize=None)
def _versions() -> tuple:
    from importlib import metadata

    from observer.version import __version__

    out = {"python": platform.python_version(), "observer": __version__}
    for pkg in ("numpy", "scipy", "pandas", "cvxpy", "osqp", "matplotlib", "numba"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return tuple(out.items())


def package_versions() -> dict[str, str]:
    """Versions of Python, the toolkit and its numerical stack, for result metadata (read once)."""
    return dict(_versions())


def typed_command(argv: list[str] | None = None) -> str:
    """The command of this process as a user types it, for result metadata (no machine path):
    ``python -m observer run ...`` for a module run (``sys.argv[0]`` is then the absolute path
    of ``__main__.py``), ``observer run ...`` for an installed console script (its absolute
    path), ``python script.py ...`` for a script as given; the arguments quoted as a shell
    reads them back (:func:`shlex.join`)."""
    import shlex
    argv = list(sys.argv if argv is None else argv)
    if not argv:
        return ""
    head = Path(argv[0])
    if head.name == "__main__.py":
        first = ["python", "-m", head.parent.name]
    elif head.is_absolute() and head.suffix != ".py":
        first = [head.name]
    elif argv[0] in ("-c", ""):
        first = ["python", "-c"] if argv[0] == "-c" else ["python"]
    else:
        first = ["python", argv[0]]
    return shlex.join([*first, *argv[1:]])


@dataclass
class SlaveTrajectory:
    """One observer's trajectory and its error Lyapunov function.

    ``V[k] = ½(u_s−u_m)ᵀM(u_s−u_m) + ½(q_s−q_m)ᵀK(q_s−q_m)`` (paper (16) with the ½ on
    both terms); ``dV_damping``/``dV_impulse``/``dV_projection`` are the per-step parts of
    the discrete identity ``V_{k+1}−V_k = −h v̄ᵀCv̄ + (Wᵀv̄)ᵀΔP − ½ ΔgᵀL⁻¹Δg`` (row k+1 =
    step k); None when the run kept only every k-th step (``record_every > 1``).
    """

    name: str
    q: np.ndarray
    u: np.ndarray
    P: np.ndarray
    V: np.ndarray
    dV_damping: np.ndarray | None
    dV_impulse: np.ndarray | None
    dV_projection: np.ndarray | None
    sigma: np.ndarray


class RunState(str, enum.Enum):
    """How a run ended: ``ok``, ``fallback`` (some contact problems were re-solved by the
    reference solver) or ``stopped`` (the run ended before ``t_end``: a signal, a residual
    above tolerance, a non-finite quantity); ``partial`` is the state of a file read with
    ``read_result(path, partial=True)`` that could not be proven whole (:mod:`observer.io`)."""

    OK = "ok"
    FALLBACK = "fallback"
    STOPPED = "stopped"
    PARTIAL = "partial"


@dataclass(frozen=True)
class RunStatus:
    """The state a run ended in and why (empty reason for ``ok``).

    Attributes
    ----------
    state : RunState
    reason : str
        One line a user can act on, e.g. ``"3 steps re-solved by the reference solver"``.
    warnings : tuple of str
        The run's health warnings (:mod:`observer.health`): outside the regime where its
        numbers mean anything (h·ω_max, penetration, energy growth), whatever the state.
    """

    state: RunState = RunState.OK
    reason: str = ""
    warnings: tuple = ()

    def __post_init__(self):
        object.__setattr__(self, "warnings", tuple(self.warnings or ()))
        try:
            object.__setattr__(self, "state", RunState(self.state))
        except ValueError:
            raise InputError("status.state", f"must be one of {[s.value for s in RunState]}, "
                                             f"got {self.state!r}") from None
        if self.state is not RunState.OK and not self.reason:
            raise InputError("status.reason", f"a {self.state.value!r} status needs a reason")

    @property
    def ok(self) -> bool:
        """True only for a run that ended normally without any fallback."""
        return self.state is RunState.OK

    def __str__(self) -> str:
        """``"ok"``, else ``"STATE: reason"`` (e.g. ``"stopped: event cap 10 reached at t = …"``)."""
        return self.state.value if self.ok else f"{self.state.value}: {self.reason}"

    @classmethod
    def from_metadata(cls, metadata: dict) -> "RunStatus":
        """The status a run's metadata implies: ``stopped`` when it has ``stopped`` (the
        loop's stop: where and why), else ``fallback`` when ``solver_fallbacks > 0``; with
        the warnings of ``metadata["health"]``."""
        warnings = tuple((metadata.get("health") or {}).get("warnings") or ())
        stopped = metadata.get("stopped")
        if stopped:
            return cls(RunState.STOPPED, f"stopped: {stopped['reason']}", warnings)
        n = int(metadata.get("solver_fallbacks") or 0)
        if n:
            return cls(RunState.FALLBACK, f"{n} step(s) re-solved by the reference solver "
                                          "(metadata fallback_steps)", warnings)
        return cls(warnings=warnings)

    def to_dict(self) -> dict:
        d = {"state": self.state.value, "reason": self.reason}
        if self.warnings:
            d["warnings"] = list(self.warnings)
        return d


@dataclass(frozen=True)
class StepStats:
    """Work and health counters of a run (from the stepper's statistics).

    Attributes
    ----------
    steps, contact_solves, solver_iterations, solver_fallbacks : int
    fallback_steps : tuple of int
        Steps whose contact problem was re-solved by the reference solver.
    max_contact_residual : float
        Largest complementarity residual of any solved contact problem.
    min_gap : float or None
        Deepest gap of the master over every step (negative: penetration).
    wall_time_s, compile_time_s : float
    """

    steps: int = 0
    contact_solves: int = 0
    solver_iterations: int = 0
    solver_fallbacks: int = 0
    fallback_steps: tuple = ()
    max_contact_residual: float = 0.0
    min_gap: float | None = None
    wall_time_s: float = float("nan")
    compile_time_s: float = float("nan")

    @classmethod
    def from_metadata(cls, metadata: dict) -> "StepStats":
        """Counters read from the metadata :func:`run_metadata` builds (missing keys: defaults)."""
        fb = tuple(int(f["step"]) if isinstance(f, dict) else int(f)
                   for f in metadata.get("fallback_steps") or ())
        num = {k: metadata[k] for k in ("steps", "contact_solves", "solver_iterations",
                                         "solver_fallbacks", "max_contact_residual", "min_gap",
                                         "wall_time_s", "compile_time_s")
               if metadata.get(k) is not None}
        return cls(fallback_steps=fb, **num)


class ReadOnlyDict(dict):
    """A dict that refuses every mutation (a frozen result's metadata and observers)."""

    def _refuse(self, *args, **kwargs):
        raise TypeError("a SimulationResult is frozen: build a new one "
                        "(dataclasses.replace) instead of changing it")

    __setitem__ = __delitem__ = __ior__ = _refuse
    clear = pop = popitem = setdefault = update = _refuse

    def __reduce__(self):
        return type(self), (dict(self),)


def _read_only(a):
    """A read-only view of array ``a`` (no copy; the caller's array stays writable); None stays."""
    if a is None:
        return None
    view = np.asarray(a).view()
    view.flags.writeable = False
    return view


#: Columns of :attr:`SimulationResult.events` (one row per impact/contact event of the
#: event-driven integrator): event time, contact index, event kind (e.g. ``"impact"``,
#: ``"release"``), contact velocity before/after and the impulse.
EVENT_COLUMNS = ("time", "contact", "kind", "gamma_minus", "gamma_plus", "impulse")


def check_events(events: pd.DataFrame | None) -> pd.DataFrame | None:
    """``events`` must be None or a DataFrame with exactly :data:`EVENT_COLUMNS`."""
    if events is None:
        return None
    import pandas as pd

    if not isinstance(events, pd.DataFrame):
        raise InputError("events", f"must be a pandas DataFrame or None, got {type(events).__name__}")
    if tuple(events.columns) != EVENT_COLUMNS:
        raise InputError("events", f"columns must be {list(EVENT_COLUMNS)}, got {list(events.columns)}")
    return events


@dataclass(frozen=True)
class EventTable:
    """Events as arrays, one entry per event and contact (the columns of
    :data:`EVENT_COLUMNS`); :meth:`frame` is the DataFrame, built only when asked for."""

    time: np.ndarray
    contact: np.ndarray
    kind: np.ndarray
    gamma_minus: np.ndarray
    gamma_plus: np.ndarray
    impulse: np.ndarray

    @classmethod
    def from_rows(cls, rows: list) -> "EventTable":
        """From rows ``(time, contact, kind, γ⁻, γ⁺, impulse, ...)`` (extra columns ignored)."""
        cols = list(zip(*[r[:6] for r in rows])) if rows else [()] * 6
        return cls(np.array(cols[0], dtype=float), np.array(cols[1], dtype=np.int64),
                   np.array(cols[2], dtype=object), *(np.array(c, dtype=float) for c in cols[3:]))

    def __len__(self) -> int:
        return int(self.time.size)

    def until(self, t: float) -> "EventTable":
        """The events at times ≤ t."""
        keep = self.time <= t
        return EventTable(*(getattr(self, c)[keep] for c in EVENT_COLUMNS))

    def frame(self) -> pd.DataFrame:
        """The table as a DataFrame with :data:`EVENT_COLUMNS`."""
        import pandas as pd

        return pd.DataFrame({c: getattr(self, c) for c in EVENT_COLUMNS})


def event_table_frame(table: EventTable) -> pd.DataFrame:
    """``table.frame()`` (a module-level function: a :class:`LazyFrame` builder)."""
    return table.frame()


def records_frame(rows: list[dict]) -> pd.DataFrame:
    """A DataFrame with one row per dict of ``rows`` (``pandas.DataFrame(rows)``)."""
    import pandas as pd

    return pd.DataFrame(rows)


@dataclass(frozen=True, eq=False)
class LazyFrame:
    """A DataFrame not built yet: :meth:`frame` returns ``build(*args)`` (``of_result``:
    ``build(result, *args)``, ``result`` the :class:`SimulationResult` holding it) with
    ``attrs`` added to its ``DataFrame.attrs``.

    :class:`SimulationResult` takes one for ``summary`` or ``events`` and builds it on the
    first read of that attribute (then keeps the DataFrame), so that pandas is imported only
    by a run whose tables are read. ``of_result`` lets a table computed from the result's
    own arrays hold no second reference to them. ``build`` and ``args`` must be picklable
    for the result to be (a module-level function and plain data).
    """

    build: Callable[..., pd.DataFrame]
    args: tuple = ()
    attrs: dict = field(default_factory=dict)
    of_result: bool = False

    def frame(self, result: SimulationResult | None = None) -> pd.DataFrame:
        """The DataFrame (built anew at each call); ``result`` is passed to ``build`` first
        when ``of_result``."""
        if self.of_result:
            if result is None:
                raise InputError("result", "this table is built from a SimulationResult: pass it")
            df = self.build(result, *self.args)
        else:
            df = self.build(*self.args)
        df.attrs.update(self.attrs)
        return df


class _FrameField:
    """A DataFrame-or-None field of a frozen dataclass that also accepts a :class:`LazyFrame`:
    a value given as a DataFrame is checked at once, a lazy one is built and checked on the
    first read and then kept (the instance's ``__dict__``, as the cached properties of
    :class:`~observer.model.LinearSystem`). Reading it on the class gives the default, None."""

    def __init__(self, check: Callable | None = None):
        self.check = check

    def __set_name__(self, owner, name: str) -> None:
        self.key = f"_{name}_frame"

    def __get__(self, obj, owner=None):
        if obj is None:
            return None                                  # the dataclass default
        value = obj.__dict__[self.key]
        if isinstance(value, LazyFrame):
            value = value.frame(obj)
            if self.check is not None:
                value = self.check(value)
            obj.__dict__[self.key] = value
        return value

    def __set__(self, obj, value) -> None:
        if self.check is not None and not isinstance(value, LazyFrame):
            value = self.check(value)
        obj.__dict__[self.key] = value


@dataclass(frozen=True)
class SimulationResult:
    """A master run (and optionally observer runs) on the grid ``t``, complete and frozen.

    Built once with every field (``dataclasses.replace`` makes a changed copy); ``metadata``
    and ``slaves`` are read-only mappings and the arrays read-only views (no copies).

    Attributes
    ----------
    t : ndarray, shape (N+1,)
    q, u : ndarray, shape (N+1, n)
    P : ndarray, shape (N+1, m)
        Impulse per step (row k+1 = step k).
    active : ndarray of bool, shape (N+1, m)
        Closed set of the master in step k (row k+1).
    system : LinearSystem
    metadata : dict
        Scenario parameters, h, θ, solver, package versions, work counters.
    chi : ndarray of bool, shape (N+1, m) or None
        Switching signal fed to the observers (row k+1 = step k).
    slaves : dict[str, SlaveTrajectory]
    summary : DataFrame or None
        ``store="summary"`` runs: the kernel's per-observer metrics over every step
        (:func:`observer.engines.loop.summary_frame`). May be given as a :class:`LazyFrame`: it is
        built on first read (pandas is imported then).
    status : RunStatus
        How the run ended (ok / fallback / stopped, with the reason); by default derived
        from ``metadata`` (:meth:`RunStatus.from_metadata`).
    stats : StepStats
        Step statistics; by default read from ``metadata``.
    events : DataFrame or None
        One row per event, columns :data:`EVENT_COLUMNS` (event-driven runs: the exact
        events; time-stepped runs keeping every step: the closing and opening steps). May be
        given as a :class:`LazyFrame`: it is built (and its columns checked) on first read.
    """

    t: np.ndarray
    q: np.ndarray
    u: np.ndarray
    P: np.ndarray
    active: np.ndarray
    system: LinearSystem
    metadata: dict = field(default_factory=dict)
    chi: np.ndarray | None = None
    slaves: dict = field(default_factory=dict)
    sigma: np.ndarray | None = None
    summary: pd.DataFrame | None = _FrameField()
    status: RunStatus | None = None
    stats: StepStats | None = None
    events: pd.DataFrame | None = _FrameField(check_events)

    def __post_init__(self):
        meta = ReadOnlyDict(self.metadata)
        status = RunStatus.from_metadata(meta) if self.status is None else self.status
        if not isinstance(status, RunStatus):
            raise InputError("status", f"must be a RunStatus, got {type(status).__name__}")
        for name, value in (("metadata", meta), ("slaves", ReadOnlyDict(self.slaves)),
                            ("status", status), ("stats", self.stats or StepStats.from_metadata(meta))):
            object.__setattr__(self, name, value)
        for name in ("t", "q", "u", "P", "active", "chi", "sigma"):
            object.__setattr__(self, name, _read_only(getattr(self, name)))

    @classmethod
    def from_record(cls, record: RunRecord, system: LinearSystem) -> "SimulationResult":
        """The public result of an engine's :class:`RunRecord` (the one place it is built);
        an event table given as arrays becomes a DataFrame on first read."""
        events = record.events
        if isinstance(events, EventTable):
            events = LazyFrame(event_table_frame, (events,))
        return cls(record.t, record.q, record.u, record.P, record.active, system, record.metadata,
                   chi=record.chi, slaves=record.slaves, sigma=record.sigma, summary=record.summary,
                   status=record.status, stats=record.stats, events=events)

    @property
    def g(self) -> np.ndarray:
        """Gaps g = Wᵀq + ν(t), shape (N+1, m)."""
        return self.system.gaps(self.q, self.t)

    @property
    def gamma(self) -> np.ndarray:
        """Contact velocities γ = Wᵀu + ν̇(t), shape (N+1, m)."""
        return self.system.contact_velocities(self.u, self.t)

    def to_frame(self) -> pd.DataFrame:
        """Tidy DataFrame: ``t, q0.., u0.., g0.., P0.., active0..`` plus, with observers,
        ``chi0..`` and per observer NAME ``NAME_q0.., NAME_u0.., V_NAME``. The metadata is in
        ``DataFrame.attrs``."""
        import pandas as pd

        n, m = self.system.n, self.system.m
        cols: dict[str, np.ndarray] = {"t": self.t}
        for name, arr, width in (("q", self.q, n), ("u", self.u, n), ("g", self.g, m), ("P", self.P, m)):
            for j in range(width):
                cols[f"{name}{j}"] = arr[:, j]
        for j in range(m):
            cols[f"active{j}"] = self.active[:, j].astype(np.int8)
        if self.chi is not None:
            for j in range(m):
                cols[f"chi{j}"] = self.chi[:, j].astype(np.int8)
        for name, s in self.slaves.items():
            for j in range(n):
                cols[f"{name}_q{j}"] = s.q[:, j]
            for j in range(n):
                cols[f"{name}_u{j}"] = s.u[:, j]
            cols[f"V_{name}"] = s.V
        df = pd.DataFrame(cols)
        df.attrs.update(json.loads(json.dumps(self.metadata, default=jsonable)))
        df.attrs["status"] = self.status.to_dict()
        return df

    def synchronization(self, rhos: tuple[float, ...] = RHOS) -> pd.DataFrame:
        """One row per observer: first-passage times ``t_sync_ρ`` (from t_on, to V ≤ ρ·V(t_on))
        and settling times ``t_settle_ρ`` (after which V stays below ρ·V(t_on) for the rest of
        the window, :func:`observer.metrics.settling_time`), the fitted exponential rate of V
        over the coupling window, V(t_on), the final V and the floor (median of V over the
        last 10 % of the window). ``inf`` marks a threshold never reached; NaN every metric of
        a coupling window that starts after the run ends (nothing to measure)."""
        import pandas as pd

        from observer.metrics import switchings

        coupling = self.metadata.get("coupling") or [float(self.t[0]), float(self.t[-1])]
        t_on, t_off = float(coupling[0]), min(float(coupling[1]), float(self.t[-1]))
        rows = []
        for name, s in self.slaves.items():
            row = {"observer": name, "t_on": t_on, "t_off": t_off,
                   **self._window_metrics(s.V, t_on, t_off, rhos),
                   "V_end": float(s.V[-1]), "master_closings": switchings(self.active)}
            rows.append(row)
        return pd.DataFrame(rows)

    def _window_metrics(self, V: np.ndarray, t_on: float, t_off: float,
                        rhos: tuple[float, ...]) -> dict:
        """V(t_on), first-passage and settling times, rate and floor of V over [t_on, t_off]."""
        from observer.metrics import (decay_rate, floor, settle_column, settling_time,
                                      sync_column, sync_time)

        names = ["V_on", *(c(rho) for rho in rhos for c in (sync_column, settle_column)),
                 "rate", "floor"]
        if t_on > self.t[-1]:                        # the window starts after the run
            return dict.fromkeys(names, float("nan"))
        out = {"V_on": float(V[int(np.searchsorted(self.t, t_on))])}
        for rho in rhos:
            out[sync_column(rho)] = sync_time(self.t, V, rho, t_on, t_off)
            out[settle_column(rho)] = settling_time(self.t, V, rho, t_on, t_off)
        out["rate"] = decay_rate(self.t, V, t_on, t_off)
        out["floor"] = floor(self.t, V, t_off - 0.1 * (t_off - t_on), t_off)
        return {k: out[k] for k in names}

    def write(self, path: str | Path) -> Path:
        """Write :meth:`to_frame` as ``.csv`` (plain header, metadata in the ``NAME.json``
        sidecar) or ``.parquet`` (metadata in the schema metadata), see :mod:`observer.io`.
        With :attr:`events`, they go to :func:`observer.io.events_path` beside it
        (``NAME.events.csv``/``.parquet``; :func:`observer.io.read_events` reads them)."""
        path = Path(path)
        df = self.to_frame()
        if self.events is not None:
            write_frame(self.events, events_path(path))
            df.attrs["events_file"] = events_path(path).name
        else:
            remove_events(path)                      # an earlier run's events are not this one's
        return write_frame(df, path)


@dataclass(frozen=True)
class RecordArray:
    """One record array of a run, declared once in :data:`RECORD_ARRAYS`.

    Attributes
    ----------
    name : str
        The attribute name, the same in the loops' records (:func:`observer.engines.loop.allocate_records`,
        :class:`~observer.engines.loop.LoopOutput`, :class:`~observer.engines.loop.Chunk`, the
        compiled kernel's ``StorageBundle``) and in :class:`RunRecord` / :class:`SimulationResult`.
    dtype : type
    width : {"n", "m"}
        Per row: one value per degree of freedom or per contact.
    per_system : bool
        Each system (master first, then the observers) has its own: the loops' array is
        ``(S, rows, width)``; else one ``(rows, width)`` array for the run (the master's closed
        set, the observers' χ).
    zero_filled : bool
        Allocated as zeros (the loops write only the closed contacts' entries); else every
        row is written before it is read.
    optional : bool
        Kept only when asked for (``record_pre``): absent from the streamed chunks and None in
        a record without it.
    """

    name: str
    dtype: type
    width: str
    per_system: bool
    zero_filled: bool
    optional: bool = False

    def allocate(self, S: int, rows: int, n: int, m: int) -> np.ndarray:
        """The loops' array of this record: ``(S, rows, width)`` or ``(rows, width)``."""
        shape = ((S,) if self.per_system else ()) + (rows, n if self.width == "n" else m)
        return (np.zeros if self.zero_filled else np.empty)(shape, dtype=self.dtype)

    def rows(self, x: np.ndarray, sl: slice) -> np.ndarray:
        """Rows ``sl`` of the loops' array ``x`` (a view)."""
        return x[:, sl] if self.per_system else x[sl]


RECORD_ARRAYS = (
    RecordArray("q", np.float64, "n", True, False),
    RecordArray("u", np.float64, "n", True, False),
    RecordArray("P", np.float64, "m", True, True),
    RecordArray("sigma", np.float64, "m", True, True),
    RecordArray("active", np.bool_, "m", False, True),
    RecordArray("chi", np.bool_, "m", False, True),
    RecordArray("q_pre", np.float64, "n", True, False, optional=True),
)
"""The record arrays of a run, in order: positions, velocities, the impulse and the projection
multiplier of the step ending at the row, the master's closed set, the observers' signal χ,
the positions before the projection (row k+1 = step k; row 0 the initial state). The loops
allocate, truncate and stream them from this declaration; the classes that carry them list
them in this order (``tests/observer/test_records.py``)."""


@dataclass(frozen=True)
class RunRecord:
    """What every engine returns (:mod:`observer.engines`): the master's arrays on the
    output grid, the observers' trajectories, the events, how the run ended and its
    counters. :meth:`SimulationResult.from_record` turns it into the public result.

    Attributes
    ----------
    engine : str
        The engine's registry name.
    t, q, u, P, sigma, active, chi
        As :class:`SimulationResult` (``chi`` None without observers).
    slaves : dict[str, SlaveTrajectory]
    status : RunStatus
        :class:`RunState` (ok / fallback / stopped) and the reason.
    stats : StepStats
    metadata : dict
    events : EventTable, LazyFrame or None
        The event table as arrays, or a table derived on first read (time-stepping), or None.
    summary : LazyFrame or None
    q_pre : ndarray, shape (1 + len(slaves), rows, n), or None
        The positions before each step's projection (row k+1 = step k; equal to ``q`` where
        nothing was projected): the master first, then the observers in the order of
        ``slaves``. Kept when the run description asks for it (``record_pre``, the proof
        checks' replays) or when an observer projects in another metric; None otherwise.
    """

    engine: str
    t: np.ndarray
    q: np.ndarray
    u: np.ndarray
    P: np.ndarray
    sigma: np.ndarray
    active: np.ndarray
    chi: np.ndarray | None
    slaves: dict
    status: RunStatus
    stats: StepStats
    metadata: dict
    events: EventTable | LazyFrame | None = None
    summary: LazyFrame | None = None
    q_pre: np.ndarray | None = None


def run_metadata(scenario, stepper, out) -> dict:
    """Metadata of a run: scenario parameters, scheme, engine, solver work (with every
    fallback to the reference solver), versions, timing (compile time apart)."""
    meta = dict(scenario.parameters())
    st = out.stats
    done = stepper.steps if out.stopped_at is None else int(out.stopped_at)   # steps actually taken
    meta.update(h=stepper.h, theta=stepper.theta, steps=done, planned_steps=stepper.steps,
                engine=out.engine, structure="dense" if stepper.S.band is None else "banded",
                record_every=int(out.record_every),
                solver=stepper.solver.name, contact_solves=st["contact_solves"],
                solver_iterations=st["iterations"], solver_fallbacks=st["fallbacks"],
                fallback_steps=list(out.fallbacks),
                max_contact_residual=st["max_residual"], wall_time_s=out.run_time_s,
                min_gap=st.get("min_gap"), min_gap_t=(float(stepper.time(st["min_gap_step"]))
                                                      if st.get("min_gap_step", -1) >= 0 else None),
                compile_time_s=out.compile_time_s,
                health=out.health.to_dict() if out.health is not None else None,
                stopped=out.stop_info(stepper),
                steps_per_second=done / out.run_time_s if out.run_time_s > 0 else float("nan"),
                versions=package_versions(), platform=platform.platform(),
                argv=typed_command())
    return meta
