"""Peers: Siconos against the toolkit on the same problems (the rows of ``bench.peers``):
per-step times, their ratios and the largest trajectory difference; without Siconos, whether
it was available when the suite ran and how to get it, as the suite's metadata records it
(the report reads results only: it does not probe this machine)."""

from __future__ import annotations

import pandas as pd

from reports import analysis
from reports.blocks import Section
from reports.context import ReportContext
from reports.tables import Table, fmt, fmt_int, fmt_ratio, text

TITLE = "Peers: Siconos on the same problems"

INTRO = ("Siconos {version} and the toolkit run the same discrete scheme (Moreau–Jean θ = ½, "
         "Newton's law, one Siconos Interaction per contact, LCP by Lemke), so their trajectories "
         "agree to round-off. Siconos runs under Debian's system Python in a subprocess; its time "
         "is the stepping loop alone (a Python loop of computeOneStep/nextStep that writes fExt "
         "every step when the problem is forced). 'Siconos run()' is Siconos' own C++ loop with "
         "the force held at its constant part — no Python per step, a different trajectory when "
         "the problem is forced, timing only. The toolkit runs on its compiled engine: 'simulate' "
         "is the whole observer.simulate() call (setup and result included), 'loop' its time loop "
         "alone. Medians of {repeats} repeats on each side; ratio = Siconos ÷ toolkit (> 1: the "
         "toolkit is faster).")


UNKNOWN = ("These results do not record whether the suite found Siconos when it ran (they "
           "were written before bench recorded it in the suite's metadata)")
"""What the page says when no suite's metadata records Siconos (:func:`siconos_recorded`)."""


def siconos_recorded(ctx: ReportContext) -> dict | None:
    """The Siconos record bench wrote in the suite's metadata when the suite ran
    (``bench.peers.siconos_record``: ``available``, ``version``, ``reason``, ``how_to_get``),
    None where no suite's metadata has a readable one (older results): the page then says it
    does not know, rather than probe this machine."""
    rec = ctx.declared("siconos")
    if not isinstance(rec, dict) or not isinstance(rec.get("available"), bool):
        return None
    key = "version" if rec["available"] else "reason"
    return rec if isinstance(rec.get(key), str) and isinstance(rec.get("how_to_get"), str) else None


def siconos_sentence(rec: dict | None) -> str:
    """Whether Siconos was available when the suite ran (its version, or why not and how to
    get it), or :data:`UNKNOWN`."""
    if rec is None:
        return UNKNOWN
    if rec["available"]:
        return f"Siconos was available when the suite ran ({rec['version']})"
    return f"Siconos was not available when the suite ran: {rec['reason']}"


def _without_results(ctx: ReportContext, sec: Section, notes: list[str]) -> Section:
    rec = siconos_recorded(ctx)
    if notes:
        if rec is None:
            why = f"the peer cases were skipped when the suite ran (each says why below). {UNKNOWN}"
        elif rec["available"]:
            why = f"the peer cases were skipped although Siconos was found ({rec['version']}); each says why below"
        else:
            why = f"Siconos was not available when the suite ran. To get it: {rec['how_to_get']}"
        sec.p(f"No peer results: {why}; then run the suite again (finished cases are skipped).")
        sec.items(notes)
        ctx.key_numbers.append("Peers: no Siconos results — the peer cases were skipped (the Peers "
                               "section says why and how to get Siconos).")
        return sec
    sec.p("No peer results: these suites have no peer cases. The comparison with Siconos is the "
          "suite `python -m bench run peers` (also part of `nox -s report -- full`). "
          + siconos_sentence(rec) + ".")
    return sec


def peers_table(pe: pd.DataFrame, summ: pd.DataFrame) -> Table:
    """Rows of :func:`reports.analysis.peer_summary` with the rows' notes."""
    t = Table("Siconos vs toolkit: time per step and largest trajectory difference",
              ["problem", "n", "m", "h (s)", "steps", "Siconos (µs/step)", "Siconos run() (µs/step)",
               "toolkit simulate (µs/step)", "toolkit loop (µs/step)", "ratio (simulate)",
               "ratio (loop)", "ratio run() / simulate", "max |Δq|", "max |Δu|", "note"])
    for (_, r), (_, sm) in zip(pe.iterrows(), summ.iterrows()):
        t.add([str(r["problem"]), fmt_int(r["n"]), fmt_int(r["m"]), fmt(r["h"]), fmt_int(r["steps"]),
               fmt(sm["siconos_us"]), fmt(sm["siconos_run_us"]), fmt(sm["toolkit_us"]),
               fmt(sm["toolkit_loop_us"]), f"{fmt_ratio(sm['ratio'])}×", f"{fmt_ratio(sm['ratio_loop'])}×",
               f"{fmt_ratio(sm['ratio_run'])}×", fmt(r["max_abs_diff_q"]), fmt(r["max_abs_diff_u"]),
               text(r.get("note")) or "—"])
    return t


def build(ctx: ReportContext) -> Section:
    """The peers section; adds the time ratios and the worst difference to the key numbers."""
    sec = Section("peers", TITLE)
    pe = ctx.rows("peers", ok_only=True)
    notes = ctx.unavailable_notes("peers:")
    if pe.empty:
        return _without_results(ctx, sec, notes)
    summ = analysis.peer_summary(pe)
    sec.p(INTRO.format(version=pe["siconos_version"].iloc[0], repeats=fmt_int(pe["repeats"].max())))
    sec.table(peers_table(pe, summ))
    if notes:
        sec.p("Some peer cases were skipped in the last run:")
        sec.items(notes)
    worst = float(summ["max_diff"].max())
    ctx.key_numbers.append("Peers (Siconos ÷ toolkit time per step, whole simulate call / loop alone): "
                           + ", ".join(f"{r['problem']} {fmt_ratio(r['ratio'])}× / "
                                       f"{fmt_ratio(r['ratio_loop'])}×" for _, r in summ.iterrows())
                           + f"; trajectories differ by at most {fmt(worst)}.")
    return sec
