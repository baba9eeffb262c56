"""Model error and sensors: the floor of V/V(t_on) when the observers' model differs from the
plant (a relative stiffness error ε, ``[observer.model]``) and when χ comes from a sensor with a
latency d (``[observer.sensor]``), read from the stored results of ``bench/stored``: the K error and
the latency on double_mass, the sensor's jitter and threshold, and the per-parameter curves of
every scenario stored (:data:`PARAMETERS_GLOB`, one set of tables and one figure per file, the
scenario named in each caption).

The stored results are read here as data files (JSON, and the member rows' CSV beside the
latency result): the report imports nothing from ``bench``; the statistics are
:mod:`observer.floor_curves`'s (no simulation), applied to the stored member floors. Per uncertainty and design the section
draws the floor against the size (median over the paired members, band = the members' spread),
states the stored power law ``log10 floor = a + s·log10 size`` with its intervals, the crossover
where one design's floor drops below the other's — on the designs' medians, and on the paired
member ratio with a cluster-bootstrap interval (placed, undecided or none) — the sensitivity
table of the model-error result and, inverting the fitted law, the largest size a user may
leave the uncertainty at for a target floor (not reachable where the target is at or below the
exact model's floor at this step).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from observer import floor_curves
from reports import registry
from reports.blocks import Block, Section
from reports.context import ReportContext
from reports.figures import Figure, fixed_layout, plt, to_data_uri
from reports.tables import Table, fmt, fmt_rho

TITLE = "Model error and sensors"
STORED = Path(__file__).resolve().parents[2] / "bench" / "stored"
"""Folder of the stored results (``bench/stored`` of the repository)."""
MODEL_ERROR = "model_error_floor_double_mass.json"
LATENCY = "latency_floor_double_mass.json"
PARAMETERS = "model_error_parameters_double_mass.json"
"""Per-parameter curves (M, C, K, W) on double_mass, ``python -m bench.model_error_parameters``."""
PARAMETERS_GLOB = "model_error_parameters_*.json"
"""Per-parameter curves of every scenario stored (``--scenario NAME``), read in sorted order."""
SENSITIVITY_SIZE = 1e-2
"""The relative error of the per-scenario sensitivity ranking (the stored size nearest to it)."""
NO_EFFECT = 1e-6
"""A parameter whose median floor is the exact model's to this relative difference has no effect
(a zero matrix scaled, or an invariance: W scaled with a zero gap offset on one contact)."""
SENSOR = "sensor_floor_double_mass.json"
"""Sensor jitter and threshold curves, ``python -m bench.sensor_floor``."""
PANELS_PER_ROW = 3
TARGETS = floor_curves.TARGETS
"""Target floors of V/V(t_on) for "what a user needs to know the model to"."""
CONFIDENCE = 0.95
SLOPE_DIGITS = 4


@dataclass(frozen=True)
class Uncertainty:
    """What one stored result varies: its label, unit and the command that regenerates it."""

    key: str
    label: str
    unit: str
    command: str


K_ERROR = Uncertainty("K", "relative K error ε (observers' K̂ = (1 + ε)K)", "", "python -m bench.model_error")
SENSOR_LATENCY = Uncertainty("latency", "sensor latency d", "s", "python -m bench.latency_floor")


@dataclass(frozen=True)
class Curve:
    """One design's floor against one uncertainty's size, as stored.

    Attributes
    ----------
    sizes : ndarray
        The sizes > 0 measured, ascending.
    floors : ndarray
        Member floors, shape (len(sizes), members); member i is the same initial error at
        every size (paired).
    exact : ndarray
        The member floors at size 0 (the floor of the grid and window alone).
    slope, intercept : float
        The stored fit ``log10 floor = intercept + slope·log10 size`` of the median floor.
    slope_members : (float, float)
        The stored 95 % interval of the slope from resampling the members.
    fit_sizes : ndarray
        The sizes the stored fit used.
    """

    what: Uncertainty
    design: str
    sizes: np.ndarray
    floors: np.ndarray
    exact: np.ndarray
    slope: float
    intercept: float
    slope_members: tuple
    fit_sizes: np.ndarray

    @property
    def median(self) -> np.ndarray:
        return np.median(self.floors, axis=1)


def model_error_curves(path: Path) -> tuple[list[Curve], dict]:
    """The K-error curves of the stored model-error result, and the raw JSON."""
    data = json.loads(Path(path).read_text(encoding="utf-8"))
    eps = np.asarray(data["epsilons"], dtype=float)
    curves = [Curve(K_ERROR, d, eps, np.asarray(r["member_floors"], dtype=float),
                    np.asarray(r["exact_member_floors"], dtype=float), float(r["slope"]),
                    float(r["intercept"]), tuple(map(float, r["slope_interval_95"])), eps)
              for d, r in data["designs"].items()]
    return curves, data


def latency_curves(path: Path) -> tuple[list[Curve], dict]:
    """The latency curves of the stored latency result (fits from the JSON, member floors from
    the CSV of member rows beside it), and the raw JSON."""
    import pandas as pd

    data = json.loads(Path(path).read_text(encoding="utf-8"))
    rows = pd.read_csv(Path(path).with_suffix(".csv"))
    curves = []
    for fit in data["fits"]:
        if fit.get("status") != "ok":
            continue
        d = fit["design"]
        table = rows[rows["design"] == d].pivot(index="latency", columns="member", values="floor").sort_index()
        sizes = table.index.to_numpy(dtype=float)
        F = table.to_numpy(dtype=float)
        curves.append(Curve(SENSOR_LATENCY, d, sizes[sizes > 0], F[sizes > 0], F[sizes == 0].ravel(),
                            float(fit["slope"]), float(fit["intercept"]),
                            tuple(map(float, fit["interval"]["members"])), np.asarray(fit["latencies"], float)))
    return curves, data


def stored_curves(path: Path) -> tuple[list[Curve], dict]:
    """The curves of a stored result in the format of :mod:`observer.floor_curves` (a list
    ``curves``, each with its sizes and per design the member floors and the fit; a design not
    fitted has ``slope`` NaN and no fitted sizes), and the raw JSON."""
    data = json.loads(Path(path).read_text(encoding="utf-8"))
    out = []
    for rec in data["curves"]:
        what = Uncertainty(rec["key"], rec["label"], rec["unit"], data["command"])
        sizes = np.asarray(rec["sizes"], dtype=float)
        for d, r in rec["designs"].items():
            fit = r["fit"]
            ok = fit["status"] == "ok"
            out.append(Curve(what, d, sizes, np.asarray(r["member_floors"], dtype=float),
                             np.asarray(r["exact_member_floors"], dtype=float),
                             float(fit["slope"]) if ok else float("nan"),
                             float(fit["intercept"]) if ok else float("nan"),
                             tuple(map(float, fit["interval"]["members"])) if ok else (float("nan"),) * 2,
                             np.asarray(fit["sizes"] if ok else [], dtype=float)))
    return out, data


def crossings(a: Curve, b: Curve) -> list[tuple[float, float, float, str]]:
    """Every sign change of log10(a's median floor / b's) between consecutive stored sizes:
    (lower size, upper size, log-log interpolated size, design with the lower floor above)."""
    d = np.log10(a.median) - np.log10(b.median)
    out = []
    for i in np.flatnonzero(d[:-1] * d[1:] < 0):
        w = d[i] / (d[i] - d[i + 1])
        at = 10.0 ** (np.log10(a.sizes[i]) + w * np.log10(a.sizes[i + 1] / a.sizes[i]))
        out.append((float(a.sizes[i]), float(a.sizes[i + 1]), float(at), a.design if d[i + 1] < 0 else b.design))
    return out


def crossing_cell(a: Curve, b: Curve) -> str:
    """The crossings of :func:`crossings` as one cell, or which design is lower at every size."""
    u = a.what.unit
    found = crossings(a, b)
    if not found:
        lower = a.design if np.median(np.log10(a.median) - np.log10(b.median)) < 0 else b.design
        return f"no crossing on the stored sizes ({registry.label(lower)} lower throughout)"
    return "; ".join(f"between {_value(lo, u)} and {_value(hi, u)} (at {_value(at, u)}; "
                     f"{registry.label(low)} lower above)" for lo, hi, at, low in found)


def curves_table(curves: list[Curve], data: dict) -> Table:
    """One stored result's fitted laws per (uncertainty, design) and each uncertainty's crossover."""
    pct = f"{100 * CONFIDENCE:.0f} %"
    t = Table(f"{data['what']} ({data['scenario']}; {data['command']}): fitted laws log10(floor) = a + "
              f"s·log10(size), {pct} intervals, and crossovers",
              ["uncertainty", "observer", "slope s [members]", "slope s [regression]", "a", "fitted sizes",
               "floor at size 0 (median)", "crossover of the designs"])
    cross = {a.what: crossing_cell(a, b) for a, b in pairs(curves)}
    for c in curves:
        if c.fit_sizes.size:
            fit = [slope_cell(c.slope, c.slope_members), slope_cell(c.slope, regression_interval(c)),
                   fmt(c.intercept), f"{_value(c.fit_sizes.min(), c.what.unit)} … "
                   f"{_value(c.fit_sizes.max(), c.what.unit)} ({c.fit_sizes.size} points)"]
        else:
            fit = ["not fitted (fewer than 3 sizes between 10 × the floor at size 0 and 0.1)", "–", "–", "–"]
        t.add([c.what.label, registry.label(c.design), *fit, fmt(float(np.median(c.exact))),
               cross.get(c.what, "–")])
    t.note = (f"{data['members'] if 'members' in data else data['settings']['members']} paired members "
              f"(seed {data.get('seed', data.get('settings', {}).get('seed'))}); floor = {data['floor']}; "
              f"status {data['status']}. Fitted sizes: the median floor at least 10 × the one at size 0 "
              "and below 0.1 (the stored fit's range). Crossover: a sign change of the designs' median "
              "floor ratio between consecutive stored sizes, log-log interpolated.")
    return t


def fit_rows(c: Curve, F: np.ndarray | None = None) -> np.ndarray:
    """Rows of ``F`` (default the curve's member floors) at the fitted sizes."""
    F = c.floors if F is None else F
    return F[np.isin(c.sizes, c.fit_sizes)]


def regression_interval(c: Curve) -> tuple[float, float]:
    """The slope's 95 % interval from the fitted points' scatter about the line (slope ± t·standard
    error, k − 2 degrees of freedom): how well one power law describes the median curve."""
    from scipy import stats

    x = np.log10(c.fit_sizes)
    reg = stats.linregress(x, np.log10(np.median(fit_rows(c), axis=1)))
    half = float(stats.t.ppf(0.5 + CONFIDENCE / 2, x.size - 2) * reg.stderr)
    return float(reg.slope) - half, float(reg.slope) + half


def crossover(a: Curve, b: Curve) -> dict:
    """Where ``a``'s median floor crosses ``b``'s on the stored sizes: the bracketing sizes and
    the log-log interpolated crossing of the first sign change, or none (then the range of the
    ratio a/b over the sizes)."""
    d = np.log10(a.median) - np.log10(b.median)
    ratio = 10.0 ** d
    found = crossings(a, b)
    if found:
        lo, hi, at, lower = found[0]
        return {"between": (lo, hi), "at": at, "lower_after": lower}
    return {"between": None, "lower": a.design if d[0] < 0 else b.design,
            "ratio": (float(ratio.min()), float(ratio.max()))}


def _value(x: float, unit: str) -> str:
    return fmt(x, unit=unit)


def crossover_text(a: Curve, b: Curve) -> str:
    """One sentence: where a's floor overtakes b's, or that it never does on the stored sizes (and
    whether the fitted lines are parallel within the slopes' member intervals)."""
    cr, u, la, lb = crossover(a, b), a.what.unit, registry.label(a.design), registry.label(b.design)
    span = f"{_value(a.sizes[0], u)} … {_value(a.sizes[-1], u)}"
    if cr["between"] is not None:
        lo, hi = cr["between"]
        return (f"{a.what.label}: the floors cross between {_value(lo, u)} and {_value(hi, u)} "
                f"(log-log interpolation: {_value(cr['at'], u)}); above it "
                f"{registry.label(cr['lower_after'])} has the lower floor.")
    lower, other = (la, lb) if cr["lower"] == a.design else (lb, la)
    r_lo, r_hi = cr["ratio"]
    ia, ib = a.slope_members, b.slope_members
    overlap = ia[0] <= ib[1] and ib[0] <= ia[1]
    if overlap:
        slopes = "the fitted slopes' member intervals overlap: parallel lines, no crossover predicted"
    else:
        at = 10.0 ** ((b.intercept - a.intercept) / (a.slope - b.slope))
        slopes = (f"the fitted slopes differ, but the lines would cross only at {_value(at, u)}, an "
                  f"extrapolation far outside {span}" if not a.sizes[0] <= at <= a.sizes[-1] else
                  f"the fitted lines cross at {_value(at, u)}")
    zero = (la if np.median(a.exact) < np.median(b.exact) else lb)
    return (f"{a.what.label}: no crossover on {span}: {lower} has the lower median floor at every "
            f"stored size (floor {la} / {lb} from {fmt(r_lo)} to {fmt(r_hi)}; at size 0 {zero} has the "
            f"lower one); {slopes}.")


def slope_cell(value: float, interval: tuple) -> str:
    return (f"{fmt(value, digits=SLOPE_DIGITS)} [{fmt(interval[0], digits=SLOPE_DIGITS)} – "
            f"{fmt(interval[1], digits=SLOPE_DIGITS)}]")


def laws_table(curves: list[Curve]) -> Table:
    """The fitted power laws, one row per (uncertainty, design)."""
    pct = f"{100 * CONFIDENCE:.0f} %"
    t = Table(f"Fitted floor laws log10(floor) = a + s·log10(size) (median over members; {pct} intervals)",
              ["uncertainty", "observer", "slope s [members]", "slope s [regression]", "a",
               "fitted sizes", "floor at size 0 (median)"])
    for c in curves:
        t.add([c.what.label, registry.label(c.design), slope_cell(c.slope, c.slope_members),
               slope_cell(c.slope, regression_interval(c)), fmt(c.intercept),
               f"{_value(c.fit_sizes.min(), c.what.unit)} … {_value(c.fit_sizes.max(), c.what.unit)} "
               f"({c.fit_sizes.size} points)", fmt(float(np.median(c.exact)))])
    t.note = ("members: the stored percentile interval of the slope refitted on resampled members "
              "(paired across sizes; narrow, since with one master the floor hardly depends on the "
              "initial error); regression: slope ± t·standard error from the fitted points' scatter "
              "about the line (computed here from the stored medians). V is quadratic in the state "
              "error, so a slope s for V is a slope s/2 for the error norm.")
    return t


def tolerance_cell(t: dict, unit: str) -> str:
    """One target's cell: the largest size with its interval, or why there is none."""
    u = f" {unit}" if unit else ""
    if t["status"] == "not reachable":
        return f"not reachable at this h (floor {fmt(t['exact_floor'])} without error)"
    if t["status"] == "whole range":
        return f"any size up to {fmt(t['at_least'])}{u} (floor at or below the target at every size)"
    if t["status"] == "not fitted":
        return "no fitted law"
    lo, hi = (fmt(v) if v is not None else "not reached" for v in t["interval"])
    return f"≤ {fmt(t['size'])} [{lo} – {hi}]{u}" + (" (extrapolated)" if t["status"] == "extrapolated" else "")


def tolerance_table(curves: list[Curve], title: str) -> Table:
    """Per (uncertainty, design) and target floor: the largest size at which the fitted law
    keeps the floor at or below the target (:mod:`observer.floor_curves`: ``tolerances``, the
    members resampled)."""
    pct = f"{100 * CONFIDENCE:.0f} %"
    t = Table(f"{title}: the largest size with a floor of V/V(t_on) at or below each target (fitted law, "
              f"{pct} interval)", ["uncertainty", "observer", "floor at size 0 (median)", "fitted sizes",
                                   *[f"floor ≤ {fmt_rho(x)}" for x in TARGETS]])
    for c in curves:
        found = floor_curves.tolerances(c.sizes, c.floors, c.exact, TARGETS, fit_sizes=c.fit_sizes,
                                        confidence=CONFIDENCE)
        span = (f"{_value(c.fit_sizes.min(), c.what.unit)} … {_value(c.fit_sizes.max(), c.what.unit)}"
                if c.fit_sizes.size else "– (not fitted)")
        t.add([c.what.label, registry.label(c.design), fmt(float(np.median(c.exact))), span,
               *[tolerance_cell(x, c.what.unit) for x in found]])
    t.note = ("Size = 10^((log10 target − a)/s) on the stored fitted law; the interval refits the law on "
              "resampled members (paired across sizes: the spread over initial errors of one master and "
              "one plant, not over other plants). Extrapolated: outside the fitted sizes. Not reachable: "
              "the target is at or below the floor with the exact model or ideal sensor (the grid's and "
              "the window's floor at this step), so no accuracy of the model reaches it.")
    return t


def paired_crossovers(curves: list[Curve]) -> dict:
    """Per declared design pair of each uncertainty, the paired crossover with its interval
    (:mod:`observer.floor_curves`: ``crossover_intervals``, the members resampled): a dict keyed by
    (uncertainty, baseline design, candidate design)."""
    return {(a.what, a.design, b.design): floor_curves.crossover_intervals(
        a.sizes, a.floors, b.floors, a.design, b.design, confidence=CONFIDENCE) for a, b in pairs(curves)}


def paired_cell(res: dict, unit: str) -> str:
    """The paired crossover as one cell: placed (size and interval), undecided or none."""
    span = f"[{_value(res['range'][0], unit)}, {_value(res['range'][1], unit)}]"
    if res["status"] == "none":
        return f"no crossover in {span} ({registry.label(res['lower_throughout'])} lower throughout)"
    if res["status"] == "undecided":
        return (f"undecided: {registry.label(res['lower_throughout'])} lower at every size on the paired "
                f"medians, but resamples change sign in {span}")
    parts = []
    for c in res["crossovers"]:
        low, (lo, hi) = registry.label(c["lower_above"]), c["between"]
        if c["status"] == "placed":
            parts.append(f"at {_value(c['at'], unit)} [{_value(c['interval'][0], unit)} – "
                         f"{_value(c['interval'][1], unit)}] (between the sizes {_value(lo, unit)} and "
                         f"{_value(hi, unit)}, {low} lower above)")
        else:
            end = "lower" if c["interval"][0] is None else "upper"
            parts.append(f"undecided between {_value(lo, unit)} and {_value(hi, unit)} (the interval reaches "
                         f"the {end} end of {_value(c['window'][0], unit)} … {_value(c['window'][1], unit)}, "
                         f"{low} lower above)")
    return "; ".join(parts)


def crossover_table(found: dict, title: str) -> Table:
    """The paired crossovers of :func:`paired_crossovers`, one row per uncertainty and pair."""
    pct = f"{100 * CONFIDENCE:.0f} %"
    t = Table(f"{title}: where one design overtakes the other, paired members ({pct} interval)",
              ["uncertainty", "designs", "crossover [interval]", "resampled"])
    for (what, a, b), res in found.items():
        t.add([what.label, f"{registry.label(a)} vs {registry.label(b)}", paired_cell(res, what.unit),
               f"{res['resamples']} resamples of the {res.get('unit', 'members')} (each member its own "
               "cluster: one master, one plant)"])
    t.note = ("Per size the median over members of log10(floor a / floor b) (member i: the same initial "
              "error, master and plant in both designs), its zero interpolated in log size; the interval "
              "resamples the members, the same at every size and in both designs. Undecided: the interval "
              "reaches an end of the swept range (or of the span between neighbouring crossovers), or the "
              "paired medians keep their sign but resamples do not: the data cannot place it, so no number "
              f"is given. No crossover: fewer than {100 * (1 - CONFIDENCE) / 2:g} % of the resamples change sign. "
              "The interval is the "
              "spread over the members (initial errors) only: it does not include the error of interpolating "
              "between the two swept sizes that bracket the crossover, nor other masters or plants.")
    return t


def sensitivity_table(data: dict) -> Table | None:
    """The model-error result's sensitivity table: the median floor per design with one
    parameter of the observers' model off by the stated relative ε, the others exact."""
    sens = data.get("sensitivity")
    if not sens:
        return None
    designs = registry.in_registry_order(next(iter(sens["floor_median"].values())))
    exact = {d: float(data["designs"][d]["exact_floor_median"]) for d in designs if d in data["designs"]}
    t = Table(f"Sensitivity: median floor with one parameter off by {fmt(sens['eps'])} (relative), "
              f"{data.get('scenario', '')}",
              ["parameter", *[f"{registry.label(d)} floor (× exact)" for d in designs]])
    for name, row in sens["floor_median"].items():
        t.add([name, *[f"{fmt(row[d])} (× {fmt(row[d] / exact[d])})" if d in exact else fmt(row[d])
                       for d in designs]])
    return t


def sensitivity_items(data: dict) -> list[str]:
    """Per design: the parameter whose error costs most and the one that costs least."""
    sens = data.get("sensitivity")
    if not sens:
        return []
    table = sens["floor_median"]
    designs = registry.in_registry_order(next(iter(table.values())))
    out = []
    for d in designs:
        ranked = sorted(table, key=lambda p: table[p][d], reverse=True)
        out.append(f"{registry.label(d)}: an error of {fmt(sens['eps'])} costs most in {ranked[0]} "
                   f"(floor {fmt(table[ranked[0]][d])}), least in {ranked[-1]} "
                   f"(floor {fmt(table[ranked[-1]][d])}); order: {', '.join(ranked)}.")
    return out


def draws_text(data: dict) -> str:
    """One sentence on the stored uncertainty ensemble (observer models drawn around the plant)."""
    u = data.get("uncertainty")
    if not u:
        return ""
    parts = [f"{registry.label(d)} {fmt(m)} [{fmt(u['floor_range_95'][d][0])} – {fmt(u['floor_range_95'][d][1])}]"
             for d, m in u["floor_median_over_draws"].items()]
    smooth = [d for d in u["floor_median_over_draws"] if d not in registry.jump_designs()]
    share = (f"; {registry.label(smooth[0])} has the lower floor in {100 * u['nojump_lower_fraction']:.0f} % "
             f"of the draws" if "nojump_lower_fraction" in u and len(smooth) == 1 else "")
    return (f"Observer models drawn around the plant ({u['model']}; {u['draws']} draws, the plant "
            f"fixed, the same members for every draw and design): median floor over the draws, "
            f"[2.5–97.5 % of the draws]: " + ", ".join(parts) + share + ".")


def pairs(curves: list[Curve]) -> list[tuple[Curve, Curve]]:
    """Per uncertainty, the declared (baseline, candidate) design pairs both curves exist for."""
    out = []
    for what in dict.fromkeys(c.what for c in curves):
        by = {c.design: c for c in curves if c.what == what}
        out += [(by[a], by[b]) for a, b in registry.ratio_pairs() if a in by and b in by]
    return out


def draw_crossovers(ax, found: dict, what: Uncertainty) -> None:
    """The placed paired crossovers of ``what`` (vertical line at the size, its interval shaded)
    and the brackets of the undecided ones (hatched)."""
    for (w, _, _), res in found.items():
        for c in res["crossovers"] if w == what else []:
            if c["status"] == "placed":
                ax.axvspan(*c["interval"], color="0.4", alpha=0.25, lw=0)
                ax.axvline(c["at"], color="0.2", ls="-.", lw=0.9)
            else:
                ax.axvspan(*c["between"], facecolor="none", edgecolor="0.5", hatch="//", lw=0)


def floor_figure(curves: list[Curve], found: dict | None = None, scenario: str | None = None) -> Figure | None:
    """One panel per uncertainty: per design the median floor (markers), the members' spread
    (band), the stored fitted line over its sizes (dashed), the floor at size 0 (dotted) and
    the paired crossovers of ``found`` (:func:`paired_crossovers`; :func:`draw_crossovers`);
    the title names ``scenario`` if given."""
    whats = list(dict.fromkeys(c.what for c in curves))
    if not whats:
        return None
    cols = min(len(whats), PANELS_PER_ROW)
    rows = -(-len(whats) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5.2 * cols, 3.8 * rows), squeeze=False)
    for ax in axes.ravel()[len(whats):]:
        ax.set_visible(False)
    for ax, what in zip(axes.ravel(), whats):
        for c in (c for c in curves if c.what == what):
            lk = registry.look(c.design)
            ax.fill_between(c.sizes, c.floors.min(axis=1), c.floors.max(axis=1), color=lk.color, alpha=0.2)
            fitted = c.fit_sizes.size > 0
            ax.loglog(c.sizes, c.median, "o", color=lk.color, ms=4,
                      label=f"{lk.label} (s = {fmt(c.slope, digits=SLOPE_DIGITS)})" if fitted else
                      f"{lk.label} (not fitted)")
            if fitted:
                x = np.geomspace(c.fit_sizes.min(), c.fit_sizes.max(), 20)
                ax.loglog(x, 10.0 ** (c.intercept + c.slope * np.log10(x)), color=lk.color, ls="--", lw=1.0)
            ax.axhline(float(np.median(c.exact)), color=lk.color, ls=":", lw=0.8)
        draw_crossovers(ax, found or {}, what)
        ax.set_xlabel(what.label + (f" ({what.unit})" if what.unit else ""), fontsize=8)
        ax.set_ylabel("floor of V / V(t_on)")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7, loc="upper left")
    fixed_layout(fig, top=0.2, wspace=0.9, hspace=0.8)
    title = "floor of V/V(t_on) against " + ", ".join(w.key for w in whats) + (f" ({scenario})" if scenario else "")
    return Figure(to_data_uri(fig, fit=False), title,
                  "Markers: median floor over the paired members; shaded: the members' spread (min–max); "
                  "dashed: the stored fitted power law over its sizes; dotted: the floor at size 0 "
                  "(exact model, ideal sensor: the floor of the grid and the window); dash-dotted "
                  "vertical line and grey band: a crossover of the paired designs placed with its "
                  f"{100 * CONFIDENCE:.0f} % interval; hatched: the bracket of an undecided one.")


def intro(me: dict | None, lat: dict | None) -> str:
    """Where the numbers come from."""
    parts = []
    if me is not None:
        parts.append(f"{me['scenario']}, observers carrying {me['model']} for ε in "
                     f"{fmt(min(me['epsilons']))} … {fmt(max(me['epsilons']))}: {me['members']} paired "
                     f"members (seed {me['seed']}); floor = {me['floor']}; status {me['status']} "
                     f"({K_ERROR.command}, {MODEL_ERROR})")
    if lat is not None:
        s = lat["settings"]
        parts.append(f"{s['scenario']}, χ from a sensor with latency d (h = {fmt(s['h'])} s, T = "
                     f"{fmt(s['t_end'])} s): {s['members']} paired members (seed {s['seed']}); floor = median "
                     f"of V/V(t_on) over the last {fmt(100 * s['tail'])} % of the window; status "
                     f"{lat['status']} ({SENSOR_LATENCY.command}, {LATENCY} and its CSV)")
    return ("The master is the true plant; each observer design advances the nominal model or reads "
            "χ from the sensor. Stored results (bench/stored): " + "; ".join(parts) + ".")


def curve_files(stored: Path) -> list[Path]:
    """The stored curve files shown after the K-error and latency results: every
    :data:`PARAMETERS_GLOB` of ``stored`` (sorted), then :data:`SENSOR`."""
    return sorted(Path(stored).glob(PARAMETERS_GLOB)) + [Path(stored) / SENSOR]


def caption(data: dict) -> str:
    """A stored curve file's name in captions: its scenario and the command that regenerates it."""
    return f"{data['scenario']}, {data['command']}"


PARAMETER_WHAT = "floor of V/V(t_on) against a relative error of one parameter"
"""How a per-parameter result's ``what`` begins (the files of :data:`PARAMETERS_GLOB`)."""


def sensitivity_index(c: Curve) -> int:
    """The index of the stored size nearest to :data:`SENSITIVITY_SIZE` (in log size)."""
    return int(np.argmin(np.abs(np.log10(c.sizes) - np.log10(SENSITIVITY_SIZE))))


def parameter_sensitivity_table(curves: list[Curve], data: dict) -> Table:
    """Per parameter (one curve each) and design: the median floor at the size nearest to
    :data:`SENSITIVITY_SIZE`, its ratio to the exact model's, and the fitted slope."""
    designs = registry.in_registry_order(list(dict.fromkeys(c.design for c in curves)))
    by = {(c.what.key, c.design): c for c in curves}
    keys = list(dict.fromkeys(c.what.key for c in curves))
    at = curves[0].sizes[sensitivity_index(curves[0])]
    t = Table(f"Sensitivity per parameter, {caption(data)}: median floor with one parameter off by "
              f"{fmt(at)} (relative), the others exact",
              ["parameter", *[f"{registry.label(d)} floor (× exact; slope s)" for d in designs]])
    for k in keys:
        cells = []
        for d in designs:
            c = by[k, d]
            f, e = float(c.median[sensitivity_index(c)]), float(np.median(c.exact))
            s = fmt(c.slope, digits=SLOPE_DIGITS) if c.fit_sizes.size else "not fitted"
            cells.append(f"{fmt(f)} (× {fmt(f / e)}; s = {s})")
        t.add([k, *cells])
    t.note = (f"{data['members']} paired members; the floor at the stored size nearest to "
              f"{fmt(SENSITIVITY_SIZE)}; × exact: over the median floor with the exact model (the grid's "
              "and window's floor). A parameter whose error leaves the floor at the exact one is not "
              "fitted.")
    return t


def parameter_sensitivity_items(curves: list[Curve], data: dict) -> list[str]:
    """Per design, the parameters of a per-parameter result ranked by their floor at the size
    nearest to :data:`SENSITIVITY_SIZE` (largest first); those within :data:`NO_EFFECT` of the
    exact model's floor are named apart, unranked."""
    out = []
    for d in registry.in_registry_order(list(dict.fromkeys(c.design for c in curves))):
        mine = [c for c in curves if c.design == d]
        exact = float(np.median(mine[0].exact))
        floor = {c.what.key: float(c.median[sensitivity_index(c)]) for c in mine}
        none = [k for k in floor if abs(floor[k] / exact - 1.0) <= NO_EFFECT]
        ranked = sorted((k for k in floor if k not in none), key=floor.get, reverse=True)
        at = fmt(mine[0].sizes[sensitivity_index(mine[0])])
        tail = (f"; no effect (floor the exact model's to {fmt(NO_EFFECT)} relative): {', '.join(none)}."
                if none else ".")
        head = (f"an error of {at} costs most in {ranked[0]} (floor {fmt(floor[ranked[0]])}), least in "
                f"{ranked[-1]} (floor {fmt(floor[ranked[-1]])}); order: {', '.join(ranked)}" if ranked
                else f"no parameter's error of {at} changes the floor")
        out.append(f"{data['scenario']}, {registry.label(d)}: {head}{tail}")
    return out


def load(stored: Path) -> tuple[list[Curve], dict | None, dict | None]:
    """The curves of the stored results present in ``stored`` and their raw JSON (None if absent)."""
    curves, me, lat = [], None, None
    if (stored / MODEL_ERROR).exists():
        c, me = model_error_curves(stored / MODEL_ERROR)
        curves += c
    if (stored / LATENCY).exists() and (stored / LATENCY).with_suffix(".csv").exists():
        c, lat = latency_curves(stored / LATENCY)
        curves += c
    return curves, me, lat


def build_from(stored: Path, key_numbers: list | None = None) -> Section:
    """The section from the stored results in ``stored``; adds one key-number line."""
    sec = Section("model-error", TITLE)
    curves, me, lat = load(Path(stored))
    if not curves:
        sec.p(f"No stored model-error or sensor result in {stored} (run {K_ERROR.command} and "
              f"{SENSOR_LATENCY.command}).")
        return sec
    sec.p(intro(me, lat))
    found = paired_crossovers(curves)
    sec.figure(floor_figure(curves, found), "No curves.")
    sec.table(laws_table(curves))
    cross = [crossover_text(a, b) for a, b in pairs(curves)]
    sec.blocks.append(Block("list", cross))
    sec.table(crossover_table(found, "Crossovers with intervals"))
    if me is not None:
        table = sensitivity_table(me)
        if table is not None:
            sec.table(table)
            sec.items(sensitivity_items(me))
        if draws_text(me):
            sec.p(draws_text(me))
    sec.table(tolerance_table(curves, "What the model and the sensor must be known to"))
    for path in curve_files(Path(stored)):
        if path.exists():
            more, data = stored_curves(path)
            found = paired_crossovers(more)
            sec.figure(floor_figure(more, found, data.get("scenario")), "No curves.")
            sec.table(curves_table(more, data))
            sec.table(crossover_table(found, f"Crossovers with intervals, {caption(data)}"))
            if data["what"].startswith(PARAMETER_WHAT):
                sec.table(parameter_sensitivity_table(more, data))
                sec.items(parameter_sensitivity_items(more, data))
            sec.table(tolerance_table(more, f"Known to for a target floor, {caption(data)}"))
    if key_numbers is not None:
        scen = ", ".join(dict.fromkeys(x["scenario"] if "scenario" in x else x["settings"]["scenario"]
                                       for x in (me, lat) if x is not None))
        key_numbers.append(f"Model error and sensors ({scen}, stored results): fitted floor slopes "
                           + "; ".join(f"{registry.label(c.design)} against {c.what.key}: "
                                       f"{slope_cell(c.slope, c.slope_members)}" for c in curves)
                           + ". " + " ".join(cross))
    return sec


def build(ctx: ReportContext) -> Section:
    """The section from the repository's stored results (:data:`STORED`)."""
    return build_from(STORED, ctx.key_numbers)
