"""Draw the README's picture: log V of both observers on ``double_mass`` (h = 1e-3 s, 10 s).

Run from the project root: ``python docs/_static/make_readme_figure.py`` (writes
``docs/_static/readme_double_mass.png``)."""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import observer  # noqa: E402

sc = observer.load_scenario("double_mass", {"simulation.h": 1e-3, "simulation.t_end": 10.0})
df = observer.simulate(sc, observers=("jump", "nojump")).to_frame()
fig, ax = plt.subplots(figsize=(6, 2.6))
for name in ("jump", "nojump"):
    d = observer.OBSERVER_DESIGNS[name]
    V = df[f"V_{name}"].to_numpy()
    ax.semilogy(df["t"], np.where(V > 0, V, np.nan), color=d.color, label=d.label)
ax.set(xlabel="t [s]", ylabel="V (paper eq. 16)", title="double_mass: error of the two observers")
ax.grid(alpha=0.3, which="both")
ax.legend(fontsize=8)
fig.tight_layout()
fig.savefig(Path(__file__).with_name("readme_double_mass.png"), dpi=80)
