"""Imperfect switching signals for the robustness suite: one sensor setting per perturbation.

A perturbation of the robustness suite is one part of a contact sensor
(:mod:`observer.sensor`, the ``[observer.sensor]`` table) applied to the master's own closing
log: there is one mechanism, and this module only names the suite's kinds and their sensor
settings (:data:`SETTINGS`):

* ``delay``  — ``latency`` d: every interval shifted later by d seconds;
* ``jitter`` — ``jitter`` σ: every endpoint moved by an independent N(0, σ²) time error (a
  zero-length impact is moved as a whole);
* ``missed`` — ``missed`` p: every closing or impact dropped with probability p;
* ``false``  — ``false_rate`` λ: spurious impacts at the times of a Poisson process of rate λ
  (1/s), kept only where the log says "open".

The case's seed is the sensor's ``seed``.
"""

from __future__ import annotations

import pandas as pd

from observer.sensor import Sensor, sense_log

KINDS = ("none", "delay", "jitter", "missed", "false")
"""Perturbation kinds, in the order the report shows them."""

SETTINGS = {"delay": "latency", "jitter": "jitter", "missed": "missed", "false": "false_rate"}
"""The ``[observer.sensor]`` setting of each perturbation kind (``none``: the ideal sensor)."""

UNITS = {"none": "", "delay": "s", "jitter": "s", "missed": "probability", "false": "1/s"}
LABELS = {"none": "exact χ (the master's closed set)", "delay": "delay d of every interval",
          "jitter": "jitter σ of every endpoint", "missed": "probability p of missing a closing",
          "false": "false closings per second λ"}


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


def perturb_log(log: pd.DataFrame, kind: str, size: float, *, seed: int, m: int, t_end: float,
                h: float) -> pd.DataFrame:
    """``log`` as the sensor of :func:`sensor_of` sees it (:func:`observer.sensor.sense_log`).

    Parameters
    ----------
    log : DataFrame
        Closing log (``contact, t_close, t_open``).
    kind : {"none", "delay", "jitter", "missed", "false"}
    size : float
        d (s), σ (s), p (probability in [0, 1]) or λ (1/s), by ``kind``.
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
    """
    sensor = Sensor.from_table(sensor_of(kind, size, seed))
    return sense_log(log, sensor, m=m, t_end=t_end, h=h)
