"""Imperfect switching signals: perturbations of a closing log (robustness suite).

A closing log is the DataFrame of :mod:`observer.switching` (columns ``contact, t_close,
t_open``; an impact is a zero-length interval). Each perturbation models a defect of a real
contact sensor and returns a *valid* log (sorted per contact, no overlaps, inside
[t_min, t_max]), ready for ``observer.simulate(..., source="log", log=path)``:

* ``delay``  — every interval shifted later by d seconds (sensor latency);
* ``jitter`` — every endpoint moved by an independent N(0, σ²) time error (a zero-length
  impact is moved as a whole);
* ``missed`` — a fraction p of the *impacts* (intervals no longer than one step h) deleted;
* ``false``  — spurious impacts (zero-length closings) added at the times of a Poisson
  process of rate λ (1/s), kept only where the true log says "open".

All randomness comes from the ``rng`` argument (``numpy.random.Generator``).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from observer.switching import LOG_COLUMNS, validate_log

KINDS = ("none", "delay", "jitter", "missed", "false")
"""Perturbation kinds, in the order the report shows them."""

UNITS = {"none": "", "delay": "s", "jitter": "s", "missed": "fraction", "false": "1/s"}
LABELS = {"none": "exact χ (the master's closed set)", "delay": "delay d of every interval",
          "jitter": "jitter σ of every endpoint", "missed": "fraction p of impacts missed",
          "false": "false closings per second λ"}


def _normalise(log: pd.DataFrame, m: int, t_min: float, t_max: float) -> pd.DataFrame:
    """Clip to [t_min, t_max], sort per contact and merge overlapping intervals."""
    rows = []
    for j, grp in log.groupby("contact", sort=True):
        iv = np.column_stack([grp["t_close"].to_numpy(float), grp["t_open"].to_numpy(float)])
        iv = np.clip(iv, t_min, t_max)
        iv = iv[np.argsort(iv[:, 0], kind="stable")]
        merged: list[list[float]] = []
        for a, b in iv:
            if merged and a <= merged[-1][1]:
                merged[-1][1] = max(merged[-1][1], b)
            else:
                merged.append([a, b])
        rows += [(int(j), a, b) for a, b in merged]
    out = pd.DataFrame(rows, columns=list(LOG_COLUMNS))
    return validate_log(out, m, "perturbed log") if len(out) else out


def perturb_log(log: pd.DataFrame, kind: str, size: float, *, rng: np.random.Generator, m: int,
                t_min: float, t_max: float, h: float) -> pd.DataFrame:
    """A perturbed copy of ``log``.

    Parameters
    ----------
    log : DataFrame
        Closing log (``contact, t_close, t_open``).
    kind : {"none", "delay", "jitter", "missed", "false"}
    size : float
        d (s), σ (s), p (fraction in [0, 1]) or λ (1/s), by ``kind``.
    rng : numpy.random.Generator
    m : int
        Number of contacts.
    t_min, t_max : float
        Time span of the run (intervals are clipped to it).
    h : float
        Step of the run: intervals of length ≤ h count as impacts.

    Returns
    -------
    DataFrame
        A valid closing log.
    """
    log = log[list(LOG_COLUMNS)].copy().reset_index(drop=True)
    tc = log["t_close"].to_numpy(float)
    to = log["t_open"].to_numpy(float)
    if kind == "none" or size == 0:
        pass
    elif kind == "delay":
        tc, to = tc + size, to + size
    elif kind == "jitter":
        impact = (to - tc) <= h
        d_close = rng.normal(0.0, size, tc.shape)
        d_open = np.where(impact, d_close, rng.normal(0.0, size, to.shape))
        tc, to = tc + d_close, to + d_open
        to = np.maximum(to, tc)
    elif kind == "missed":
        if not 0.0 <= size <= 1.0:
            raise ValueError(f"missed fraction must lie in [0, 1], got {size}")
        impacts = np.flatnonzero((to - tc) <= h)
        drop = rng.choice(impacts, size=int(round(size * impacts.size)), replace=False)
        keep = np.setdiff1d(np.arange(tc.size), drop)
        log, tc, to = log.iloc[keep].reset_index(drop=True), tc[keep], to[keep]
    elif kind == "false":
        count = rng.poisson(size * (t_max - t_min))
        times = np.sort(rng.uniform(t_min, t_max, count))
        contacts = rng.integers(0, m, count)
        extra = []
        for t, j in zip(times, contacts):
            mine = log["contact"].to_numpy() == j
            inside = np.any((tc[mine] <= t) & (t <= to[mine]))
            if not inside:
                extra.append((int(j), t, t))
        if extra:
            add = pd.DataFrame(extra, columns=list(LOG_COLUMNS))
            log = pd.concat([log.assign(t_close=tc, t_open=to), add], ignore_index=True)
            tc, to = log["t_close"].to_numpy(float), log["t_open"].to_numpy(float)
    else:
        raise ValueError(f"unknown perturbation {kind!r}; choose from {KINDS}")
    log = log.assign(t_close=tc, t_open=to)
    return _normalise(log, m, t_min, t_max)
