"""A system of your own
====================

Simulate a system of your own from a TOML file and check the paper's proof steps on it.

``my_system.toml`` (next to this script) describes three masses between two walls with a
stop on mass 0 and a clearance between masses 1 and 2: copy it and edit the matrices, the
contacts (columns of W and the gap offsets), the impact law and the initial states.

The script:

1. loads the file and prints the system (n, m, the law),
2. simulates the master with every registered observer design (with position jumps in the
   K metric, the paper's; without; jumps in other metrics), plots the master's gaps and
   each observer's error Lyapunov function V (paper eq. (16)) to DIR/NAME.png and prints
   how fast V falls,
3. runs every numerical check of Proposition 1 and Theorem 1 (``proofs_checks.run_checks``:
   assumptions A1-A3, eqs. (13)-(14), (17), ...) and prints the table.

Exit status: 0 when no check FAILed (PASS or n/a = not applicable), 1 when one did, so the
script can gate a CI job; 2 with one line ``error: FIELD: ...`` on stderr for bad input. A FAIL is a finding, not a crash: read its witness (e.g. the
discrete impulse slack of ``lyapunov_decrease``, an O(h) effect explained in the README).

    python examples/my_system.py [path/to/system.toml] [--out DIR] [--quick]
"""

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")                       # write files, never open a window
import matplotlib.pyplot as plt  # noqa: E402

import observer  # noqa: E402
import proofs_checks  # noqa: E402

parser = argparse.ArgumentParser(description=(__doc__ or "").partition("\n")[0])
parser.add_argument("toml", nargs="?", default=Path(sys.argv[0]).with_name("my_system.toml"), type=Path)
parser.add_argument("--out", default=Path(sys.argv[0]).parent / "out", type=Path, help="output directory")
parser.add_argument("--quick", action="store_true", help="h = 1e-3 s and 3 s: a few seconds")
args = parser.parse_args()
args.out.mkdir(parents=True, exist_ok=True)

# 1. Load. Bad input (a typo, a matrix that is not symmetric PSD, ...) raises
#    observer.InputError, whose message names the field: print it and exit with status 2.
overrides = {"simulation.h": 1e-3, "simulation.t_end": 3.0} if args.quick else {}
try:
    scenario = observer.load_scenario(args.toml, overrides)
except observer.InputError as exc:
    print(f"error: {exc}", file=sys.stderr)
    sys.exit(2)
system = scenario.system
print(f"{scenario.name}: n = {system.n} DOF, m = {system.m} contacts, {scenario.law.law} law, "
      f"h = {scenario.h:g} s, t_end = {scenario.t_end:g} s")

# 2. Simulate the master and every registered observer design, all started from the file's
#    [observer] state: "jump" (the paper's, position jumps in the K metric), "nojump" (the
#    earlier design) and whatever else observer.OBSERVER_DESIGNS holds (other metrics).
designs = observer.OBSERVER_DESIGNS
result = observer.simulate(scenario, observers=tuple(designs))
frame = result.to_frame()            # t, q0.., g0.., active0.., jump_q0.., V_jump, V_nojump, ...
closings = (frame.filter(like="active").diff() > 0).sum()            # 0 -> 1 per contact
print("master closings per contact:", closings.to_dict())
fig, (ax_g, ax_v) = plt.subplots(2, 1, sharex=True, figsize=(7, 5))
for j in range(system.m):                                            # the master's gaps
    ax_g.plot(frame["t"], frame[f"g{j}"], lw=0.8, label=f"$g_{j}$")
for name, d in designs.items():                                      # eq. (16) per observer
    ax_v.semilogy(frame["t"], frame[f"V_{name}"].where(frame[f"V_{name}"] > 0), color=d.color,
                  ls=d.linestyle, label=d.label)
ax_g.set(ylabel="gap [m]", title=scenario.name)
ax_v.set(ylabel="V", xlabel="t [s]")
for ax in (ax_g, ax_v):
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
fig.savefig(args.out / f"{scenario.name}.png", dpi=110)
sync = result.synchronization()     # first passage (t_sync) and settling (t_settle) of V
times = [c for c in sync.columns if c.startswith(("t_sync_", "t_settle_"))]   # one per threshold ρ
print(sync[["observer", "V_on", *times, "rate"]].to_string(index=False))

# 3. The proof checks. Every check returns passed (True/False/None), a signed margin
#    (passed <=> margin >= -tolerance) and a witness (where the margin is worst).
#    Quick mode shortens the runs the checks replay.
checks = proofs_checks.run_checks(scenario, t_end=3.0 if args.quick else None)
table = proofs_checks.results_frame(checks)
print(f"{'check':<24} {'status':<6} {'margin':>10} {'tol':>8}  equation")
for row in table.itertuples():
    print(f"{row.check:<24} {row.status:<6} {row.margin:>10.3g} {row.tolerance:>8.2g}  {row.equation}")
table.to_csv(args.out / f"{scenario.name}_checks.csv", index=False)   # with the full witnesses

failed = table.loc[table["status"] == "FAIL", "check"].tolist()
for row in table[table["status"] == "FAIL"].itertuples():
    print(f"FAIL {row.check}: {row.witness}")                        # reason, then witness
print(f"{len(table) - len(failed)} of {len(table)} checks without failure; failed: {failed or 'none'}")
if failed:
    sys.exit(1)             # exit status 0 otherwise (the end of the script)
