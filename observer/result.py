"""Simulation results: time-major arrays, a tidy DataFrame view, CSV/Parquet output.

Array layout (everywhere in the toolkit): time-major, ``shape (N+1, n)`` for N steps.
Row 0 is the initial state; row k+1 of ``P`` and ``active`` belongs to the step
t_k → t_{k+1} (the impulse of that step and the closed set it used).
"""

from __future__ import annotations

import functools
import json
import platform
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from observer.errors import InputError
from observer.model import LinearSystem


@functools.lru_cache(maxsize=None)
def _versions() -> tuple:
    from importlib import metadata

    import observer

    out = {"python": platform.python_version(), "observer": observer.__version__}
    for pkg in ("numpy", "scipy", "pandas", "cvxpy", "osqp", "matplotlib", "numba"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return tuple(out.items())


def package_versions() -> dict[str, str]:
    """Versions of Python, the toolkit and its numerical stack, for result metadata (read once)."""
    return dict(_versions())


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


@dataclass
class SimulationResult:
    """A master run (and optionally observer runs) on the grid ``t``.

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
        (:func:`observer.loop.summary_frame`).
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
    summary: pd.DataFrame | None = None

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
        df.attrs.update(json.loads(json.dumps(self.metadata, default=_jsonable)))
        return df

    def synchronization(self, rhos: tuple[float, ...] = (1e-3, 1e-6, 1e-9)) -> pd.DataFrame:
        """One row per observer: first-passage times ``t_sync_ρ`` (from t_on, to V ≤ ρ·V(t_on))
        and settling times ``t_settle_ρ`` (after which V stays below ρ·V(t_on) for the rest of
        the window, :func:`observer.metrics.settling_time`), the fitted exponential rate of V
        over the coupling window, V(t_on), the final V and the floor (median of V over the
        last 10 % of the window). ``inf`` marks a threshold never reached."""
        from observer.metrics import decay_rate, floor, settling_time, switchings, sync_time

        coupling = self.metadata.get("coupling") or [float(self.t[0]), float(self.t[-1])]
        t_on, t_off = float(coupling[0]), min(float(coupling[1]), float(self.t[-1]))
        rows = []
        for name, s in self.slaves.items():
            k_on = int(np.searchsorted(self.t, t_on))
            row = {"observer": name, "t_on": t_on, "t_off": t_off, "V_on": float(s.V[k_on])}
            for rho in rhos:
                row[f"t_sync_{rho:g}"] = sync_time(self.t, s.V, rho, t_on, t_off)
                row[f"t_settle_{rho:g}"] = settling_time(self.t, s.V, rho, t_on, t_off)
            row["rate"] = decay_rate(self.t, s.V, t_on, t_off)
            row["V_end"] = float(s.V[-1])
            row["floor"] = floor(self.t, s.V, t_off - 0.1 * (t_off - t_on), t_off)
            row["master_closings"] = switchings(self.active)
            rows.append(row)
        return pd.DataFrame(rows)

    def write(self, path: str | Path) -> Path:
        """Write :meth:`to_frame` as CSV (metadata in a leading ``# metadata:`` line) or Parquet."""
        return write_frame(self.to_frame(), path)


def _jsonable(x):
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    return str(x)


def write_frame(df: pd.DataFrame, path: str | Path) -> Path:
    """Write a DataFrame by extension: ``.csv`` (metadata as a JSON comment line) or ``.parquet``."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".parquet"):
        raise InputError("--out", f"unsupported extension {path.suffix!r}; use .csv or .parquet")
    path.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".csv":
        with path.open("w", newline="") as fh:
            fh.write("# metadata: " + json.dumps(df.attrs, default=_jsonable) + "\n")
            df.to_csv(fh, index=False, float_format="%.17g")
    else:
        df.to_parquet(path, index=False)
    return path


def read_frame(path: str | Path) -> pd.DataFrame:
    """Read a result written by :func:`write_frame`, restoring ``attrs`` (the metadata)."""
    path = Path(path)
    if not path.exists():
        raise InputError(str(path), "file not found")
    try:
        if path.suffix.lower() == ".parquet":
            return pd.read_parquet(path)
        with path.open() as fh:
            first = fh.readline()
        has_meta = first.startswith("# metadata:")
        df = pd.read_csv(path, skiprows=1 if has_meta else 0)
        if has_meta:
            df.attrs.update(json.loads(first[len("# metadata:"):]))
    except (UnicodeDecodeError, ValueError, OSError) as exc:
        raise InputError(str(path), f"not a result file written by this toolkit ({exc})") from None
    if "t" not in df.columns:
        raise InputError(str(path), "not a result file (no column 't')")
    flags = [c for c in df.columns if c.startswith(("active", "chi"))]
    return df.astype({c: float for c in df.columns if c not in flags})


def run_metadata(scenario, stepper, out) -> dict:
    """Metadata of a run: scenario parameters, scheme, engine, solver work (with every
    fallback to the reference solver), versions, timing (compile time apart)."""
    meta = dict(scenario.parameters())
    st = out.stats
    meta.update(h=stepper.h, theta=stepper.theta, steps=stepper.steps,
                engine=out.engine, structure="dense" if stepper.S.band is None else "banded",
                record_every=int(out.rows[1] - out.rows[0]) if out.rows.size > 1 else 1,
                solver=stepper.solver.name, contact_solves=st["contact_solves"],
                solver_iterations=st["iterations"], solver_fallbacks=st["fallbacks"],
                fallback_steps=list(out.fallbacks),
                max_contact_residual=st["max_residual"], wall_time_s=out.run_time_s,
                min_gap=st.get("min_gap"), min_gap_t=(float(stepper.time(st["min_gap_step"]))
                                                      if st.get("min_gap_step", -1) >= 0 else None),
                compile_time_s=out.compile_time_s,
                steps_per_second=stepper.steps / out.run_time_s if out.run_time_s > 0 else float("nan"),
                versions=package_versions(), platform=platform.platform(),
                argv=" ".join(sys.argv))
    return meta
