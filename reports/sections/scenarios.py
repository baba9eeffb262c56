"""Scenarios: per scenario the paper's figure (a gap, a coordinate and log V of every observer
that ran), the settings of the run and its observer table (the declared pairs' headlines are
in the observer section's ratio table, not repeated per scenario)."""

from __future__ import annotations

import pandas as pd

from reports import figures, registry
from reports.blocks import Section, slug
from reports.context import ReportContext, load_trajectory
from reports.sections.observers import observer_table
from reports.tables import fmt, fmt_window, text

TITLE = "Scenarios: trajectories and Lyapunov function (the paper's figures)"


def _settings_text(r0: pd.Series, ok: bool) -> str:
    params = f", {text(r0.get('params'))}" if text(r0.get("params")) else ""
    window = fmt_window(r0.get("t_on"), r0.get("t_off")) if ok else "n/a"
    return (f"Settings: h = {fmt(r0['h'])} s, T = {fmt(r0['t_end'])} s, coupling window {window} s, "
            f"law {r0['law']}, solver {r0['solver']}{params}.")


def _sentence(text: str) -> str:
    """``text`` with a capital first letter and a final full stop ('' stays '')."""
    text = text.strip()
    if not text:
        return ""
    return text[:1].upper() + text[1:] + ("" if text.endswith(".") else ".")


def _intro(scen: str, r0: pd.Series, ok: bool) -> str:
    desc = registry.scenario_description(scen)
    notes = registry.scenario_notes(scen)
    parts = [_sentence(desc), _sentence(notes), _settings_text(r0, ok)]
    return " ".join(p for p in parts if p)


def _figure(name: str, scen: str, ok: pd.DataFrame, r0: pd.Series):
    if ok.empty:
        return None
    traj = load_trajectory(r0)
    if traj is None:
        return None
    dof, con = (0 if pd.isna(r0.get(c)) else int(r0.get(c)) for c in ("plot_dof", "plot_contact"))
    coord, gap = registry.plot_labels(scen, dof, con)
    window = (float(r0["t_on"]), float(r0["t_off"]))
    observers = registry.in_registry_order(ok["observer"])
    return figures.scenario_figure(traj, str(name), observers, window, coord, gap)


def scenario_subsection(name: str, g: pd.DataFrame) -> Section:
    """One scenario's subsection (figure, settings, observer table)."""
    scen = g["scenario"].iloc[0]
    sub = Section(f"scn-{slug(str(name))}", str(name))
    ok = g[g["status"] == "ok"]
    r0 = ok.iloc[0] if len(ok) else g.iloc[0]
    sub.p(_intro(scen, r0, len(ok) > 0))
    sub.figure(_figure(name, scen, ok, r0), "No trajectory file for this scenario (rerun the suite).")
    sub.table(observer_table(g, f"Synchronization of the observers on {name}"))
    return sub


def build(ctx: ReportContext) -> Section:
    """The scenario section: one subsection per scenario name in the observer rows."""
    sec = Section("scenarios", TITLE)
    obs = ctx.rows_or_say(sec, "observers", "observer runs")
    if obs is None:
        return sec
    designs = registry.in_registry_order(obs["observer"])
    sec.p("Each run couples the observers to the master through the master's own closed set χ "
          "(same grid) inside the shaded window. "
          + "; ".join(f"{registry.label(d)}: {registry.look(d).description}"
                      for d in (registry.MASTER, *designs)) + ".")
    for name, g in obs.groupby("name", sort=False):
        sec.subsections.append(scenario_subsection(name, g))
    return sec
