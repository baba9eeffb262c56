"""The K-metric question and the settling-time claims (below the first screen): at most
:data:`reports.sections.claims.MAX_CLAIMS` sentences of :func:`reports.analysis.ensemble_claims`,
each with its number, 95 % CI and n, a link to its evidence and, where it names a design whose V
rises in discrete time, the cause and a link to the remedy."""

from __future__ import annotations

from reports.blocks import Block, Section
from reports.context import ReportContext
from reports.sections import artifacts
from reports.sections.claims import claim_items
from reports.tables import fmt_int

TITLE = "The K-metric question and settling times (ensembles, 95 % confidence intervals)"
ID = "k-metric-question"


def build(ctx: ReportContext) -> Section:
    sec = Section(ID, TITLE)
    view = ctx.ensemble()
    if view.claims is None or view.claims.empty:
        sec.p(f"No claims: {view.reason}.")
        return sec
    n = view.members.groupby(["label", "integrator", "design"]).size()
    size = fmt_int(n.min()) if n.min() == n.max() else f"{fmt_int(n.min())}–{fmt_int(n.max())}"
    sec.blocks.append(Block("claims", claim_items(view.claims, artifacts.caveats(view))))
    sec.p(f"Each claim is a statistic over an ensemble of initial errors ({size} members per "
          "scenario, integrator and design, the same members for every design); bootstrap 95 % "
          "confidence intervals. Evidence: the settling matrix, the proof-check matrix and the "
          "paired statistics below.")
    return sec
