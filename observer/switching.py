"""Switching signals χ for the observers: from the master, from the observer itself, or from a log.

χ_i = 1 means "contact i of the observed system is closed". On the grid, χ^k belongs to
the step t_k → t_{k+1}.

* ``master``: χ^k is the master's own closed set at the same step on the same grid (no
  tolerance: the slave copies exactly what the master used).
* ``self``: every observer uses its own predicted closed set (uncoupled).
* ``log``: a measured record of closings, a CSV with columns ``contact, t_close, t_open``
  (an impact is an interval of zero length), sampled onto the grid: χ^k_i = 1 when an
  interval of contact i meets the step [t_k, t_{k+1}).

A coupling window [t_on, t_off] uses the source for t_on ≤ t_k ≤ t_off and ``self``
outside it.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from observer.errors import InputError

if TYPE_CHECKING:
    import pandas as pd

SOURCES = ("master", "log", "self")
LOG_COLUMNS = ("contact", "t_close", "t_open")


def read_log(path: str | Path, m: int) -> pd.DataFrame:
    """Read and validate a closing log (CSV with columns contact, t_close, t_open), or validate
    one given as a :class:`pandas.DataFrame` with those columns.

    Errors name the file, the row and the problem: unknown contact index, NaN,
    ``t_open < t_close``, intervals of one contact not sorted or overlapping.
    """
    import pandas as pd

    if isinstance(path, pd.DataFrame):           # the log itself, with the log's columns
        return validate_log(path, m, f"the DataFrame given as the log ({len(path)} rows)")
    if not isinstance(path, (str, Path)) or not str(path).strip():
        raise InputError("observer.log", f"must be a file path, got {path!r}")
    path = Path(path)
    if not path.is_file():
        raise InputError("observer.log", f"file not found: {path}" if not path.exists()
                         else f"{path} is not a file")
    try:
        df = pd.read_csv(path, comment="#")
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise InputError("observer.log", f"{path}: not a readable CSV ({exc})") from None
    return validate_log(df, m, str(path))


def validate_log(df: pd.DataFrame, m: int, where: str = "log") -> pd.DataFrame:
    """Check a closing log DataFrame; return it with columns (contact:int, t_close, t_open)."""
    import pandas as pd

    missing = [c for c in LOG_COLUMNS if c not in df.columns]
    if missing:
        raise InputError("observer.log", f"{where}: missing column(s) {missing}; expected {list(LOG_COLUMNS)}")
    df = df[list(LOG_COLUMNS)].copy()
    for col in LOG_COLUMNS:
        vals = pd.to_numeric(df[col], errors="coerce")
        bad = np.flatnonzero(~np.isfinite(vals.to_numpy(dtype=float)))
        if bad.size:
            raise InputError("observer.log", f"{where}: row {bad[0] + 1}: {col} is NaN or not a number")
        df[col] = vals
    c = df["contact"].to_numpy()
    bad = np.flatnonzero((c != np.round(c)) | (c < 0) | (c >= m))
    if bad.size:
        raise InputError("observer.log", f"{where}: row {bad[0] + 1}: unknown contact index "
                         f"{_number(df['contact'].iloc[bad[0]])} (the system has contacts 0..{m - 1})")
    df["contact"] = df["contact"].astype(int)
    bad = np.flatnonzero(df["t_close"].to_numpy() < 0.0)
    if bad.size:
        raise InputError("observer.log", f"{where}: row {bad[0] + 1}: t_close = "
                         f"{_number(df['t_close'].iloc[bad[0]])} < 0 (runs start at t = 0)")
    bad = np.flatnonzero(df["t_open"].to_numpy() < df["t_close"].to_numpy())
    if bad.size:
        raise InputError("observer.log", f"{where}: row {bad[0] + 1}: t_open < t_close")
    for j, grp in df.groupby("contact", sort=False):
        tc, to = grp["t_close"].to_numpy(), grp["t_open"].to_numpy()
        rows = grp.index.to_numpy()
        order = np.flatnonzero(np.diff(tc) < 0)
        if order.size:
            raise InputError("observer.log", f"{where}: row {rows[order[0] + 1] + 1}: intervals of "
                             f"contact {j} are not sorted by t_close")
        overlap = np.flatnonzero(tc[1:] < to[:-1])
        if overlap.size:
            raise InputError("observer.log", f"{where}: row {rows[overlap[0] + 1] + 1}: interval of "
                             f"contact {j} overlaps the previous one")
    return df.reset_index(drop=True)


def _number(x) -> str:
    """A log entry as the file has it (``2``, ``0.5``), never NumPy's ``np.int64(2)``."""
    x = x.item() if isinstance(x, np.generic) else x
    return str(int(x)) if isinstance(x, float) and x.is_integer() else repr(x)


def sample_log(log: pd.DataFrame, t: np.ndarray, m: int) -> np.ndarray:
    """χ on the grid: bool array (N, m), χ[k, i] = 1 if an interval of i meets [t_k, t_{k+1})."""
    steps = t.shape[0] - 1
    chi = np.zeros((steps, m), dtype=bool)
    for j, tc, to in log[list(LOG_COLUMNS)].itertuples(index=False):
        # steps k with t_k <= t_open and t_{k+1} > t_close
        k_hi = np.searchsorted(t[:-1], to, side="right")
        k_lo = np.searchsorted(t[1:], tc, side="right")
        chi[k_lo:k_hi, int(j)] = True
    return chi


def log_from_active(t: np.ndarray, active: np.ndarray) -> pd.DataFrame:
    """Closing log of a run: each maximal run of closed steps k1..k2 of contact i becomes the
    interval [t_{k1} + h/2, t_{k2} + h/2] (the step midpoints, where the closed set is
    decided); a single closed step gives a zero-length interval (an impact).

    ``active`` has shape (N+1, m) with row k+1 for step k (as in :class:`SimulationResult`).
    Sampling the log back onto the same grid returns ``active`` exactly.
    """
    import pandas as pd

    steps_active = active[1:]
    mid = 0.5 * (t[:-1] + t[1:])
    rows = []
    for i in range(active.shape[1]):
        a = steps_active[:, i].astype(np.int8)
        d = np.diff(np.concatenate([[0], a, [0]]))
        starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1
        rows += [(i, mid[s], mid[e]) for s, e in zip(starts, ends)]
    df = pd.DataFrame(rows, columns=list(LOG_COLUMNS))
    return df.sort_values(["contact", "t_close"], kind="stable").reset_index(drop=True)


def coupling_mask(t: np.ndarray, coupling: tuple[float, float] | None) -> np.ndarray:
    """Bool (N,): step k is coupled when t_on ≤ t_k ≤ t_off (always, when ``coupling`` is None)."""
    tk = t[:-1]
    if coupling is None:
        return np.ones(tk.shape, dtype=bool)
    t_on, t_off = coupling
    return (tk >= t_on) & (tk <= t_off)
