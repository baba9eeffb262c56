"""Paper-style figures of a run: trajectories (master black, each observer design in its
registered colour and style: jump blue, no-jump red, …) and log V."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from observer.errors import InputError
from observer.observers import OBSERVER_DESIGNS


def _style(name: str) -> dict:
    """Colour and line style of observer ``name`` (its design's; matplotlib's cycle otherwise)."""
    d = OBSERVER_DESIGNS.get(name)
    return {} if d is None else {"color": d.color, "ls": d.linestyle}


def observer_names(df: pd.DataFrame) -> list[str]:
    """Observer names present in a result frame (columns ``V_NAME``)."""
    return [c[2:] for c in df.columns if c.startswith("V_")]


def plot_run(df: pd.DataFrame, out: str | Path, dof: int = 0) -> Path:
    """Draw q_dof(t), u_dof(t) and, with observers, V(t) on a log scale; save to ``out``."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    formats = plt.figure().canvas.get_supported_filetypes()
    plt.close("all")
    if out.suffix.lstrip(".").lower() not in formats:
        raise InputError("--out", f"unsupported image format {out.suffix!r}; use one of "
                         f"{', '.join('.' + f for f in ('png', 'svg', 'pdf'))}")
    if f"q{dof}" not in df.columns:
        raise InputError("--dof", f"no coordinate q{dof} in the result")
    names = observer_names(df)
    rows = 3 if names else 2
    fig, axes = plt.subplots(rows, 1, figsize=(8, 2.4 * rows + 0.6), sharex=True)
    t = df["t"].to_numpy()
    for ax, var in zip(axes, ("q", "u")):
        ax.plot(t, df[f"{var}{dof}"], color="black", lw=1.2, label="master")
        for name in names:
            ax.plot(t, df[f"{name}_{var}{dof}"], lw=0.9, label=name, **_style(name))
        ax.set_ylabel(f"${var}_{{{dof}}}$")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    if names:
        ax = axes[2]
        for name in names:
            V = df[f"V_{name}"].to_numpy()
            ax.semilogy(t, np.where(V > 0, V, np.nan), lw=1.0, label=f"V {name}", **_style(name))
        ax.set_ylabel("V")
        ax.grid(alpha=0.3, which="both")
        ax.legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("t [s]")
    title = df.attrs.get("scenario", "")
    if title:
        fig.suptitle(f"{title} (h = {df.attrs.get('h', '?')})", fontsize=10)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out
