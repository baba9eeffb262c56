"""Figures of the report: matplotlib (Agg) → PNG → ``data:`` URI, so the page is self-contained.

Colours, labels and line styles come from the observer designs
(:func:`reports.registry.look`: master black, each design its registered look). Every function returns a :class:`Figure` (data URI + alt text) or None when
there is nothing to draw (the report then says so instead of showing an empty plot).
"""

from __future__ import annotations

import base64
import io
import multiprocessing
import pickle
import textwrap
from functools import partial
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, replace
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import FuncFormatter, LogFormatterSciNotation  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from reports.registry import MASTER, REFERENCE_SOLVER, contact_solvers, look  # noqa: E402

DPI = 96


@dataclass(frozen=True)
class Figure:
    """An inline image: ``src`` is a ``data:image/png;base64,...`` URI (a :class:`Pending`
    one while :func:`parallel_rendering` renders it)."""

    src: str | Pending
    alt: str
    caption: str = ""


PNG_OPTIONS = {"compress_level": 3}
"""Pillow's PNG settings: level 3 encodes faster than the default 6 for a few per cent more bytes."""
_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def decade_label(x: float, _pos=None) -> str:
    """Tick label of a log axis in plain Unicode (``10⁻⁶``; ``2e-06`` off the decades): the same
    text as matplotlib's default, without its mathtext parser (≈ 10 % of a page's build time)."""
    if not (np.isfinite(x) and x > 0):
        return ""
    e = round(float(np.log10(x)))
    return f"10{str(e).translate(_SUPERSCRIPT)}" if np.isclose(x, 10.0 ** e, rtol=1e-9) else f"{x:g}"


def _minor_label(axis, x: float, _pos=None) -> str:
    """Minor tick label of a log axis: none, unless the view spans less than a decade (it may
    then hold no decade at all): 2·10ᵏ and 5·10ᵏ labelled as ``2e-06``."""
    lo, hi = sorted(axis.get_view_interval())
    if not (lo > 0 and hi / lo < 10.0) or f"{x:.0e}"[0] not in "25":
        return ""
    return f"{x:g}"


def _tidy_log_axes(axes) -> None:
    """Where a log axis has matplotlib's default (mathtext) formatters: major ticks labelled by
    :func:`decade_label`, minor ticks unlabelled (they overlap on narrow panels)."""
    for ax in np.ravel(axes):
        for axis, scale in ((ax.xaxis, ax.get_xscale()), (ax.yaxis, ax.get_yscale())):
            if scale == "log":
                if isinstance(axis.get_major_formatter(), LogFormatterSciNotation):
                    axis.set_major_formatter(FuncFormatter(decade_label))
                if isinstance(axis.get_minor_formatter(), LogFormatterSciNotation):
                    axis.set_minor_formatter(FuncFormatter(partial(_minor_label, axis)))


def fixed_layout(fig, left: float = 0.85, right: float = 0.2, top: float = 0.4, bottom: float = 0.55,
                 hspace: float = 0.3, wspace: float = 0.75) -> None:
    """Margins and gaps of a grid of subplots in inches (instead of ``tight_layout``, which
    measures every tick label: ≈ 40 % of a figure's time): ``left`` holds a y label and tick
    labels of up to 6 characters, ``bottom`` an x label and tick labels, ``top`` a title."""
    w, h = fig.get_size_inches()
    rows, cols = fig.axes[0].get_subplotspec().get_gridspec().get_geometry()
    ax_h = (h - top - bottom - (rows - 1) * hspace) / rows
    ax_w = (w - left - right - (cols - 1) * wspace) / cols
    fig.subplots_adjust(left=left / w, right=1 - right / w, top=1 - top / h, bottom=bottom / h,
                        hspace=hspace / ax_h, wspace=wspace / ax_w)


def _render(fig, fit: bool) -> str:
    """The PNG data URI of ``fig`` (closed after): one draw (:func:`to_data_uri`)."""
    _tidy_log_axes(fig.axes)
    if fit and fig.get_layout_engine() is None:
        fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, pil_kwargs=PNG_OPTIONS)
    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _render_pickled(data: bytes, fit: bool) -> str:
    """:func:`_render` of a pickled figure (in a worker process of :func:`parallel_rendering`)."""
    return _render(pickle.loads(data), fit)


_POOL: list = []
"""The process pool of the enclosing :func:`parallel_rendering` (empty outside it)."""


@dataclass(frozen=True)
class Pending:
    """A figure being rendered in :func:`parallel_rendering`'s pool; ``str()`` waits for its
    data URI (:func:`resolve` replaces it in the figures before the page is written)."""

    future: Any

    def __str__(self) -> str:
        return self.future.result()


def to_data_uri(fig, fit: bool = True) -> str | Pending:
    """Render a matplotlib figure as a base64 PNG data URI and close it.

    One draw: the log axes' labels are set (:func:`_tidy_log_axes`), the layout fitted once
    (``tight_layout``; not with ``fit=False``, a figure placed by :func:`fixed_layout`, nor
    one with its own layout engine, e.g. ``"constrained"``) and the canvas saved as it is (no
    ``bbox_inches="tight"``, which draws the figure twice). Inside :func:`parallel_rendering`
    the figure is pickled and rendered in a worker process: a :class:`Pending` is returned.
    """
    if not _POOL:
        return _render(fig, fit)
    data = pickle.dumps(fig)
    plt.close(fig)
    return Pending(_POOL[0].submit(_render_pickled, data, fit))


@contextmanager
def parallel_rendering(workers: int):
    """Within the block, :func:`to_data_uri` renders in ``workers`` forked processes (none
    with ``workers`` ≤ 1: each figure is rendered at once), while the caller goes on building
    the page; the figures' layout, drawing and PNG encoding are ≈ half of a page's CPU time.
    Pass every figure made inside through :func:`resolve` before leaving the block."""
    if workers <= 1:
        yield
        return
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork"))
    _POOL.append(pool)
    try:
        yield
    finally:
        _POOL.clear()
        pool.shutdown(wait=True, cancel_futures=True)


def resolve(figure: Figure) -> Figure:
    """``figure`` with its data URI (waiting for a :class:`Pending` one)."""
    return figure if isinstance(figure.src, str) else replace(figure, src=str(figure.src))


def _positive(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    return np.where(x > 0, x, np.nan)


def scenario_figure(traj: pd.DataFrame, title: str, observers: list[str], window: tuple[float, float],
                    coord_label: str, contact_label: str) -> Figure | None:
    """The paper's figure of one scenario: a gap, a coordinate, and log V of each observer.

    Parameters
    ----------
    traj : DataFrame
        Columns ``t, master_q, master_g, <obs>_q, <obs>_g, V_<obs>`` (downsampled run).
    observers : list of str
        Observers present in ``traj``.
    window : (t_on, t_off)
        Coupling window, shaded.
    """
    if traj is None or traj.empty:
        return None
    t = traj["t"].to_numpy()
    fig, axes = plt.subplots(3, 1, figsize=(8.6, 6.6), sharex=True)
    for ax, var, label in ((axes[0], "g", contact_label), (axes[1], "q", coord_label)):
        for name in (MASTER, *observers):
            col, lk = f"{name}_{var}", look(name)
            if col in traj:
                ax.plot(t, traj[col], color=lk.color, lw=1.3 if name == MASTER else 1.0,
                        ls=lk.linestyle, label=lk.label)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].axhline(0.0, color="0.5", lw=0.6)
    axes[0].legend(loc="upper right", fontsize=8, ncol=3)
    ax = axes[2]
    drawn = False
    for name in observers:
        col = f"V_{name}"
        if col in traj:
            lk = look(name)
            ax.semilogy(t, _positive(traj[col]), color=lk.color, ls=lk.linestyle, lw=1.0,
                        label=f"V, {lk.label}")
            drawn = True
    if not drawn:
        plt.close(fig)
        return None
    ax.set_ylabel("V (J)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(loc="upper right", fontsize=8)
    t_on, t_off = window
    for a in axes:
        a.axvspan(t_on, t_off, color="0.92", zorder=0)
    axes[-1].set_xlabel("t (s)   (shaded: coupling window, χ from the master)")
    fig.suptitle(title, fontsize=11)
    fixed_layout(fig, top=0.45, hspace=0.2)
    return Figure(to_data_uri(fig, fit=False), f"{title}: gap, coordinate and log V of the observers",
                  f"Top: {contact_label}; middle: {coord_label}; bottom: V of each observer "
                  "(log scale).")


def work_precision_figure(wp: pd.DataFrame, orders: dict[str, float]) -> Figure | None:
    """One row per (scenario, quantity): log error against log CPU time (left) and against
    log h (right), one line per (impact law, contact solver)."""
    if wp.empty:
        return None
    groups = list(dict.fromkeys(zip(wp["scenario"], wp["target"])))
    fig, axes = plt.subplots(len(groups), 2, figsize=(10.5, 3.1 * len(groups)), squeeze=False)
    for i, (scen, target) in enumerate(groups):
        sub = wp[(wp["scenario"] == scen) & (wp["target"] == target)]
        color = look(target).color
        for method, g in sub.groupby("method", sort=False):
            g = g.sort_values("h")
            law, solver = g["law"].iloc[0], g["solver"].iloc[0]
            ls = "-" if law == "newton" else "--"
            fast = solver != REFERENCE_SOLVER
            marker, mfc, ms = ("o", color, 5) if fast else ("s", "none", 8)
            p = orders.get(method, float("nan"))
            label = f"{law} · {solver} (p = {p:.2f})" if np.isfinite(p) else f"{law} · {solver} (p = —, no fit)"
            axes[i, 0].loglog(g["cpu_time_s"], g["err_mean"], ls=ls, marker=marker, color=color,
                              mfc=mfc, ms=ms, lw=1.1, label=label)
            axes[i, 1].loglog(g["h"], g["err_mean"], ls=ls, marker=marker, color=color, mfc=mfc,
                              ms=ms, lw=1.1, label=label)
        hs = np.sort(sub["h"].unique())
        ref = sub["err_mean"].median() * hs / np.median(hs)
        axes[i, 1].loglog(hs, ref, color="0.6", lw=0.8, ls="-.", label="slope 1")
        what = look(target).label
        refname = sub["reference"].iloc[0].split(" (")[0]
        axes[i, 0].set_title(f"{scen}: {what} (reference: {refname})", fontsize=9, loc="left")
        axes[i, 0].set_xlabel("CPU time (s)")
        axes[i, 1].set_xlabel("h (s)")
        for a in axes[i]:
            a.grid(alpha=0.3, which="both")
            a.set_ylabel("error", fontsize=9)
        axes[i, 1].legend(fontsize=7, loc="lower right")
    fixed_layout(fig, top=0.3, hspace=0.75, wspace=0.8)
    return Figure(to_data_uri(fig, fit=False), "work-precision diagrams: error against CPU time and against h",
                  "Left: error (time average of max_i |q_i − q_ref,i|) against CPU time "
                  "(work-precision). Right: the same error against h, with a slope-1 guide. Solid: "
                  "Newton law; dashed: Poisson law; filled circles: fast contact solver; open squares: "
                  "cvxpy/OSQP reference solver (same errors, more CPU time). Colours: master black, "
                  + ", ".join(f"{look(t).label} {look(t).color.replace('tab:', '')}"
                              for t in dict.fromkeys(wp["target"]) if t != MASTER) + ".")


def _whole_call_panel(ax, sc: pd.DataFrame, fit: tuple[float, float, int] | None) -> None:
    """The whole call's CPU time (load + setup + loop + health) against N, with its fit
    ``(p, c, N_min)`` drawn over the N it was fitted on."""
    N = sc["N"].to_numpy(dtype=float)
    ax.loglog(N, sc["whole_call_cpu_s"], "o-", color="black", label="whole call")
    if fit is not None:
        p, c, n_min = fit
        Nf = N[N >= n_min]
        ax.loglog(Nf, np.exp(c) * Nf ** p, "--", color="tab:orange", label=f"fit ∝ N^{p:.2f} (N ≥ {n_min})")
    ax.set_xlabel("N")
    ax.set_ylabel("load_scenario + simulate, CPU (s)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)


def scaling_figure(sc: pd.DataFrame, fit_time: tuple[float, float], fit_mem: tuple[float, float] | None,
                   fit_from: int | None = None,
                   fit_whole: tuple[float, float, int] | None = None) -> Figure | None:
    """CPU time per step, peak memory and (when the rows have it) the whole call's CPU time
    against N (log-log) with the fitted power laws (the time fits drawn over the N they were
    fitted on, ``N ≥ fit_from``)."""
    sc = sc[sc["status"] == "ok"].sort_values("N")
    if sc.empty:
        return None
    N = sc["N"].to_numpy(dtype=float)
    whole = "whole_call_cpu_s" in sc and sc["whole_call_cpu_s"].notna().any()
    fig, axes = plt.subplots(1, 3 if whole else 2, figsize=(15 if whole else 10, 3.8))
    if whole:
        _whole_call_panel(axes[2], sc, fit_whole)
    ax = axes[0]
    ax.loglog(N, sc["cpu_per_step_s"] * 1e6, "o-", color="black", label="measured")
    p, c = fit_time
    Nf = N[N >= fit_from] if fit_from is not None else N
    ax.loglog(Nf, np.exp(c) * Nf ** p * 1e6, "--", color="tab:blue",
              label=f"fit ∝ N^{p:.2f}" + (f" (N ≥ {fit_from})" if fit_from is not None else ""))
    ax.set_xlabel("N (blocks; n = m = 2N)")
    ax.set_ylabel("CPU time per step, setup subtracted (µs)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax = axes[1]
    if "peak_mem_mb" in sc and sc["peak_mem_mb"].notna().any():
        ax.loglog(N, sc["peak_mem_mb"], "o-", color="black", label="peak traced memory")
        if fit_mem is not None:
            p, c = fit_mem
            ax.loglog(N, np.exp(c) * N ** p, "--", color="tab:blue", label=f"fit ∝ N^{p:.2f}")
        ax.set_ylabel("peak memory (MB)")
    ax.set_xlabel("N")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    for a in axes:
        a.set_xticks([int(n) for n in N], [str(int(n)) for n in N])
    return Figure(to_data_uri(fig), "scaling of the rocking chain with N")


def solver_colors() -> dict[str, str]:
    """One colour per registered contact solver (the reference grey, the others the
    matplotlib cycle in registry order)."""
    fast = [s for s in contact_solvers() if s != REFERENCE_SOLVER]
    return {REFERENCE_SOLVER: "0.35", **{s: f"C{i}" for i, s in enumerate(fast)}}


def micro_figure(micro: pd.DataFrame) -> Figure | None:
    """Mean time of one contact solve per solver and size (log scale bars)."""
    cs = micro[micro["kind"] == "contact_solve"]
    if cs.empty:
        return None
    sizes = sorted(cs["m"].unique())
    solvers = list(dict.fromkeys(cs["solver"]))
    fig, ax = plt.subplots(figsize=(7.5, 3.4))
    width = 0.8 / len(solvers)
    colors = solver_colors()
    for i, s in enumerate(solvers):
        vals = [float(cs[(cs["m"] == m) & (cs["solver"] == s)]["mean_s"].mean()) * 1e6 for m in sizes]
        ax.bar(np.arange(len(sizes)) + (i - (len(solvers) - 1) / 2) * width, vals, width,
               label=s, color=colors.get(s))
    ax.set_yscale("log")
    ax.set_xticks(np.arange(len(sizes)), [f"m = {int(m)}" for m in sizes])
    ax.set_ylabel("mean time per solve (µs)")
    ax.grid(alpha=0.3, axis="y", which="both")
    ax.legend(fontsize=8, ncol=len(solvers))
    return Figure(to_data_uri(fig), "micro-benchmark: time of one contact solve per solver")


def _matrix_label(r: pd.Series) -> str:
    """Cell text of the settling matrix: median [10 %, 90 %] in s, and the never-settling share."""
    def t(x: float) -> str:
        return "∞" if np.isinf(x) else f"{x:.3g}"
    text = f"{t(r['median'])}\n[{t(r['q10'])}, {t(r['q90'])}]"
    return text + (f"\n✗ {100 * r['never']:.0f} % never" if r["never"] > 0 else "")


def _seconds_label(x: float, _pos=None) -> str:
    """Colour-bar tick label of the settling matrix: 1, 2 and 5 × 10ᵏ s as ``0.5``, ``20``."""
    return f"{x:g}" if f"{x:.0e}"[0] in "125" else ""


MATRIX_LABEL_CHARS = 44
"""Row labels of the settling matrix wrap at this many characters (the figure is sized to them)."""


def settling_matrix_figure(mat: pd.DataFrame) -> Figure | None:
    """Scenario (label · integrator) × design: the median settling time (colour, log scale) with
    its 10–90 % band in the cell; cells where some members never settle are hatched and say
    which share (:func:`reports.ensemble_view.settling_matrix`)."""
    if mat.empty:
        return None
    mat = mat.assign(row=mat["label"] + " · " + mat["integrator"])
    rows = list(dict.fromkeys(mat["row"]))
    cols = list(dict.fromkeys(mat["design"]))
    grid = np.full((len(rows), len(cols)), np.nan)
    names = [textwrap.fill(r, MATRIX_LABEL_CHARS) for r in rows]
    label_in = 0.07 * max(len(line) for n in names for line in n.splitlines())   # 8 pt ≈ 0.07 in/char
    fig, ax = plt.subplots(figsize=(1.6 + label_in + 1.9 * len(cols), 1.2 + 0.75 * len(rows)),
                           layout="constrained")                  # the colorbar and the labels fit
    for _, r in mat.iterrows():
        i, j = rows.index(r["row"]), cols.index(r["design"])
        grid[i, j] = np.nan if np.isinf(r["median"]) else r["median"]
        ax.text(j, i, _matrix_label(r), ha="center", va="center", fontsize=7.5)
        if r["never"] > 0:
            ax.add_patch(plt.Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, hatch="///",
                                       edgecolor="tab:red", lw=0.0))
    pos = grid[np.isfinite(grid) & (grid > 0)]
    norm = matplotlib.colors.LogNorm(vmin=pos.min(), vmax=pos.max()) if pos.size and pos.min() < pos.max() else None
    im = ax.imshow(np.where(grid > 0, grid, np.nan), cmap="YlGnBu", norm=norm, aspect="auto", alpha=0.75)
    cb = fig.colorbar(im, ax=ax, label="median settling time (s)", shrink=0.8)
    seconds = FuncFormatter(_seconds_label)
    cb.ax.yaxis.set_major_formatter(seconds)
    cb.ax.yaxis.set_minor_formatter(seconds)
    ax.set_xticks(range(len(cols)), [look(c).label.replace(" (", "\n(") for c in cols], fontsize=8)
    ax.set_yticks(range(len(rows)), names, fontsize=8)
    rho = float(mat["rho"].iloc[0])
    ax.set_title(f"Settling time below {rho:g}·V(t_on): median [10 %, 90 %] over the members", fontsize=9)
    return Figure(to_data_uri(fig), "settling matrix: median settling time per scenario and design",
                  "Each cell: median settling time (s) over the ensemble's initial errors, its "
                  "10–90 % band in brackets (∞: those members never settle within the window); "
                  "hatched red: some members never settle (share given); white: the median "
                  "member never settles.")


def _finish_v_axes(fig, ax, ylabel: str, title: str) -> None:
    """Labels, grid, legend and title of a one-panel V(t) figure."""
    ax.set_xlabel("t (s)")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="upper right")
    ax.set_title(title, fontsize=10)


def ensemble_band_figure(band: pd.DataFrame, title: str) -> Figure | None:
    """V/V(t_0) of an ensemble per design: the median (line) and the 10–90 % band (shaded)
    over the stored members (:func:`reports.ensemble_view.path_band`)."""
    if band.empty:
        return None
    fig, ax = plt.subplots(figsize=(8.6, 3.2))
    for design, g in band.groupby("design", sort=False):
        lk = look(design)
        t = g["t"].to_numpy(dtype=float)
        ax.semilogy(t, _positive(g["median"]), color=lk.color, ls=lk.linestyle, lw=1.2,
                    label=f"{lk.label}: median")
        ax.fill_between(t, _positive(g["q10"]), _positive(g["q90"]), color=lk.color, alpha=0.18)
    _finish_v_axes(fig, ax, "V / V(t₀)", title)
    return Figure(to_data_uri(fig), f"{title}: ensemble band of V",
                  "Line: median over the stored members of V divided by its first sample; "
                  "shaded: 10–90 % of the members.")


def artifact_figure(curves: dict, title: str) -> Figure | None:
    """V of one design under each integrator variant ("time-stepping", "projected master",
    "event-driven"): ``curves[variant] = (t, V)``; the discrete artifact and its remedy side by side."""
    curves = {k: v for k, v in curves.items() if v is not None and len(v[0])}
    if not curves:
        return None
    styles = {"time-stepping": ("tab:red", "-"), "projected master": ("tab:blue", "--"),
              "event-driven": ("black", ":")}
    fig, ax = plt.subplots(figsize=(8.6, 3.0))
    for variant, (t, v) in curves.items():
        color, ls = styles.get(variant, ("0.4", "-"))
        ax.semilogy(t, _positive(v), color=color, ls=ls, lw=1.0, label=variant)
    _finish_v_axes(fig, ax, "V (J)", title)
    return Figure(to_data_uri(fig), f"{title}: V under time-stepping, projected master and event-driven",
                  "The same observer design and system under the three masters: a rise of V "
                  "under plain time-stepping that the projected master and the event-driven "
                  "integrator do not show is a discretisation artifact.")


def forest_figure(forest: pd.DataFrame) -> Figure | None:
    """The paired rate ratio jump / nojump with its 95 % interval, one line per ensemble
    (:func:`reports.forest.forest_rows`; log axis, 1 = no difference; the exact event-driven
    master's rows filled, the time-stepped master's open)."""
    if forest.empty:
        return None
    f = forest.iloc[::-1]
    y = np.arange(len(f))
    fig, ax = plt.subplots(figsize=(9.0, 0.9 + 0.2 * len(f)))
    exact = (f["integrator"] == "event").to_numpy()
    est, lo, hi = (f[c].to_numpy(dtype=float) for c in ("estimate", "low", "high"))
    grid = (f["grid_decided"].to_numpy() > 0) if "grid_decided" in f else np.zeros(len(f), bool)
    ax.hlines(y, lo, hi, color=np.where(grid, "0.7", "0.25"), lw=1.4)
    ax.plot(est[exact], y[exact], "o", color="black", ms=5, label="exact event-driven master")
    ax.plot(est[~exact & ~grid], y[~exact & ~grid], "o", mfc="white", mec="black", ms=5,
            label="time-stepped master")
    if grid.any():
        ax.plot(est[grid], y[grid], "x", color="0.5", ms=5, label="undecided (floor-decided fit)")
    ax.axvline(1.0, color="0.5", ls="--", lw=0.8)
    ax.set_xscale("log")
    ax.set_yticks(y, [f"{lab} · {'event' if e else 'time-stepping'}" for lab, e in zip(f["label"], exact)],
                  fontsize=7)
    ax.set_xlabel("rate ratio jump / no jump (> 1: jump's V decays faster), 95 % CI", fontsize=8)
    ax.tick_params(axis="x", labelsize=7)
    ax.grid(alpha=0.3, axis="x", which="both")
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout(pad=0.3)
    return Figure(to_data_uri(fig, fit=False), "forest plot of the paired rate ratio jump / no jump per ensemble",
                  "Paired decay-rate ratio (mean rate of jump / mean rate of no jump over the same members) "
                  "with its 95 % cluster bootstrap interval (observer.stats.rate_ratio); dashed: no difference.")
