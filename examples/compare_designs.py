"""Comparing two observer designs, with intervals
==============================================

Do position jumps make the observer converge faster, and how sure is that?

:func:`observer.compare` runs paired ensembles of both designs (the observer with position
jumps, ``jump``, and the no-jump observer, ``nojump``) against several masters of the built-in
scenario ``double_mass``: each master is one trajectory, each member one initial error of the
observer (paper eq. (16) measures it, ``V``). The intervals resample whole masters (a master is
a cluster: its members share the contact times), so they say how far the answer would move
with another set of masters, not only another set of initial errors. The script prints the
comparison's lines (decay-rate ratio, which design settles first, the censored settling
summary, the floors and any warnings) and draws, per design, the Kaplan–Meier curve of the
settling times (:func:`observer.stats.kaplan_meier`; a member that has not settled by the end
of the window is right-censored there, not dropped) and the per-member decay rates.

The sizes here are small so that the gallery builds quickly; the intervals are wide
accordingly. ``--quick`` uses fewer members and a shorter horizon.

    python examples/compare_designs.py [--out DIR] [--quick] [--seed N]
"""

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")                       # write files, never open a window
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import observer  # noqa: E402
from observer.stats import kaplan_meier  # noqa: E402

parser = argparse.ArgumentParser(description=(__doc__ or "").partition("\n")[0])
parser.add_argument("--out", default=Path(sys.argv[0]).parent / "out", type=Path, help="output directory")
parser.add_argument("--quick", action="store_true", help="6 members x 3 masters, 4 s, instead of 20 x 5, 8 s")
parser.add_argument("--seed", type=int, default=0, help="seed of the masters and the initial errors")
args = parser.parse_args()
args.out.mkdir(parents=True, exist_ok=True)
N, MASTERS, T_END = (6, 3, 4.0) if args.quick else (20, 5, 8.0)
RHO = 1e-3                                  # settling threshold: V ≤ ρ·V(t_on)
COLORS = {"jump": "tab:blue", "nojump": "tab:red"}

cmp = observer.compare("double_mass", n=N, masters=MASTERS, rho=RHO, seed=args.seed, h=1e-3, t_end=T_END)
print("\n".join(cmp.lines()))

members, column = cmp.members, f"t_settle_{RHO:g}"
window = cmp.window[1] - cmp.window[0]
fig, (ax_km, ax_rate) = plt.subplots(1, 2, figsize=(11, 3.8))
for k, design in enumerate(cmp.designs):
    rows = members[members["design"] == design]
    sf = kaplan_meier(rows[column].to_numpy(), window)
    if sf is None:                          # no member settled: S(t) = 1 on the whole window
        ax_km.step([0.0, window], [1.0, 1.0], where="post", color=COLORS[design], label=f"{design} (none settled)")
    else:
        t = np.concatenate([[0.0], sf.quantiles, [window]])
        S = np.concatenate([[1.0], sf.probabilities, [sf.probabilities[-1]]])
        ax_km.step(t, S, where="post", color=COLORS[design], label=design)
    for c, group in rows.groupby("cluster"):
        x = k + 0.25 * (c - (MASTERS - 1) / 2) / max(MASTERS - 1, 1)
        ax_rate.plot(np.full(len(group), x), group["rate"], "o", ms=3, color=COLORS[design], alpha=0.7)
ax_km.set(xlabel=f"time after coupling [s] (censored at {window:g} s)", ylabel="share not yet settled",
          title=f"Kaplan–Meier: settling below {RHO:g}·V(t_on)", ylim=(-0.02, 1.02))
ax_km.legend()
ax_rate.set(xticks=range(len(cmp.designs)), xticklabels=cmp.designs, ylabel="decay rate of V [1/s]",
            title="per-member decay rates (grouped by master)")
for ax in (ax_km, ax_rate):
    ax.grid(alpha=0.3)
fig.tight_layout()
fig.savefig(args.out / "compare_designs.png", dpi=110)
