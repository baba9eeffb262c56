"""Tables of the report: every cell is a formatted string, never NaN.

Rules (the report promises "no NaN cells"):

* a finite number gets 3 significant digits (scientific notation outside [1e-3, 1e4));
* ``inf`` in a time-to-threshold column reads "not reached" (:func:`fmt_time`), elsewhere "∞";
* a missing or not-applicable value reads "n/a" or "n/a (reason)" — the caller gives the
  reason when there is one.

Every table has a one-line title (rendered before it, so two reports diff cleanly).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Iterable


@dataclass
class Table:
    """A titled table of preformatted cells."""

    title: str
    columns: list[str]
    rows: list[list[str]] = field(default_factory=list)
    note: str = ""
    classes: list[list[str]] = field(default_factory=list)
    """Per cell CSS class ("" for none), only when some row was added with ``classes``."""
    titles: list[list[str]] = field(default_factory=list)
    """Per cell hover text (``title`` attribute, "" for none), likewise."""

    def add(self, cells: Iterable[Any], classes: Iterable[str] | None = None,
            titles: Iterable[str] | None = None) -> None:
        cells = [c if isinstance(c, str) else fmt(c) for c in cells]
        if len(cells) != len(self.columns):
            raise ValueError(f"table {self.title!r}: {len(cells)} cells for {len(self.columns)} columns")
        for attr, given in (("classes", classes), ("titles", titles)):
            extra = getattr(self, attr)
            if given is not None or extra:
                vals = [""] * len(cells) if given is None else [str(x) for x in given]
                if len(vals) != len(cells):
                    raise ValueError(f"table {self.title!r}: {len(vals)} {attr} for {len(cells)} cells")
                if not extra and self.rows:
                    extra.extend([[""] * len(cells) for _ in self.rows])
                extra.append(vals)
        self.rows.append(cells)


def _isnan(x: Any) -> bool:
    try:
        return x is None or (isinstance(x, float) and math.isnan(x)) or (
            hasattr(x, "dtype") and math.isnan(float(x)))
    except (TypeError, ValueError):
        return False


def fmt(x: Any, digits: int = 3, na: str = "n/a", unit: str = "") -> str:
    """A number for reading: 3 significant digits, ``∞``, or ``na`` for missing values."""
    if x is None or isinstance(x, str):
        return na if x is None or x == "" else x
    if isinstance(x, bool):
        return "yes" if x else "no"
    try:
        v = float(x)
    except (TypeError, ValueError):
        return str(x)
    if math.isnan(v):
        return na
    if math.isinf(v):
        return "∞" if v > 0 else "−∞"
    if v == 0:
        s = "0"
    elif isinstance(x, int) or (float(v).is_integer() and abs(v) < 1e6 and digits >= 3
                                and not isinstance(x, float)):
        s = f"{int(v):d}"
    elif 10 ** (digits - 1) <= abs(v) < 1e4:
        s = f"{v:.0f}"
    elif 1e-3 <= abs(v) < 1e4:
        s = f"{v:.{digits}g}"
    else:
        mant, exp = f"{v:.{digits - 1}e}".split("e")
        s = f"{mant}e{int(exp)}"
    s = s.replace("-", "−")
    return f"{s} {unit}".rstrip() if unit else s


def fmt_int(x: Any, na: str = "n/a") -> str:
    if _isnan(x):
        return na
    return f"{int(round(float(x))):d}"


def fmt_time(x: Any, na: str = "n/a") -> str:
    """A time to reach a threshold: "not reached" for ``inf``."""
    if _isnan(x):
        return na
    v = float(x)
    return "not reached" if math.isinf(v) else fmt(v, unit="s")


def fmt_ratio(x: Any, na: str = "n/a") -> str:
    if _isnan(x):
        return na
    v = float(x)
    if math.isinf(v):
        return "∞"
    return f"{v:.0f}" if abs(v) >= 100 else f"{v:.1f}" if abs(v) >= 10 else f"{v:.2f}"


def fmt_pct(x: Any) -> str:
    return "n/a" if _isnan(x) else f"{100 * float(x):.0f} %"


def fmt_rho(x: Any) -> str:
    """A threshold such as 1e-6 as "1e−6" (plain when it is not a power of ten)."""
    v = float(x)
    if v > 0:
        e = math.log10(v)
        if abs(e - round(e)) < 1e-9:
            return f"1e{int(round(e))}".replace("-", "−")
    return fmt(v)


def ratio_text(x: Any) -> str:
    """A ratio with 2 decimals, "∞", or "n/a"."""
    if _isnan(x):
        return "n/a"
    v = float(x)
    return "∞" if math.isinf(v) else f"{v:.2f}"


def band_cell(median: float, lo: float, hi: float, seeds: int) -> str:
    """"median [lo – hi]" for several seeds, the value alone for one (deterministic) run."""
    if seeds <= 1 or _isnan(lo):
        return fmt(median)
    return f"{fmt(median)} [{fmt(lo)} – {fmt(hi)}]"


def fmt_window(t_on: Any, t_off: Any) -> str:
    """A coupling window "[t_on, t_off]"."""
    return f"[{fmt(t_on)}, {fmt(t_off)}]"


def text(x: Any) -> str:
    """A text cell of a row: '' for a missing value (None or NaN, as a concat of rows of
    different kinds leaves them), else ``str(x)``."""
    return "" if _isnan(x) else str(x)


_NUMBER_WORDS = {"nan": "n/a", "none": "n/a", "inf": "∞", "+inf": "∞", "-inf": "−∞"}


def witness_text(x: Any) -> str:
    """A ``key=value; …`` witness (a proof check's) as a cell: :func:`text`, a value that is no
    number (``nan``, ``None``) read "n/a" and an infinite one "∞", as :func:`fmt` shows them."""
    import re

    return re.sub(r"=\s*([+-]?inf|nan|None)\b(?![\w.])",
                  lambda m: "=" + _NUMBER_WORDS[m.group(1).lower()], text(x), flags=re.IGNORECASE)

