"""What every report section reads: the result rows, the micro-benchmarks and the run's
settings, loaded once (:func:`load_context`), plus the key-number lines sections add.

:func:`load_rows` is the only place the report reads benchmark storage, through
:mod:`observer.results_io` (the reading side :mod:`bench.results` writes for).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import pandas as pd

from observer.results_io import CASES_SUFFIX, load_results, read_suite_meta
from reports import registry


def load_rows(files: list[Path]) -> pd.DataFrame:
    """The tidy result rows of ``files`` (one DataFrame, a ``results_dir`` column per row), in
    a fixed order (:func:`order_rows`). The only place the report reads benchmark storage."""
    return order_rows(plain_strings(load_results(files)))


def plain_strings(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` with its text columns as NumPy object arrays instead of pandas' Arrow-backed
    ``str`` dtype: the page selects rows of this wide frame hundreds of times, and each
    selection of an Arrow column is a separate ``take`` (measured: a third of the page's
    table-building time); values and missing entries (NaN) are unchanged."""
    text = [c for c, t in df.dtypes.items() if isinstance(t, pd.StringDtype)]
    return df.astype({c: object for c in text}).copy() if text else df     # copy: one block per dtype


def suite_results(suite: str, folder: str | Path) -> Path:
    """Where :mod:`bench` stores the results of ``suite`` under ``folder`` (what
    :func:`load_rows` takes): the case folder ``<suite>.cases`` (one Parquet file per case,
    :data:`observer.results_io.CASES_SUFFIX`)."""
    return Path(folder) / f"{suite}{CASES_SUFFIX}"


def _suite_folders(df: pd.DataFrame) -> dict[str, str | None]:
    """Suite → the results folder of its first row (None where the rows carry none), suites in
    order of appearance."""
    if df.empty or "suite" not in df:
        return {}
    first = df.drop_duplicates("suite")
    dirs = first["results_dir"] if "results_dir" in df else [None] * len(first)
    return {str(s): (str(d) if isinstance(d, (str, Path)) else None) for s, d in zip(first["suite"], dirs)}


def suite_meta(suite: str, folder: str | Path | None) -> dict | None:
    """The metadata bench wrote beside the suite's results
    (:func:`observer.results_io.read_suite_meta`), None where there is none (results written
    before it)."""
    return read_suite_meta(suite, folder) if folder is not None else None


def _declared_order(suite: str, folder: str | Path | None) -> dict[str, int]:
    meta = suite_meta(suite, folder)
    return {cid: i for i, cid in enumerate(meta["cases"])} if meta is not None else {}


def order_rows(df: pd.DataFrame) -> pd.DataFrame:
    """Rows sorted by suite (first appearance), the suite's declared case order (as its
    metadata sidecar lists it; case id for a suite without one), then the row index within the
    case: storage order (one file per case) carries no meaning, the page must not depend on it."""
    if df.empty or not {"suite", "case_id"} <= set(df.columns):
        return df
    folders = _suite_folders(df)
    suites = list(folders)
    pos = pd.Series(float("inf"), index=df.index)
    for s in suites:
        sel = df["suite"].astype(str) == s
        pos[sel] = df.loc[sel, "case_id"].map(_declared_order(s, folders[s])).fillna(float("inf"))
    keys = pd.DataFrame({"suite": df["suite"].astype(str).map(suites.index), "pos": pos,
                         "case": df["case_id"].astype(str),
                         "row": df["row"] if "row" in df else pd.Series(range(len(df)), index=df.index)})
    order = keys.sort_values(["suite", "pos", "case", "row"], kind="stable").index
    return df.loc[order].reset_index(drop=True)


def _suite_of(path: Path) -> str:
    return path.stem[:-len("-micro")] if path.stem.endswith("-micro") else path.stem


def discover_micro(result_files: Iterable[Path]) -> list[Path]:
    """``<dir>/<suite>-micro.json`` next to each results file, where it exists."""
    out = []
    for p in result_files:
        cand = p.parent / f"{_suite_of(p)}-micro.json"
        if cand.exists() and cand not in out:
            out.append(cand)
    return out


MICRO_EXTRA = ("kind", "solver", "m", "scenario", "case", "engine", "steps", "n", "systems",
               "compile_time_s", "residual", "iterations")
"""``extra_info`` keys of a pytest-benchmark record kept as columns."""
MICRO_STATS = {"mean_s": "mean", "median_s": "median", "stddev_s": "stddev", "min_s": "min",
               "rounds": "rounds"}
"""Columns taken from a record's ``stats`` (times in seconds)."""


def _micro_row(path: Path, b: dict) -> dict:
    st, ex = b.get("stats", {}), b.get("extra_info", {})
    row = {"file": str(path), "group": b.get("group") or "", "name": b.get("name", "")}
    row.update({k: ex.get(k, "" if k in ("kind", "solver", "scenario", "case", "engine") else None)
                for k in MICRO_EXTRA})
    row.update({col: st.get(key) for col, key in MICRO_STATS.items()})
    return row


def load_micro(paths: Iterable[Path]) -> tuple[pd.DataFrame, dict]:
    """pytest-benchmark JSON files → one row per benchmark (times in seconds), and metadata."""
    rows, meta = [], {}
    for p in paths:
        data = json.loads(Path(p).read_text())
        meta = {"datetime": data.get("datetime", ""), "version": data.get("version", ""),
                "cpu": (data.get("machine_info", {}).get("cpu", {}) or {}).get("brand_raw", ""),
                "file": str(p)}
        rows += [_micro_row(Path(p), b) for b in data.get("benchmarks", [])]
    return pd.DataFrame(rows), meta


def load_trajectory(row: pd.Series) -> pd.DataFrame | None:
    """The downsampled trajectory a result row points to (``None`` when it has none)."""
    rel = row.get("trajectory")
    if not isinstance(rel, str) or not rel:
        return None
    path = Path(row.get("results_dir", ".")) / rel
    return pd.read_parquet(path) if path.exists() else None


def name_integrator(rows: pd.DataFrame) -> pd.DataFrame:
    """Rows of another integrator than the default get it in their ``name`` ("double_mass ·
    event"), so a scenario run by both integrators shows as two runs, not one."""
    if rows.empty or "integrator" not in rows or "name" not in rows:
        return rows
    other = ~rows["integrator"].map(registry.is_default_integrator).astype(bool)
    if not other.any():
        return rows
    rows = rows.copy()
    rows.loc[other, "name"] = rows.loc[other, "name"].astype(str) + " · " + rows.loc[other, "integrator"].astype(str)
    return rows


PEERS_KIND = "peers"
"""Rows of the Siconos comparison (declared by :mod:`bench.peers`, not by the schema)."""


def schema_columns(kind: str) -> tuple[str, ...]:
    """The columns :mod:`observer.row_schema` declares for rows of ``kind`` (none for peer rows)."""
    from observer.row_schema import ROWS

    if kind == PEERS_KIND:
        return ()
    if kind not in ROWS:
        raise ValueError(f"kind: unknown row kind {kind!r} (known: {', '.join([*ROWS, PEERS_KIND])})")
    return tuple(ROWS[kind])


@dataclass
class ReportContext:
    """Shared input of the sections.

    Attributes
    ----------
    df : DataFrame
        Every result row of the suites (column ``kind`` says which runner wrote it).
    files : list of Path
        The results files read.
    micro, micro_meta : DataFrame, dict
        Micro-benchmark rows (:func:`load_micro`) and the metadata of their file.
    suites : list of str
        Suite names in the rows, in order of appearance.
    command : str
        The one command that reproduces the page.
    out_dir : Path
        Output folder of the page.
    key_numbers : list of str
        Lines for the "Key numbers" section, appended by the sections as they are built.
    key_groups : list of (str, list of str)
        The same lines grouped by the section that added them.
    """

    df: pd.DataFrame
    files: list
    micro: pd.DataFrame
    micro_meta: dict
    suites: list
    command: str
    out_dir: Path
    key_numbers: list = field(default_factory=list)
    key_groups: list = field(default_factory=list)
    """(section id, its key-number lines) in build order (:func:`reports.sections.build_sections`)."""
    _ensemble: object = None

    def ensemble(self):
        """The page's :class:`reports.ensemble_view.EnsembleView` (computed once)."""
        if self._ensemble is None:
            from reports.ensemble_view import ensemble_view
            self._ensemble = ensemble_view(self.df)
        return self._ensemble

    def suite_meta(self, suite: str) -> dict | None:
        """The metadata sidecar of ``suite`` (:func:`suite_meta`), None where it is missing."""
        return suite_meta(suite, _suite_folders(self.df).get(suite))

    def declared(self, key: str):
        """The value of ``key`` in the first suite's metadata sidecar that has it (e.g.
        ``"band"``), None where no sidecar has it."""
        for s in _suite_folders(self.df):
            meta = self.suite_meta(s)
            if meta is not None and key in meta:
                return meta[key]
        return None

    def suites_without_meta(self) -> list[str]:
        """The suites of the rows whose results folder holds no metadata sidecar
        (:func:`suite_meta`): written before bench recorded it; the page says so."""
        return [s for s, folder in _suite_folders(self.df).items() if suite_meta(s, folder) is None]

    def rows(self, kind: str, ok_only: bool = False) -> pd.DataFrame:
        """The rows of one case kind, with every column :mod:`observer.row_schema` declares for it
        (NaN where the rows lack one); optionally only those with status ok.

        Raises
        ------
        ValueError
            ``kind`` is not a kind of :data:`observer.row_schema.ROWS` (nor ``"peers"``).
        """
        declared = schema_columns(kind)
        sel = self.df[self.df["kind"] == kind] if "kind" in self.df else pd.DataFrame()
        if ok_only and "status" in sel:
            sel = sel[sel["status"] == "ok"]
        missing = [c for c in declared if c not in sel.columns]
        sel = sel.assign(**{c: float("nan") for c in missing}) if len(sel) else sel.copy()
        return name_integrator(sel)

    def rows_or_say(self, sec, kind: str, what: str) -> pd.DataFrame | None:
        """The rows of ``kind`` (:meth:`rows`), or None after telling ``sec`` there are no
        ``what`` in these results."""
        rows = self.rows(kind)
        if rows.empty:
            sec.p(f"No {what} in these results.")
            return None
        return rows

    def unavailable_notes(self, prefix: str) -> list[str]:
        """Cases the last suite run skipped (``<suite>.unavailable.json``) whose id starts
        with ``prefix``: "case id: reason"."""
        notes = []
        if not {"suite", "results_dir"} <= set(self.df.columns):
            return notes
        for (suite, folder), _ in self.df.groupby(["suite", "results_dir"]):
            path = Path(folder) / f"{suite}.unavailable.json"
            if path.exists():
                try:
                    notes += [f"{cid}: {msg}" for cid, msg in json.loads(path.read_text()).items()]
                except (OSError, ValueError):
                    continue
        return [n for n in notes if n.startswith(prefix)]


def load_context(result_files: Iterable[str | Path], out_dir: str | Path, *,
                 micro_files: Iterable[str | Path] | None = None,
                 command: str | None = None) -> ReportContext:
    """Read the results files (and micro-benchmark JSON) into a :class:`ReportContext`.

    Raises
    ------
    FileNotFoundError
        A results file does not exist.
    ValueError
        The files hold no rows.
    """
    files = [Path(p) for p in result_files]
    missing = [str(p) for p in files if not p.exists()]
    if missing:
        raise FileNotFoundError(f"results file(s) not found: {', '.join(missing)}")
    df = load_rows(files)
    if df.empty:
        from observer.errors import InputError          # (a ValueError: one line at the CLI)
        raise InputError(", ".join(map(str, files)), "the results files contain no rows; run "
                         "`python -m bench run SUITE` first")
    micro_paths = [Path(p) for p in micro_files] if micro_files is not None else discover_micro(files)
    micro, micro_meta = load_micro(micro_paths)
    suites = list(dict.fromkeys(df["suite"].astype(str)))
    if command is None:
        command = f"nox -s report -- {suites[0] if len(suites) == 1 else 'SUITE'}"
    return ReportContext(df=df, files=files, micro=micro, micro_meta=micro_meta, suites=suites,
                         command=command, out_dir=Path(out_dir))
