"""Observers driven by a measured contact log
==========================================

Compare the two observers when χ comes from a measured contact log, not from the master.

In an experiment the observer sees a log of contact closings written by a sensor
(CSV columns ``contact, t_close, t_open``; an impact is a zero-length interval), with
timing errors. This script:

1. simulates the observed system (the master of ``double_mass``) and writes its closings
   as a log, at the step midpoints where the scheme decides them (an exact log),
2. makes "measured" logs from it: every interval endpoint moved by a Gaussian timing
   error of standard deviation σ (an impact as a whole; seeded:
   ``np.random.default_rng(seed)``), then sorted and merged where the errors made
   intervals overlap (as a sensor would report them),
3. runs both observers with ``source="log"`` (they see only the log; V is still measured
   against the true master, paper eq. (16)) and prints and plots their settling times.

Settling time: the time after which V stays at or below ρ·V(0). A logged impact that is
early or late by δ leaves the observer with the wrong velocity for δ, so V spikes for a
few steps at every impact; a running median over 0.1 s removes those spikes (not the
trend) before the settling time is read. "inf": V does not stay below ρ·V(0) by the end.
The timing errors also set the level V ends at ("floor", median of V/V(0) over the last
10 % of the run).

    python examples/measured_log.py [--out DIR] [--quick] [--seed N]
"""

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")                       # write files, never open a window
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

import observer  # noqa: E402

parser = argparse.ArgumentParser(description=(__doc__ or "").partition("\n")[0])
parser.add_argument("--out", default=Path(sys.argv[0]).parent / "out", type=Path, help="output directory")
parser.add_argument("--quick", action="store_true", help="h = 1e-3 s and 10 s instead of 1e-4 s and 20 s")
parser.add_argument("--seed", type=int, default=0, help="seed of the timing errors")
args = parser.parse_args()
args.out.mkdir(parents=True, exist_ok=True)
SIGMAS = (0.0, 1e-4, 3e-4, 1e-3)            # timing error σ of the sensor [s]; 0: the exact log
RHOS = (1e-2, 1e-3)                         # settling thresholds ρ (fractions of V(0))
scenario = observer.load_scenario("double_mass", {"simulation.h": 1e-3, "simulation.t_end": 10.0}
                                  if args.quick else {"simulation.h": 1e-4, "simulation.t_end": 20.0})
h = scenario.h


def exact_log(frame):
    """Closed intervals of each contact: runs of active steps; row k+1 holds step k, which
    the scheme decides at its midpoint t_{k+1} - h/2."""
    rows, t = [], frame["t"].to_numpy()
    for j in range(scenario.system.m):
        edges = np.diff(np.concatenate([[0], frame[f"active{j}"].to_numpy(int), [0]]))
        starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
        rows += [(j, t[a] - h / 2, t[b] - h / 2) for a, b in zip(starts, ends)]
    return pd.DataFrame(rows, columns=["contact", "t_close", "t_open"])


def measured(log, sigma, rng):
    """Endpoints moved by N(0, σ²) errors (an impact, zero length, as a whole), clipped at the
    start of the recording t = 0 (a log holds no time before it), intervals sorted and
    overlapping ones merged."""
    err_close, err_open = rng.normal(0.0, sigma, (2, len(log)))
    err_open = np.where(log["t_open"] == log["t_close"], err_close, err_open)
    noisy = log.assign(t_close=log["t_close"] + err_close, t_open=log["t_open"] + err_open)
    noisy[["t_close", "t_open"]] = noisy[["t_close", "t_open"]].clip(lower=0.0)
    noisy["t_open"] = noisy[["t_close", "t_open"]].max(axis=1)        # a contact opens after it closes
    merged = []
    for j, a, b in noisy.sort_values(["contact", "t_close"]).itertuples(index=False):
        if merged and merged[-1][0] == j and a <= merged[-1][2]:
            merged[-1][2] = max(merged[-1][2], b)      # overlaps the previous interval
        else:
            merged.append([j, a, b])
    return pd.DataFrame(merged, columns=log.columns)


def smooth(V):
    """Running median of V over 0.1 s: removes the spikes of mistimed impacts."""
    return pd.Series(V).rolling(max(1, round(0.1 / h)), center=True, min_periods=1).median().to_numpy()


def settling(t, V, rho):
    """Time from t = 0 after which the 0.1 s running median of V stays ≤ ρ·V(0)."""
    above = np.flatnonzero(smooth(V) > rho * V[0])
    if above.size == 0:
        return 0.0                          # never above
    if above[-1] == len(t) - 1:
        return np.inf                       # still above at the end of the run
    return t[above[-1] + 1] - t[0]


truth = exact_log(observer.simulate(scenario).to_frame())          # 1. the master's closings
rng, rows, curves = np.random.default_rng(args.seed), [], {}
for sigma in SIGMAS:                                                 # 2.-3. one log per σ
    path = args.out / f"log_sigma_{sigma:g}.csv"
    log = measured(truth, sigma, rng)
    log.to_csv(path, index=False)                                    # the format a sensor writes
    frame = observer.simulate(scenario, observers=("jump", "nojump"), source="log", log=path).to_frame()
    t = frame["t"].to_numpy()
    for name in ("jump", "nojump"):
        V = frame[f"V_{name}"].to_numpy()
        curves[sigma, name] = V
        rows.append({"sigma_s": sigma, "observer": name, "intervals_logged": len(log),
                     **{f"settle_{rho:g}": settling(t, V, rho) for rho in RHOS},
                     "floor": np.median(V[-len(V) // 10:]) / V[0]})   # V/V(0), last 10 %
table = pd.DataFrame(rows)
print(f"double_mass, h = {h:g} s, seed {args.seed}; settling times [s] of the 0.1 s median of V")
print(table.to_string(index=False))

fig, (ax_v, ax_s) = plt.subplots(1, 2, figsize=(11, 3.8))
for name, color in (("jump", "tab:blue"), ("nojump", "tab:red")):
    ax_v.semilogy(t, curves[SIGMAS[-1], name], color=color, lw=0.4, alpha=0.5)
    ax_v.semilogy(t, smooth(curves[SIGMAS[-1], name]), color=color, lw=1.5, label=f"{name} (0.1 s median)")
    settle = table[table["observer"] == name][f"settle_{RHOS[-1]:g}"]
    ax_s.plot(np.array(SIGMAS) * 1e3, settle.replace(np.inf, np.nan), "o-", color=color, label=name)
ax_v.set(xlabel="t [s]", ylabel="V", title=f"V with a log of timing error σ = {SIGMAS[-1] * 1e3:g} ms")
ax_s.set(xlabel="σ [ms]", ylabel=f"settling time to {RHOS[-1]:g}·V(0) [s]", title="a missing point: never settles")
for ax in (ax_v, ax_s):
    ax.legend()
    ax.grid(alpha=0.3)
fig.tight_layout()
fig.savefig(args.out / "measured_log.png", dpi=110)
