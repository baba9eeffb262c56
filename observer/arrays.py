"""Raw user values to finite float arrays, or an :class:`~observer.errors.InputError` naming the field.

The lowest layer of validation: :mod:`observer.validation` and :mod:`observer.sparse` (which
reads the banded and triplet tables) both use it, so neither imports the other for it.
"""

from __future__ import annotations

import datetime
from typing import Any

import numpy as np

from observer.errors import InputError

MAX_DEPTH = 64
"""Deepest nesting of arrays and tables accepted in a scenario document or a value (a matrix
is 2 deep; the reader refuses a deeper document before any recursion can overflow)."""

_NUMERIC_KINDS = "fiu"


def _describe(leaf: Any) -> str | None:
    """Why ``leaf`` is not a number (None: it is one, or a type ``np.array`` refuses itself)."""
    if isinstance(leaf, (bool, np.bool_)):
        return f"a boolean ({str(bool(leaf)).lower()})"
    if isinstance(leaf, (str, bytes)):
        return f"the string {leaf!r}"
    if isinstance(leaf, (complex, np.complexfloating)):
        return f"the complex number {leaf!r}"
    if isinstance(leaf, (np.datetime64, np.timedelta64, datetime.date, datetime.time,
                         datetime.timedelta)):
        return (f"the {type(leaf).__name__} {str(leaf)!r}: a date or a duration is not a number "
                "(give seconds as a float)")
    return None


def non_numeric_entry(field: str, value: Any) -> tuple[tuple[int, ...], str] | None:
    """The index and description of the first entry of ``value`` (a number or nested lists of
    numbers) that is a string, a boolean, a complex number, a date or a duration (NumPy's
    ``datetime64`` / ``timedelta64`` too), or a masked entry of a masked array, or None.

    TOML strings (``"1.0"``) and booleans are not numbers, although NumPy would convert them.
    Walks the nesting without recursion; nesting deeper than :data:`MAX_DEPTH` is an error.
    """
    if np.ma.isMaskedArray(value) and np.ma.is_masked(value):
        i = int(np.flatnonzero(np.ma.getmaskarray(value))[0])
        return (tuple(int(k) for k in np.unravel_index(i, np.shape(value))),
                "masked: a masked entry has no value (fill the array first, e.g. .filled(0.0))")
    if isinstance(value, np.ndarray):
        kind = value.dtype.kind
        if kind in "mM" and value.size:
            return (tuple(0 for _ in value.shape), _describe(value.reshape(-1)[0]))
        if kind in _NUMERIC_KINDS or value.size == 0:
            return None
        items = value.reshape(-1).tolist() if kind in "bUSc" else value.reshape(-1)
        for i, leaf in enumerate(items):
            why = _describe(leaf)
            if why is not None:
                return tuple(int(k) for k in np.unravel_index(i, value.shape)), why
        return None
    stack: list[tuple[tuple[int, ...], Any]] = [((), value)]
    while stack:
        index, node = stack.pop()
        if isinstance(node, (list, tuple)):
            if len(index) >= MAX_DEPTH:
                raise InputError(field, f"nested deeper than {MAX_DEPTH} levels")
            if all(type(x) is float or type(x) is int for x in node):
                continue
            stack.extend((index + (i,), x) for i, x in reversed(list(enumerate(node))))
        else:
            why = _describe(node)
            if why is not None:
                return index, why
    return None


def ragged_row(value: Any) -> str | None:
    """Where nested lists have rows of unequal length (``[[1, 0], [0]]``), said as ``row 1 has
    1 entry, expected 2`` (rows and indices count from 0, as in ``entry (0, 1)``), or None.

    Level by level without recursion (the nesting is already bounded by :data:`MAX_DEPTH`);
    a row that is a number among lists, or a list among numbers, is ragged too."""
    level: list[tuple[tuple[int, ...], Any]] = [((), value)]
    while level:
        lists = [(i, x) for i, x in level if isinstance(x, (list, tuple))]
        if not lists:
            return None
        if len(lists) != len(level):
            index = next(i for i, x in level if not isinstance(x, (list, tuple)))
            return f"{_row_name(index)} is a number where its siblings are rows"
        want = len(lists[0][1])
        for index, x in lists:
            if len(x) != want:
                return (f"{_row_name(index)} has {len(x)} entr{'y' if len(x) == 1 else 'ies'}, "
                        f"expected {want}")
        level = [(i + (k,), y) for i, x in lists for k, y in enumerate(x)]
    return None


def _row_name(index: tuple[int, ...]) -> str:
    return "the array" if not index else f"row {index[0]}" if len(index) == 1 else f"entry {index}"


PATTERN_KEYS = ("pattern", "head", "tail")
"""A periodic vector: ``head``, then ``pattern`` repeated (and cut) to fill, then ``tail``
(``head`` and ``tail`` optional, default empty): a chain of identical blocks stores its
periodic vectors and its matrices' diagonals in O(block size) whatever its length
(:func:`observer.sparse.periodic_form` writes it)."""

VECTOR_KEYS = ("n",) + PATTERN_KEYS
"""A compact vector in a scenario document: ``{n = N, pattern = [...], head = [...],
tail = [...]}``, the periodic form (:data:`PATTERN_KEYS`) with its length ``n``, required
(``{n = 400000, pattern = [0.0]}`` is 400 000 zeros); :func:`as_array` expands it, bit for
bit, wherever a vector is read (initial state, forcing, gaps, observers, restitution)."""


def check_declared_size(field: str, what: str, need: float) -> None:
    """Raise before expanding a compact declaration (a periodic vector, a banded or triplet
    matrix table) whose expansion needs ``need`` bytes (estimated) when fewer are available
    (:func:`observer.memory.available_memory`): a file of a few hundred bytes can declare
    a system of 10⁹ degrees of freedom. The error names ``field`` and what it declares."""
    from observer import memory

    avail = memory.available_memory()
    if avail is not None and need > avail:
        raise InputError(field, f"declares {what}: expanding it needs about {need / 2 ** 30:.3g} GiB "
                         f"(estimated) but {avail / 2 ** 30:.3g} GiB are available")


def periodic_vector(field: str, value: dict, size: int | None, keys: tuple[str, ...] = VECTOR_KEYS) -> np.ndarray:
    """Expand a periodic table (``keys``: :data:`VECTOR_KEYS` for a vector, with its length
    ``n``; :data:`PATTERN_KEYS` for a banded matrix's diagonal, whose length ``size`` the matrix
    gives) into ``head + pattern repeated + tail``; errors name ``field.KEY``."""
    unknown = sorted(set(value) - set(keys))
    if unknown or "pattern" not in value or ("n" in keys and "n" not in value):
        missing = "pattern" if "pattern" not in value else "n"
        raise InputError(f"{field}.{unknown[0] if unknown else missing}",
                         f"a periodic table has the keys {', '.join(keys)} ({'n and ' if 'n' in keys else ''}"
                         "pattern required)")
    if "n" in keys:
        n = value["n"]
        if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or n < 1 or (size is not None and n != size):
            want = f"the length {size}" if size is not None else "a positive integer"
            raise InputError(f"{field}.n", f"must be {want}, got {n!r}")
        size = n
    pat = as_array(f"{field}.pattern", value["pattern"], (None,))
    head = as_array(f"{field}.head", value.get("head", []), (None,))
    tail = as_array(f"{field}.tail", value.get("tail", []), (None,))
    fill = size - head.size - tail.size
    if pat.size == 0 or fill < 0:
        raise InputError(f"{field}.pattern", f"must be non-empty, with head and tail at most {size} values")
    check_declared_size(field, f"{size} values", 16.0 * size)    # the repeated body, then the whole
    body = np.tile(pat, -(-fill // pat.size))[:fill]     # (np.resize concatenates fill/p copies: slow)
    return np.concatenate([head, body, tail])


def as_array(field: str, value: Any, shape: tuple[int | None, ...]) -> np.ndarray:
    """Convert ``value`` to a finite float64 array of the given shape (``None`` = any length).

    Entries must be numbers: strings (``"1.0"``), booleans and complex numbers are refused
    rather than converted. A vector (one-dimensional ``shape``) may also be a compact periodic
    table (:data:`VECTOR_KEYS`, :func:`periodic_vector`).
    """
    if isinstance(value, dict) and len(shape) == 1:
        return periodic_vector(field, value, shape[0])
    bad = non_numeric_entry(field, value)
    if bad is not None:
        index, why = bad
        if index:
            raise InputError(field, f"not a numeric array: entry {index} is {why}")
        raise InputError(field, f"not a numeric array or number: got {why}")
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError, OverflowError) as exc:
        ragged = ragged_row(value)          # walked only once NumPy has refused the value
        if ragged is not None:
            raise InputError(field, f"not a numeric array: {ragged}") from None
        raise InputError(field, f"not a numeric array ({exc})") from None
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        want = "x".join("*" if s is None else str(s) for s in shape) or "scalar"
        got = "x".join(str(a) for a in arr.shape) or "scalar"
        raise InputError(field, f"wrong shape: expected {want}, got {got}")
    if not np.all(np.isfinite(arr)):
        if arr.ndim == 0:
            raise InputError(field, f"is NaN or infinity ({float(arr)!r})")
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise InputError(field, f"contains NaN or infinity (first at index {tuple(int(i) for i in bad)})")
    return arr
