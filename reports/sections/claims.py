"""Claims: the page's answer, on its first screen — at most :data:`MAX_CLAIMS` sentences from
:func:`reports.analysis.ensemble_claims`, each with its number, 95 % confidence interval and n,
a link to its evidence, and, where it names a design whose V rises in discrete time, the
cause and a link to the remedy (:func:`reports.sections.artifacts.caveats`)."""

from __future__ import annotations

import re

import pandas as pd

from reports import registry
from reports.blocks import Block, Section
from reports.context import ReportContext
from reports.sections import artifacts
from reports.tables import fmt, fmt_int

TITLE = "Claims (ensembles of initial errors, 95 % confidence intervals)"
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


def build(ctx: ReportContext) -> Section:
    """The claims section (shown first, before the page's header)."""
    sec = Section("claims", TITLE, lead=True)
    view = ctx.ensemble()
    if view.claims is None or view.claims.empty:
        sec.p(f"No claims: {view.reason}. The evidence sections below show the single runs.")
        return sec
    n = view.members.groupby(["label", "integrator", "design"]).size()
    size = fmt_int(n.min()) if n.min() == n.max() else f"{fmt_int(n.min())}–{fmt_int(n.max())}"
    sec.blocks.append(Block("claims", claim_items(view.claims, artifacts.caveats(view))))
    sec.p(f"Each claim is a statistic over an ensemble of initial errors ({size} members per "
          "scenario, integrator and design, the same members for every design); bootstrap 95 % "
          "confidence intervals. Evidence: the settling matrix, the proof-check matrix and the "
          "paired statistics below.")
    return sec
