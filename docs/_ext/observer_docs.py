"""Sphinx directives generated from the code, so that the pages cannot drift from it.

* ``.. toml-reference::`` — the scenario file's fields, from :data:`observer.scenario.SCHEMA`,
  :data:`observer.scenario.REQUIRED` and :data:`observer.scenario.FIELDS` (a leaf without
  documentation, or documentation without a leaf, is a build error);
* ``.. cli-reference:: MODULE`` — every subcommand of a command-line parser
  (``MODULE.build_parser()``), with its help and options.

The developer API's pages and the resolution of cross-references are ``observer_api.py``.
"""

from __future__ import annotations

import argparse
import importlib

from docutils import nodes
from docutils.parsers.rst import Directive
from sphinx.errors import ExtensionError


def _table(header: list[str], rows: list[list[str]], widths: list[int]) -> nodes.table:
    table = nodes.table()
    group = nodes.tgroup(cols=len(header))
    table += group
    for w in widths:
        group += nodes.colspec(colwidth=w)
    head = nodes.thead()
    group += head
    body = nodes.tbody()
    group += body
    for target, cells in ((head, [header]), (body, rows)):
        for cells_row in cells:
            row = nodes.row()
            for i, text in enumerate(cells_row):
                entry = nodes.entry()
                para = nodes.paragraph()
                para += nodes.literal(text=text) if i == 0 else nodes.Text(text)
                entry += para
                row += entry
            target += row
    return table


def toml_reference_rows() -> list[tuple[str, str, str, str, str, str]]:
    """(table, field, type, unit, default, meaning) of every leaf of the scenario schema."""
    from observer.scenario import FIELDS, REQUIRED, schema_fields
    leaves = schema_fields()
    missing = [k for k in leaves if k not in FIELDS]
    extra = [k for k in FIELDS if k not in leaves]
    if missing or extra:
        raise ExtensionError(f"observer.scenario.FIELDS out of step with SCHEMA: undocumented "
                             f"{missing}, unknown {extra}")
    rows = []
    for key in leaves:
        kind, unit, default, meaning = FIELDS[key]
        if (key in REQUIRED) != (default == "required"):
            raise ExtensionError(f"observer.scenario.FIELDS[{key!r}]: 'required' must match REQUIRED")
        table, _, name = key.rpartition(".")
        table = f"[[{table[:-2]}]]" if table.endswith("[]") else f"[{table}]"
        rows.append((table, name, kind, unit or "—", default, meaning))
    return rows


class TomlReference(Directive):
    """The scenario file's fields as one table per TOML table."""

    def run(self):
        out = []
        current, rows = None, []
        for table, name, kind, unit, default, meaning in toml_reference_rows() + [(None,) * 6]:
            if table != current and rows:
                section = nodes.rubric(text=current)
                out += [section, _table(["field", "type", "unit", "default", "meaning"], rows,
                                        [14, 18, 10, 14, 34])]
                rows = []
            current = table
            if table is not None:
                rows.append([name, kind, unit, default, meaning])
        return out


def cli_subcommands(module: str) -> dict[str, argparse.ArgumentParser]:
    """Subcommand name -> parser of ``module.build_parser()``."""
    parser = importlib.import_module(module).build_parser()
    subs: dict[str, argparse.ArgumentParser] = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            subs.update(action.choices)
    return subs


class CliReference(Directive):
    """Every subcommand of a command-line parser, with its usage and options."""

    required_arguments = 1

    def run(self):
        module = self.arguments[0]
        parser = importlib.import_module(module).build_parser()
        subs = cli_subcommands(module)
        out = []
        if not subs:
            out.append(nodes.literal_block(text=parser.format_help()))
            return out
        helps = {}
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                helps = {a.dest: a.help for a in action._choices_actions}
        for name, sub in subs.items():
            section = nodes.section(ids=[nodes.make_id(f"{module}-{name}")])
            section += nodes.title(text=f"{parser.prog} {name}")
            section += nodes.paragraph(text=helps.get(name) or "")
            section += nodes.literal_block(text=sub.format_help())
            out.append(section)
        return out


def setup(app):
    app.add_directive("toml-reference", TomlReference)
    app.add_directive("cli-reference", CliReference)
    return {"version": "1", "parallel_read_safe": True}
