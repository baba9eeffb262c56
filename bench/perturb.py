"""Imperfect switching signals for the robustness suite: one sensor setting per perturbation.

A perturbation of the robustness suite is one part of a contact sensor
(:mod:`observer.sensor`, the ``[observer.sensor]`` table): there is one mechanism, and this
module names the suite's kinds and their sensor settings (:data:`SETTINGS`):

* ``delay``     — ``latency`` d: every interval reported d later;
* ``jitter``    — ``jitter`` σ: every endpoint moved by an independent N(0, σ²) time error;
* ``missed``    — ``missed`` p: every closing or impact dropped with probability p;
* ``false``     — ``false_rate`` λ: spurious impacts at the times of a Poisson process of rate λ
  (1/s), kept only where the contact is seen open;
* ``threshold`` — ``threshold`` δ: a contact is seen closed once the master's predicted gap is
  at most δ (m);
* ``sampling``  — ``sampling_period`` T: χ read at the instants j·T and held in between.

A robustness case (:func:`robustness_rows`) is one level of one kind as a *paired ensemble*:
the masters of :func:`observer.compare.master_scenarios` (the scenario's own initial state and
``masters − 1`` sampled around it, as the ensemble suite draws them) × the initial errors of
:func:`observer.ensemble.sample_errors` (on the energy sphere of the scenario's own error), the
same for both designs and — the case's seed being the same at every level — the same at every
level of every kind. Each master's own run passes through the sensor
(:func:`observer.ensemble`'s ``sensor``, seeded per master by :func:`sensor_seed`), so every
master's observers see that master's χ as the sensor reports it.

A member's **floor** is the median of V(t)/V(t_on) over the last :data:`TAIL` of the coupling
window (the level V keeps between impacts; a latency also makes V spike for d seconds after
each impact, kept as ``peak``, the largest V/V(t_on) there).

:func:`perturb_log` (the sensor's log parts on a given closing log) serves the perturbed-χ
ensembles of the ensemble suite.
"""

from __future__ import annotations

import time

import pandas as pd

from observer.sensor import Sensor, sense_log

KINDS = ("none", "delay", "jitter", "missed", "false", "threshold", "sampling")
"""Perturbation kinds, in the order the report shows them."""

SETTINGS = {"delay": "latency", "jitter": "jitter", "missed": "missed", "false": "false_rate",
            "threshold": "threshold", "sampling": "sampling_period"}
"""The ``[observer.sensor]`` setting of each perturbation kind (``none``: the ideal sensor)."""

LOG_KINDS = ("none", "delay", "jitter", "missed", "false", "sampling")
"""The kinds :func:`perturb_log` can apply to a closing log (a threshold needs the gaps)."""

UNITS = {"none": "", "delay": "s", "jitter": "s", "missed": "probability", "false": "1/s",
         "threshold": "m", "sampling": "s"}
LABELS = {"none": "exact χ (the master's closed set)", "delay": "latency d of every interval",
          "jitter": "jitter σ of every endpoint", "missed": "probability p of missing a closing",
          "false": "false closings per second λ", "threshold": "gap threshold δ of the sensor",
          "sampling": "sampling period T of χ"}

TAIL = 0.25
"""A member's floor is taken over this last fraction of the coupling window."""


def sensor_of(kind: str, size: float, seed: int) -> dict:
    """The ``[observer.sensor]`` table of a perturbation (``{}`` for ``none``).

    Raises
    ------
    ValueError
        For a kind not in :data:`KINDS`.
    """
    if kind not in KINDS:
        raise ValueError(f"unknown perturbation {kind!r}; choose from {KINDS}")
    return {} if kind == "none" else {SETTINGS[kind]: size, "seed": seed}


def sensor_seed(case_seed: int, master: int) -> int:
    """The sensor seed of master ``master`` of a case seeded ``case_seed``: ``1000·seed + master``
    (each master's missed, false and jittered detections drawn apart, the same at every level)."""
    return 1000 * int(case_seed) + int(master)


def perturb_log(log: pd.DataFrame, kind: str, size: float, *, seed: int, m: int, t_end: float,
                h: float) -> pd.DataFrame:
    """``log`` as the sensor of :func:`sensor_of` sees it (:func:`observer.sensor.sense_log`).

    Parameters
    ----------
    log : DataFrame
        Closing log (``contact, t_close, t_open``).
    kind : str
        One of :data:`LOG_KINDS`.
    size : float
        d (s), σ (s), p (probability in [0, 1]), λ (1/s) or T (s), by ``kind``.
    seed : int
        The sensor's seed.
    m : int
        Number of contacts.
    t_end : float
        End of the run (intervals are clipped to [0, t_end]).
    h : float
        Step of the run: intervals of length ≤ h count as impacts.

    Returns
    -------
    DataFrame
        A valid closing log.

    Raises
    ------
    ValueError
        For a kind not in :data:`LOG_KINDS` (``threshold`` needs the master's gaps).
    """
    if kind in KINDS and kind not in LOG_KINDS:
        raise ValueError(f"perturbation {kind!r} needs the master's gaps, not a log; choose from {LOG_KINDS}")
    sensor = Sensor.from_table(sensor_of(kind, size, seed))
    return sense_log(log, sensor, m=m, t_end=t_end, h=h)


def tail_levels(paths: pd.DataFrame, V_on: pd.Series, t_on: float, t_off: float) -> pd.DataFrame:
    """Per (design, member) of an ensemble's V(t) ``paths`` the ``floor`` (median) and the
    ``peak`` (largest) of V/V(t_on) over the last :data:`TAIL` of the window [t_on, t_off];
    ``V_on`` is indexed by (design, member)."""
    tail = paths[(paths["t"] >= t_off - TAIL * (t_off - t_on) - 1e-12) & (paths["t"] <= t_off + 1e-12)]
    by = tail.groupby(["design", "member"])["V"]
    out = pd.concat([by.median().rename("floor"), by.max().rename("peak")], axis=1)
    on = V_on.reindex(out.index).to_numpy(dtype=float)
    return out.div(on, axis=0).reset_index()


def robustness_rows(case, masters) -> tuple[list[dict], float, float]:
    """The paired ensemble of one robustness case (module docstring): one row per (design,
    master, member) with ``V_on``, ``floor``, ``peak``, ``V_end``, the settling times, the
    master, the sensor's seed and intervals seen and the member's initial error (``dq0_j``,
    ``du0_j``); and the CPU and wall time of the runs.

    Parameters
    ----------
    case : bench.suites.Case
        ``perturbation``, ``size``, ``observers`` (the designs), ``seed``, ``engine``.
    masters : list of (Scenario, int, numpy.random.Generator)
        Per master its scenario, its number of members and the generator of their initial
        errors (``bench.runners`` ``_ensemble_masters``).
    """
    import observer
    from observer.metrics import window_of
    from observer.ensemble import sample_errors
    from observer.metrics import RHOS, settle_column

    designs = tuple(case.observers)
    rows, cpu, wall, first = [], 0.0, 0.0, 0
    for j, (sc, n, rng) in enumerate(masters):
        X, _ = sample_errors(sc, n, "energy_sphere", rng, None)
        seed = sensor_seed(case.seed, j)
        sensor = sensor_of(case.perturbation, case.size, seed) or None
        c0, w0 = time.process_time(), time.perf_counter()
        df = observer.ensemble(sc, designs, n=n, initial_errors=X, paths=n, workers=1, sensor=sensor,
                               engine=case.engine, label=case.name)
        cpu, wall = cpu + time.process_time() - c0, wall + time.perf_counter() - w0
        t_on, t_off = window_of(sc)
        levels = tail_levels(df.attrs.pop("paths"), df.set_index(["design", "member"])["V_on"], t_on, t_off)
        df = df.merge(levels, on=["design", "member"], validate="one_to_one")
        seen = df.attrs.get("metadata", {}).get("sensor", {}).get("intervals")
        for r in df.to_dict("records"):
            rows.append({"design": r["design"], "member": first + int(r["member"]), "master": j,
                         "sensor_seed": seed if sensor else -1, "status": str(r["status"]),
                         "V_on": float(r["V_on"]), "floor": float(r["floor"]), "peak": float(r["peak"]),
                         "V_end": float(r["V_end"]), "log_intervals": float("nan") if seen is None else float(seen),
                         **{settle_column(rho): float(r[settle_column(rho)]) for rho in RHOS},
                         **{c: float(r[c]) for c in r if c.startswith(("dq0_", "du0_"))}})
        first += n
    return rows, cpu, wall


def robustness_case_rows(case, masters) -> list[dict]:
    """:func:`robustness_rows` with the case's columns (the runner adds its base row)."""
    rows, cpu, wall = robustness_rows(case, masters)
    extra = {"perturbation": case.perturbation, "size": float(case.size),
             "setting": SETTINGS.get(case.perturbation, ""), "masters": len(masters),
             "members": int(sum(n for _, n, _ in masters)), "tail": TAIL, "note": "",
             "cpu_time_s": cpu, "wall_time_s": wall,
             "cpu_scope": f"{len(masters)} masters, each sensed, with {len(case.observers)} designs × "
                          f"its members"}
    return [{**r, **extra} for r in rows]
