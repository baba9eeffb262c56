"""Robustness: the observers under imperfect switching signals (delayed, jittered, missed and
false closings), median and quantile band over seeds."""

from __future__ import annotations

import pandas as pd

from reports import analysis, figures, registry
from reports.analysis import ROBUST_FLOOR, ROBUST_RHOS
from reports.blocks import Block, Section
from reports.context import ReportContext
from reports.sections.settings import MISSING
from reports.tables import Table, band_cell, fmt, fmt_int, fmt_rho, fmt_time

TITLE = "Robustness: observers under imperfect switching signals"


def _perturbations(meta: dict) -> tuple[list[str], dict[str, str], dict[str, str]]:
    """``(kinds, labels, units)`` of the perturbations as the suite's metadata sidecar records
    them (``"perturbations"``, written by bench from :mod:`bench.perturb`)."""
    return list(meta["kinds"]), dict(meta["labels"]), dict(meta["units"])


def intro(rob: pd.DataFrame, bands: pd.DataFrame, quantiles: tuple[float, float], kinds: list[str],
          labels: dict[str, str]) -> str:
    """Setting of the robustness runs, from the rows, the suite's band ``quantiles`` and its
    perturbation ``kinds`` and ``labels``."""
    lo, hi = (f"{100 * q:.0f}" for q in quantiles)
    rnd = bands[bands["seeds"] > 1]
    seeds = int(rnd["seeds"].max()) if len(rnd) else 1
    random_kinds = ", ".join(dict.fromkeys(rnd["perturbation"])) or "none"
    single = ", ".join(k for k in dict.fromkeys(bands["perturbation"])
                       if k != "none" and k not in set(rnd["perturbation"])) or "none"
    r0 = rob.iloc[0]
    seeds_text = (f"Perturbations run with several seeds ({random_kinds}) have {seeds} seeds per point "
                  f"(numpy.random.default_rng(seed)); each cell gives the median over the seeds and, "
                  f"in brackets, the {lo}–{hi} % band (numpy's linear quantiles). One run per size: "
                  f"{single}." if len(rnd) else
                  f"Every point here is one run (one seed); with several seeds a cell gives the "
                  f"median and the {lo}–{hi} % band.")
    return (f"Scenario {', '.join(dict.fromkeys(rob['name'].astype(str)))} (h = {fmt(r0['h'])} s, "
            f"T = {fmt(r0['t_end'])} s, coupled over the whole run). The observers read χ from the "
            f"master's closing log (source = \"log\") after one perturbation, each one setting of "
            f"the contact sensor model ([observer.sensor], observer.sensor): "
            + "; ".join(f"{k}: {labels[k]}" for k in kinds) + ". " + seeds_text)


def bands_table(bands: pd.DataFrame, quantiles: tuple[float, float], units: dict[str, str]) -> Table:
    """:func:`reports.analysis.robustness_bands` (over the band ``quantiles``) as a table, sizes
    in the perturbations' ``units``."""
    lo, hi = (f"{100 * q:.0f}" for q in quantiles)
    t = Table(f"Robustness: floor and rate of V against the perturbation (median [{lo}–{hi} %] "
              f"over seeds)",
              ["perturbation", "size", "seeds", "observer", "floor / V(t_on)", "rate (1/s)"]
              + [f"settles below {fmt_rho(rho)} (median; seeds settled)" for rho in ROBUST_RHOS]
              + ["log intervals (true)"])
    for _, b in bands.iterrows():
        kind, n = b["perturbation"], int(b["seeds"])
        settle = [f"{fmt_time(b[analysis.rho_col('settle', rho, '_median')])}; "
                  f"{int(b[analysis.rho_col('settled', rho)])}/{n}"
                  for rho in ROBUST_RHOS]
        t.add(["none (exact χ)" if kind == "none" else kind,
               "0" if kind == "none" else fmt(b["size"], unit=units.get(kind, "")), str(n),
               registry.label(b["observer"]),
               band_cell(b["floor_median"], b["floor_lo"], b["floor_hi"], n),
               band_cell(b["rate_median"], b["rate_lo"], b["rate_hi"], n), *settle,
               f"{fmt_int(b['log_intervals'])} ({fmt_int(b['true_intervals'])})"])
    return t


def summary_items(bands: pd.DataFrame, units: dict[str, str]) -> list[str]:
    """One line per observer (:func:`reports.analysis.robustness_summary`), sizes in ``units``."""
    summ = analysis.robustness_summary(bands)
    items = []
    for name, g in summ.groupby("observer", sort=False):
        parts = [f"{r['perturbation']}: " + (
            f"median floor above {fmt_rho(ROBUST_FLOOR)} from "
            f"{fmt(r['breaks_from'], unit=units.get(r['perturbation'], ''))}"
            if pd.notna(r["breaks_from"]) else f"median floor below {fmt_rho(ROBUST_FLOOR)} for every size")
            for _, r in g.iterrows()]
        r0 = g.iloc[0]
        items.append(f"Observer {registry.label(name)} (exact χ: floor {fmt(r0['base_floor'])}·V(t_on), "
                     f"rate {fmt(r0['base_rate'])}/s): " + "; ".join(parts) + ".")
    return items


def build(ctx: ReportContext) -> Section:
    """The robustness section; adds one key-number line."""
    sec = Section("robustness", TITLE)
    rob = ctx.rows_or_say(sec, "robustness", "robustness runs")
    if rob is None:
        return sec
    quantiles, perturbations = ctx.declared("band"), ctx.declared("perturbations")
    if quantiles is None or perturbations is None:
        sec.p(f"The robustness bands are not shown: {MISSING}.")
        return sec
    kinds, labels, units = _perturbations(perturbations)
    bands = analysis.robustness_bands(rob, tuple(quantiles))
    sec.p(intro(rob, bands, tuple(quantiles), kinds, labels))
    sec.figure(figures.robustness_figure(rob, list(kinds), labels, units, bands), "No robustness data.")
    sec.table(bands_table(bands, tuple(quantiles), units))
    items = summary_items(bands, units)
    sec.blocks.append(Block("list", items))
    if items:
        rnd = bands[bands["seeds"] > 1]
        seeds = int(rnd["seeds"].max()) if len(rnd) else 1
        ctx.key_numbers.append(f"Robustness ({seeds} seeds per random perturbation, medians): "
                               + " ".join(items))
    return sec
