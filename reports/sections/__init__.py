"""The report's sections, one module each, in page order.

A section module defines ``TITLE`` and ``build(ctx: ReportContext) -> Section``; it may append
lines to ``ctx.key_numbers``. Adding a section = one module here + one entry in
:data:`SECTIONS`. Entries with ``after_others=True`` are built once every other section has
run (the key-number summary shows what they added) but keep their place on the page.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from reports.blocks import Section
from reports.context import ReportContext
from reports.sections import (artifacts, claims, ensemble, hard_cases, integrators, k_metric_claims,
                              key_numbers, limitations, micro, model_error, more_numbers, observers, peers,
                              proof_checks, reproduce, robustness, scaling, scenarios, settings, work_precision)


@dataclass(frozen=True)
class SectionSpec:
    """One registry entry: the section's id and builder, and whether it is built last."""

    id: str
    build: Callable[[ReportContext], Section]
    after_others: bool = False


SECTIONS: tuple[SectionSpec, ...] = (
    SectionSpec("claims", claims.build),
    SectionSpec("key-numbers", key_numbers.build, after_others=True),
    SectionSpec("k-metric-question", k_metric_claims.build),
    SectionSpec("ensemble", ensemble.build),
    SectionSpec("discrete-artifacts", artifacts.build),
    SectionSpec("scenarios", scenarios.build),
    SectionSpec("all-key-numbers", more_numbers.build, after_others=True),
    SectionSpec("observers", observers.build),
    SectionSpec("work-precision", work_precision.build),
    SectionSpec("integrators", integrators.build),
    SectionSpec("robustness", robustness.build),
    SectionSpec("model-error", model_error.build),
    SectionSpec("hard-cases", hard_cases.build),
    SectionSpec("scaling", scaling.build),
    SectionSpec("peers", peers.build),
    SectionSpec("micro", micro.build),
    SectionSpec("proof-checks", proof_checks.build),
    SectionSpec("settings", settings.build),
    SectionSpec("limitations", limitations.build),
    SectionSpec("reproduce", reproduce.build),
)
"""Ordered registry of the page's sections."""


def build_sections(ctx: ReportContext, specs: tuple[SectionSpec, ...] = SECTIONS) -> list[Section]:
    """Build every section of ``specs`` (page order), the ``after_others`` ones last; the
    key-number lines each section adds are recorded in ``ctx.key_groups`` (when ``ctx`` has it)."""
    built: dict[int, Section] = {}
    groups = getattr(ctx, "key_groups", None)
    for late in (False, True):
        for i, spec in enumerate(specs):
            if spec.after_others == late:
                before = len(ctx.key_numbers) if groups is not None else 0
                built[i] = spec.build(ctx)
                if groups is not None and not late:
                    groups.append((spec.id, list(ctx.key_numbers[before:])))
    return [built[i] for i in range(len(specs))]
