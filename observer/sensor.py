"""χ from a sensor: the switching signal the observers see, derived from the plant's gaps.

The paper's observers are switched by χ(t) *generated* by the master's gaps (Definition 2:
χ_i = 1 where g_i = 0, 0 where g_i > 0; eqs. (8)–(11) switch the constraints by it). A real
contact sensor gives something else. A :class:`Sensor` (the ``[observer.sensor]`` table, or
the ``sensor=`` keyword of :func:`observer.simulate`, :func:`observer.ensemble` and
:func:`observer.compare`) turns the plant's run into a closing log (the log of
:mod:`observer.switching`, ``contact, t_close, t_open``) in this order:

1. **threshold** δ ≥ 0 (m): contact i is *seen closed* at step k when the master's predicted
   mid-step gap ĝ_k = w_iᵀ(q_k + h/2·u_k) + ν_i(t_k) + h/2·ν̇_i(t_k) is at most δ, or when the
   master closed it at that step (:func:`seen_closed`). ĝ_k ≤ 0 is the master's own rule
   (:meth:`observer.stepping.MoreauJean.predicted_active`), so δ = 0 gives the master's closed
   set exactly; each maximal run of seen-closed steps becomes one interval at the step
   midpoints (:func:`observer.switching.log_from_active`).
2. **missed** p ∈ [0, 1]: every interval (a closing or an impact) is dropped with probability p,
   independently.
3. **false_rate** λ ≥ 0 (1/s): spurious impacts (zero-length intervals) at the times of a
   Poisson process of rate λ on [0, t_end], each on a uniformly drawn contact, kept only where
   that contact is seen open.
4. **sampling_period** T > 0 (s): χ is read at the sample instants j·T and held in between;
   each endpoint moves to the first sample instant at or after it (an interval shorter than
   a period is latched and reported at the next sample as an impact).
5. **jitter** σ ≥ 0 (s): every endpoint moves by an independent N(0, σ²) time error (an
   impact is moved as a whole; an opening never precedes its closing).
6. **latency** d ≥ 0 (s): every interval is reported d later. On the grid χ moves by d/h
   steps rounded to the nearest whole step (half a step rounds up): the log's interval
   endpoints sit at step midpoints and a step is closed when an interval meets it.

The result is clipped to [0, t_end], sorted and merged per contact. All randomness (2, 3, 5,
drawn in that order, a part at 0 drawing nothing) comes from ``numpy.random.default_rng(seed)``.
A measured log (``source = "log"``) passes through parts 2–6 only: no gap is known, so
δ > 0 is refused there. The ideal sensor (every part at its default) is no sensor at all:
the run is today's, bitwise.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from observer.errors import InputError
from observer.switching import LOG_COLUMNS, log_from_active, validate_log
from observer.validation import as_scalar

if TYPE_CHECKING:
    import pandas as pd

FIELD = "observer.sensor"
"""The scenario table (and the prefix of every error about it)."""


@dataclass(frozen=True)
class Sensor:
    """The settings of a contact sensor (module docstring: what each part does, in order).

    Attributes
    ----------
    threshold : float
        δ ≥ 0 (m): a gap at most δ is seen closed (0: the master's closed set).
    latency : float
        d ≥ 0 (s): every interval reported d later.
    sampling_period : float or None
        T > 0 (s): χ read at t = j·T and held; None: read at every step.
    jitter : float
        σ ≥ 0 (s): standard deviation of each endpoint's time error.
    missed : float
        p ∈ [0, 1]: probability that a closing or impact is not seen.
    false_rate : float
        λ ≥ 0 (1/s): rate of false impacts.
    seed : int
        Seed of the sensor's random generator (missed, false, jitter).
    """

    threshold: float = 0.0
    latency: float = 0.0
    sampling_period: float | None = None
    jitter: float = 0.0
    missed: float = 0.0
    false_rate: float = 0.0
    seed: int = 0

    @staticmethod
    def from_table(table: Any) -> "Sensor":
        """The sensor of an ``[observer.sensor]`` table (a dict; None or ``{}``: the ideal one).

        Raises
        ------
        InputError
            Naming ``observer.sensor.FIELD``: an unknown key, a value that is not a finite
            number, a negative threshold, latency, jitter or rate, a sampling period that is
            not a positive number, a probability outside [0, 1], a seed that is not an integer ≥ 0.
        """
        if table is None:
            return Sensor()
        if not isinstance(table, dict):
            raise InputError(FIELD, f"must be a table (a dict) of sensor settings, got {type(table).__name__}")
        known = Sensor.__dataclass_fields__
        for key in table:
            if key not in known:
                raise InputError(f"{FIELD}.{key}", f"unknown key (known keys here: {', '.join(sorted(known))})")
        kw: dict[str, Any] = {}
        for key in ("threshold", "latency", "jitter", "false_rate"):
            if key in table:
                kw[key] = as_scalar(f"{FIELD}.{key}", table[key], low=0.0)
        if "missed" in table:
            kw["missed"] = as_scalar(f"{FIELD}.missed", table["missed"], low=0.0, high=1.0)
        if table.get("sampling_period") is not None:
            kw["sampling_period"] = as_scalar(f"{FIELD}.sampling_period", table["sampling_period"],
                                              positive=True)
        if "seed" in table:
            seed = table["seed"]
            if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
                raise InputError(f"{FIELD}.seed", f"must be an integer ≥ 0, got {seed!r}")
            kw["seed"] = int(seed)
        return Sensor(**kw)

    @property
    def ideal(self) -> bool:
        """True when every part is at its default: χ is the master's own (no sensor)."""
        return self == Sensor(seed=self.seed)

    def to_dict(self) -> dict:
        """The settings, JSON-ready (the result metadata's ``sensor``)."""
        return asdict(self)


def seen_closed(t: np.ndarray, q: np.ndarray, u: np.ndarray, active: np.ndarray, system, h: float,
                threshold: float) -> np.ndarray:
    """Part 1: the steps at which each contact is seen closed, bool (N+1, m) shaped as
    ``active`` (row k+1 for step k, row 0 False).

    Parameters
    ----------
    t : ndarray (N+1,)
        The grid.
    q, u : ndarray (N+1, n)
        The master's state at every grid point.
    active : ndarray of bool (N+1, m)
        The master's closed set (row k+1: step k).
    system : LinearSystem
    h : float
        The step.
    threshold : float
        δ ≥ 0: seen closed where ĝ_k ≤ δ (or where the master closed the contact).
    """
    out = np.asarray(active, dtype=bool).copy()
    if threshold > 0.0:
        tk = t[:-1]
        # the Siconos predictor of MoreauJean.predicted_active, on the whole recorded run
        g_pred = system.gaps(q[:-1] + (h / 2) * u[:-1], tk) + (h / 2) * system.nu_dot(tk)
        out[1:] |= g_pred <= threshold
    return out


def sensed_master_log(t: np.ndarray, q: np.ndarray, u: np.ndarray, active: np.ndarray, system,
                      h: float, sensor: Sensor) -> pd.DataFrame:
    """Parts 1–6 on a master's run (every grid point recorded): the log the observers see."""
    seen = seen_closed(t, q, u, active, system, h, sensor.threshold)
    return sense_log(log_from_active(t, seen), sensor, m=system.m, t_end=float(t[-1]), h=h)


def sense_log(log: pd.DataFrame, sensor: Sensor, *, m: int, t_end: float, h: float) -> pd.DataFrame:
    """Parts 2–6 on a closing log: missed, false, sampled, jittered and delayed detections.

    Parameters
    ----------
    log : DataFrame
        Closing log (``contact, t_close, t_open``): the seen-closed intervals of part 1, or a
        measured log.
    sensor : Sensor
    m : int
        Number of contacts.
    t_end : float
        End of the run: intervals are clipped to [0, t_end]; false impacts fall in it.
    h : float
        Step of the run: an interval no longer than h is an impact (jittered as a whole).

    Returns
    -------
    DataFrame
        A valid closing log (sorted per contact, no overlaps, inside [0, t_end]).
    """
    rng = np.random.default_rng(sensor.seed)
    log = log[list(LOG_COLUMNS)].reset_index(drop=True)
    tc, to = log["t_close"].to_numpy(float), log["t_open"].to_numpy(float)
    if sensor.missed > 0.0:
        keep = ~(rng.random(tc.size) < sensor.missed)
        log, tc, to = log.iloc[np.flatnonzero(keep)].reset_index(drop=True), tc[keep], to[keep]
    if sensor.false_rate > 0.0:
        log = _with_false_impacts(log.assign(t_close=tc, t_open=to), sensor.false_rate, rng, m, t_end)
        tc, to = log["t_close"].to_numpy(float), log["t_open"].to_numpy(float)
    if sensor.sampling_period is not None:
        tc, to = next_sample(tc, sensor.sampling_period), next_sample(to, sensor.sampling_period)
    if sensor.jitter > 0.0:
        impact = (to - tc) <= h
        d_close = rng.normal(0.0, sensor.jitter, tc.shape)
        d_open = np.where(impact, d_close, rng.normal(0.0, sensor.jitter, to.shape))
        tc, to = tc + d_close, to + d_open
        to = np.maximum(to, tc)
    if sensor.latency > 0.0:
        tc, to = tc + sensor.latency, to + sensor.latency
    return normalise(log.assign(t_close=tc, t_open=to), m, 0.0, t_end)


def next_sample(t: np.ndarray, period: float) -> np.ndarray:
    """Part 4: the first sample instant j·T at or after each time of ``t``."""
    t = np.asarray(t, dtype=float)
    j = np.ceil(t / period)
    j = np.where(j * period < t, j + 1.0, j)                   # t/T rounded below a multiple
    j = np.where((j - 1.0) * period >= t, j - 1.0, j)          # t/T rounded above one
    return j * period


def _with_false_impacts(log: pd.DataFrame, rate: float, rng: np.random.Generator, m: int,
                        t_end: float) -> pd.DataFrame:
    """Part 3: ``log`` with zero-length impacts at Poisson(rate) times on [0, t_end], each on a
    uniformly drawn contact, kept where that contact's intervals do not cover the time."""
    import pandas as pd

    count = rng.poisson(rate * t_end)
    times = np.sort(rng.uniform(0.0, t_end, count))
    contacts = rng.integers(0, m, count)
    c = log["contact"].to_numpy()
    tc, to = log["t_close"].to_numpy(float), log["t_open"].to_numpy(float)
    extra = [(int(j), s, s) for s, j in zip(times, contacts)
             if not np.any((c == j) & (tc <= s) & (s <= to))]
    if not extra:
        return log
    return pd.concat([log, pd.DataFrame(extra, columns=list(LOG_COLUMNS))], ignore_index=True)


def normalise(log: pd.DataFrame, m: int, t_min: float, t_max: float) -> pd.DataFrame:
    """``log`` clipped to [t_min, t_max], sorted per contact and with overlapping intervals merged
    (a valid closing log, :func:`observer.switching.validate_log`)."""
    import pandas as pd

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
    return validate_log(out, m, "sensed log") if len(out) else out

