"""Evidence of the claims: the settling matrix (scenario × design: median settling time with its
10–90 % band, failures marked), the proof-check matrix (scenario × check, coloured, the
reason on hover), the ensemble's V(t) band per scenario, and the long tables (paired settling
statistics, settling matrix) collapsed, each with its CSV written beside the page."""

from __future__ import annotations

import pandas as pd

from reports import figures, registry
from reports.blocks import Section, slug
from reports.context import ReportContext
from reports.ensemble_view import load_paths, path_band, settling_matrix
from reports.sections.artifacts import rise_table
from reports.sections.proof_checks import EVIDENCE_TEXT, matrix_table
from reports.tables import Table, fmt, fmt_int, fmt_pct, fmt_rho, fmt_time, text

TITLE = "Evidence: ensembles, settling matrix and proof-check matrix"
ID = "ensemble"
MATRIX_ID = "settling-matrix"
CHECKS_ID = "check-matrix"
PAIRED_ID = "paired-statistics"
K_METRIC_ID = "k-metric"


def matrix_csv_table(mat: pd.DataFrame) -> Table:
    """The settling matrix as a table (the figure's numbers)."""
    t = Table("Settling matrix: median and 10–90 % of the settling time per scenario, integrator "
              "and design", ["scenario", "integrator", "design", "ρ", "n", "median", "10 %", "90 %",
                             "never settles"])
    for _, r in mat.iterrows():
        t.add([r["label"], r["integrator"], registry.label(r["design"]), fmt_rho(r["rho"]),
               fmt_int(r["n"]), fmt_time(r["median"]), fmt_time(r["q10"]), fmt_time(r["q90"]),
               fmt_pct(r["never"])])
    return t


def paired_table(paired: pd.DataFrame) -> Table:
    """One row per (scenario, integrator, pair, ρ) of :func:`reports.analysis.paired_settling`."""
    t = Table("Paired settling statistics: ratio t_candidate / t_baseline per member",
              ["scenario", "integrator", "baseline / candidate", "ρ", "n", "median ratio [10–90 %]",
               "95 % CI of the median", "candidate first", "never: baseline / candidate",
               "Wilcoxon p"],
              note="ratio < 1: the candidate settles sooner. Bootstrap CI (scipy.stats.bootstrap), "
                   "paired by member; Wilcoxon signed-rank on the log-times where both settle.")
    for _, r in paired.iterrows():
        p = fmt(r["wilcoxon_p"], na=f"n/a ({text(r.get('reason')) or 'undefined'})")
        t.add([text(r.get("label")) or text(r.get("scenario")), text(r.get("integrator")),
               f"{registry.label(r['baseline'])} / {registry.label(r['candidate'])}",
               fmt_rho(r["rho"]), fmt_int(r["n"]),
               f"{fmt(r['ratio_median'])} [{fmt(r['ratio_q10'])}–{fmt(r['ratio_q90'])}]",
               f"{fmt(r['ci_low'])}–{fmt(r['ci_high'])}", fmt_pct(r["frac_candidate_first"]),
               f"{fmt_pct(r['never_baseline'])} / {fmt_pct(r['never_candidate'])}", p])
    return t


def write_csv(ctx: ReportContext, frame: pd.DataFrame, name: str) -> str:
    """Write ``frame`` as ``name`` beside the page; the relative link."""
    frame.to_csv(ctx.out_dir / name, index=False)
    return name


def band_subsections(paths: pd.DataFrame) -> list[Section]:
    """Per scenario with stored paths: the ensemble's V(t) band (10–90 %) and median per
    integrator."""
    subs = []
    for label, p in paths.groupby("label", sort=False):
        sub = Section(f"ens-{slug(str(label))}", str(label))
        for integ, gp in p.groupby("integrator", sort=False):
            sub.figure(figures.ensemble_band_figure(path_band(gp), f"{label} · {integ}"),
                       f"{integ}: no V(t) to draw.")
        subs.append(sub)
    return subs


def _bands(sec: Section, members: pd.DataFrame) -> None:
    paths = load_paths(members)
    if paths.empty:
        sec.p("No V(t) paths are stored with these ensembles (settling statistics only); the "
              "single runs' V(t) are in the scenario section.")
        return
    sec.subsections += band_subsections(paths)


def _checks_block(ctx: ReportContext, sec: Section) -> None:
    ch = ctx.rows("checks")
    sec.anchor(CHECKS_ID)
    if ch.empty:
        sec.p("No proof-check results in these results (see the proof-check section).")
        return
    sec.p(EVIDENCE_TEXT)
    sec.table(matrix_table(ch))


def build(ctx: ReportContext) -> Section:
    """The evidence section (anchors: settling matrix, check matrix, paired statistics, and one
    subsection per scenario)."""
    sec = Section(ID, TITLE)
    view = ctx.ensemble()
    members = view.members
    sec.anchor(MATRIX_ID)
    if members.empty:
        sec.p(f"No ensemble results: {view.reason}.")
    else:
        mat = settling_matrix(members)
        sec.figure(figures.settling_matrix_figure(mat), "No settling times in the ensemble rows.")
        sec.details("Settling matrix as a table", matrix_csv_table(mat),
                    write_csv(ctx, mat, "settling_matrix.csv"))
    _checks_block(ctx, sec)
    sec.anchor(PAIRED_ID)
    if len(view.paired):
        sec.details(f"Paired statistics: {len(view.paired)} rows (scenario × integrator × pair × ρ)",
                    paired_table(view.paired), write_csv(ctx, view.paired, "paired_settling.csv"))
    sec.anchor(K_METRIC_ID)
    if len(view.rises):
        sec.details(f"Rises of V per scenario, integrator and design ({len(view.rises)} rows; the "
                    "K-metric question)", rise_table(view.rises),
                    write_csv(ctx, view.rises, "rise_distribution.csv"))
    if not members.empty:
        _bands(sec, members)
    return sec
