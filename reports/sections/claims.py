"""Claims: the page's answer, on its first screen — one figure (the forest plot of the paired
rate ratio jump / no jump per ensemble, :mod:`reports.forest`) and at most :data:`MAX_CLAIMS`
claims, one per scenario the paper names, each with its estimand, interval and evidence.

The helpers :func:`claim_items` and :func:`claim_text` render the claims of
:func:`reports.analysis.ensemble_claims` (the settling-time and K-metric claims, each with its
number, 95 % CI and n, and, where it names a design whose V rises in discrete time, the cause
and a link to the remedy): :mod:`reports.sections.k_metric_claims` shows them below."""

from __future__ import annotations

import re

import pandas as pd

from reports import figures, registry
from reports import forest as forest_mod
from reports.blocks import Block, Section
from reports.context import ReportContext
from reports.sections import artifacts
from reports.tables import Table, fmt, fmt_int

TITLE = "Is the jump observer faster? Paired decay-rate ratio per scenario (95 % CI)"
FOREST_ID = "forest-numbers"
UNDEFINED = "—"
"""The table's symbol for a ratio that is not defined (legend in the table's note)."""
MAX_CLAIMS = 8
"""At most this many claims on the first screen."""
CI_MARK = "CI"


def named_designs(sentence: str) -> list[str]:
    """Registered designs a claim names by their label (the claims' sentences use labels; a
    label inside a longer word does not count)."""
    return [d for d in registry.designs()
            if re.search(rf"(?<![\w-]){re.escape(registry.label(d))}(?![\w-])", sentence)]


def event_only(sentence: str) -> bool:
    """The claim is about event-driven ensembles only (it names the event integrator and not
    time-stepping): no discrete-time caveat applies."""
    return bool(re.search(r"\bevent\b", sentence)) and not re.search(r"time-?stepping", sentence)


def claim_text(r: pd.Series) -> str:
    """The claim's sentence; its CI and n appended when the sentence does not state them."""
    sentence = str(r["text"]).strip()
    if CI_MARK not in sentence:
        sentence = (sentence.rstrip(".") + f" (95 % CI {fmt(r['ci_low'])}–{fmt(r['ci_high'])}, "
                    f"n = {fmt_int(r['n'])}).")
    return sentence


def claim_items(claims: pd.DataFrame, notes: dict[str, str]) -> list[dict]:
    """Rendered claims: text, evidence anchor, and the discrete-time caveat of the designs it
    names (every claim of kind "artifact" gets the caveats of its designs, or the cause)."""
    items = []
    for _, r in claims.head(MAX_CLAIMS).iterrows():
        sentence = claim_text(r)
        caveat = ("" if event_only(str(r["text"])) else
                  " ".join(notes[d] for d in named_designs(str(r["text"])) if d in notes))
        if not caveat and r.get("kind") == "artifact":
            caveat = f"cause: {artifacts.CAUSE}."
        items.append({"text": sentence, "anchor": str(r["anchor"]), "caveat": caveat,
                      "kind": str(r.get("kind", ""))})
    return items


def forest_table(forest: pd.DataFrame) -> Table:
    """The forest plot's numbers (every cell a number or a defined word: no NaN, ∞ or 0 [0, 0])."""
    t = Table("Paired rate ratio jump / no jump per ensemble (the forest plot's numbers)",
              ["ensemble", "integrator", "rate ratio", "95 % CI", "evidence", "members left out",
               "jump faster in"],
              note="rate ratio: mean decay rate of jump / of no jump over the same members "
                   "(observer.stats.rate_ratio; CI: bootstrap over the masters of an ensemble on several, "
                   "over its members on one, over systems for a family). members left out: a rate not "
                   "finite in a design. "
                   f"{UNDEFINED}: not defined (a design's mean rate is not positive).")
    for _, r in forest.iterrows():
        ok = r["status"] == "ok"
        t.add([r["label"], r["integrator"], fmt(r["estimate"]) if ok else UNDEFINED,
               f"{fmt(r['low'])}–{fmt(r['high'])}" if ok else UNDEFINED, forest_mod.evidence(r),
               fmt_int(r["dropped"]), f"{fmt_int(r['k_clusters'])} of {fmt_int(r['clusters'])}"])
    return t


FOREST_CSV = "forest.csv"
"""The forest plot's rows, written beside the page (the stored result the README quotes is a
copy: ``bench/stored/quick_forest.csv``)."""

def forest_frame(members: pd.DataFrame) -> pd.DataFrame:
    """:func:`reports.forest.forest_rows` and, per integrator, the random family pooled."""
    f = forest_mod.forest_rows(members)
    if f.empty:
        return f
    fam = [forest_mod.family_row(members, "random_system", i) for i in f["integrator"].unique()]
    fam = [r for r in fam if r is not None]
    f = pd.concat([f, pd.DataFrame(fam)], ignore_index=True) if fam else f
    return f[f["status"] == "ok"].reset_index(drop=True) if "status" in f else f


def build(ctx: ReportContext) -> Section:
    """The page's first screen: the forest plot and one claim per scenario the paper names."""
    sec = Section("claims", TITLE, lead=True)
    view = ctx.ensemble()
    if view.members.empty:
        sec.p(f"No claims: {view.reason}. The evidence sections below show the single runs.")
        return sec
    forest = forest_frame(view.members)
    if forest.empty:
        sec.p("No claims: the ensemble rows carry no per-member decay rate of both jump and no jump. "
              "The evidence sections below show the settling statistics.")
        return sec
    sec.figure(figures.forest_figure(forest), "")
    items = [{"text": c["text"], "anchor": FOREST_ID, "caveat": "", "kind": c["verdict"]}
             for c in forest_mod.scenario_claims(view.members, forest)][:MAX_CLAIMS]
    sec.blocks.append(Block("claims", items))
    summary = forest_mod.where_faster(forest)
    if summary:
        sec.p(summary)
    sec.p("Each claim: the paired decay-rate ratio of V (jump / no jump, the same initial errors "
          "against the same master) with its 95 % bootstrap interval and its evidence (members × "
          "masters × systems, and what the interval resamples); faster / slower: the interval lies "
          "above / below 1. The K-metric question is answered in its own section below.")
    sec.anchor(FOREST_ID)
    forest.to_csv(ctx.out_dir / FOREST_CSV, index=False)
    sec.details("The forest plot's numbers", forest_table(forest), FOREST_CSV)
    return sec
