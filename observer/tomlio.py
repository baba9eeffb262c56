"""Reading and writing scenario documents as TOML.

Reading uses the standard library's ``tomllib``. Writing is a small emitter for the
scenario schema (tables of scalars, strings, vectors and matrices) that prints one
matrix row per line and every float with ``repr`` (shortest round-trip form), so that
``show`` output is editable by hand and reads back to bit-identical arrays.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any

from observer.errors import InputError
from observer.validation import MAX_DEPTH


MAX_BYTES = 16 * 1024 * 1024
"""Largest scenario file read (16 MiB: the 200-body chain's document is ≈ 2 MiB, the chain of
10⁵ blocks' 8.6 MiB with its periodic vectors and diagonals compact — its three non-periodic
vectors, ≈ 90 bytes per block, are the rest); a larger file, or an endless one such as
``/dev/zero``, is refused after reading at most this much."""


def read_toml(path: str | Path) -> dict:
    """Parse a TOML scenario file; every failure becomes an :class:`InputError` naming the file.

    At most :data:`MAX_BYTES` are read; the text must be UTF-8 and valid TOML, and its arrays
    and tables nested at most :data:`~observer.validation.MAX_DEPTH` deep.
    """
    path = Path(path)
    try:
        with path.open("rb") as fh:
            data = fh.read(MAX_BYTES + 1)
    except FileNotFoundError:
        raise InputError(str(path), "file not found") from None
    except IsADirectoryError:
        raise InputError(str(path), "is a directory, not a TOML file") from None
    except OSError as exc:
        raise InputError(str(path), f"cannot read ({exc.strerror or exc})") from None
    if len(data) > MAX_BYTES:
        raise InputError(str(path), f"larger than the {MAX_BYTES // 2**20} MiB a scenario file "
                         "may have (is it a scenario?)")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(str(path), f"invalid TOML (not UTF-8 text: {exc.reason})") from None
    return loads(text, str(path))


def loads(text: str, where: str) -> dict:
    """Parse TOML ``text``; errors (syntax, arrays or tables nested deeper than
    :data:`~observer.validation.MAX_DEPTH`) are :class:`InputError` naming ``where``."""
    too_deep = InputError(where, f"invalid TOML (arrays or tables nested deeper than {MAX_DEPTH} "
                                 "levels)")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(where, f"invalid TOML ({exc})") from None
    except RecursionError:          # tomllib recurses once per level: far beyond MAX_DEPTH
        raise too_deep from None
    if nesting_depth(doc) > MAX_DEPTH:
        raise too_deep
    return doc


def nesting_depth(value: Any) -> int:
    """Depth of nested lists, tuples and dicts in ``value`` (a scalar is 0), without recursion."""
    deepest = 0
    stack = [(value, 0)]
    while stack:
        node, depth = stack.pop()
        if isinstance(node, dict):
            node = list(node.values())
        if isinstance(node, (list, tuple)):
            deepest = max(deepest, depth + 1)
            stack.extend((x, depth + 1) for x in node if isinstance(x, (list, tuple, dict)))
    return deepest


STRING_ESCAPES = {**{c: f"\\u{c:04x}" for c in (*range(0x00, 0x09), *range(0x0A, 0x20), *range(0x7F, 0xA0))},
                  ord("\\"): "\\\\", ord('"'): '\\"', ord("\n"): "\\n"}
"""A TOML basic string's escapes: backslash, quote, and every control character but the tab
(TOML refuses them raw; a terminal would act on a BEL or an ESC of a scenario name)."""


def _scalar(x: Any) -> str:
    if isinstance(x, bool):
        return "true" if x else "false"
    if isinstance(x, int):
        return str(x)
    if isinstance(x, float):
        if not math.isfinite(x):
            raise ValueError(f"cannot write non-finite float {x!r} to TOML")
        return repr(x)
    if isinstance(x, str):
        return '"' + x.translate(STRING_ESCAPES) + '"'
    raise TypeError(f"cannot write {type(x).__name__} to TOML")


def _value(x: Any, indent: str = "") -> str:
    if isinstance(x, (list, tuple)):
        if x and isinstance(x[0], (list, tuple)):
            rows = ",\n".join(indent + "  " + _value(r) for r in x)
            return "[\n" + rows + ",\n" + indent + "]"
        return "[" + ", ".join(_scalar(v) for v in x) + "]"
    return _scalar(x)


def dumps(doc: dict, comments: dict[str, str] | None = None) -> str:
    """Serialise a nested dict (tables, arrays of tables under key ``harmonics``) to TOML.

    ``comments`` maps a dotted table name to a comment printed above the table.
    """
    comments = comments or {}
    out: list[str] = []

    def table(prefix: str, d: dict, array_item: bool = False) -> None:
        scalars = {k: v for k, v in d.items() if not isinstance(v, dict) and not _is_table_array(v)}
        if prefix:
            if prefix in comments:
                out.append("")
                out.extend("# " + line for line in comments[prefix].splitlines())
            elif out:
                out.append("")
            out.append(f"[[{prefix}]]" if array_item else f"[{prefix}]")
        for k, v in scalars.items():
            out.append(f"{k} = {_value(v)}")
        for k, v in d.items():
            name = f"{prefix}.{k}" if prefix else k
            if isinstance(v, dict):
                table(name, v)
            elif _is_table_array(v):
                for item in v:
                    table(name, item, array_item=True)

    table("", doc)
    return "\n".join(out).lstrip("\n") + "\n"


def _is_table_array(v: Any) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(i, dict) for i in v)
