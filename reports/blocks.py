"""The pieces a report section is made of: :class:`Block` (paragraph, list, table, figure,
details, preformatted text, claims, anchor) and :class:`Section` (a titled list of blocks and
subsections; a ``lead`` section is shown before the page's header, on its first screen)."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

from reports.figures import Figure
from reports.tables import Table


@dataclass
class Block:
    """One piece of a section: ``kind`` in {"p", "list", "table", "figure", "details",
    "details-list", "pre", "claims", "anchor"}; ``href``: a file beside the page (the CSV of a
    collapsible table)."""

    kind: str
    content: Any
    summary: str = ""
    href: str = ""


@dataclass
class Section:
    """A section of the page: ``id`` (the anchor), ``title``, blocks and subsections."""

    id: str
    title: str
    blocks: list = field(default_factory=list)
    subsections: list = field(default_factory=list)
    lead: bool = False

    def p(self, text: str) -> None:
        self.blocks.append(Block("p", text))

    def items(self, items: list[str]) -> None:
        self.blocks.append(Block("list", items))

    def table(self, t: Table) -> None:
        self.blocks.append(Block("table", t))

    def figure(self, f: Figure | None, missing: str) -> None:
        if f is None:
            self.p(missing)
        else:
            self.blocks.append(Block("figure", f))

    def details(self, summary: str, t: Table, href: str = "") -> None:
        """A collapsible table (with a link to its CSV ``href`` when given)."""
        self.blocks.append(Block("details", t, summary, href))

    def details_list(self, summary: str, items: list[str]) -> None:
        """A collapsible list."""
        self.blocks.append(Block("details-list", items, summary))

    def anchor(self, html_id: str) -> None:
        """An empty element with ``id`` (a link target inside a section)."""
        self.blocks.append(Block("anchor", html_id))

    def pre(self, text: str) -> None:
        self.blocks.append(Block("pre", text))


def slug(text: str) -> str:
    """An HTML id from a title: lower case, runs of other characters replaced by ``-``."""
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "x"
