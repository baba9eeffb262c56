"""bench.revisions: the revision extracted as committed, an unknown revision refused by name,
a timing process that imports another tree refused, the summary recomputed from its rows
(no timing is asserted: the module measures, the tests check the bookkeeping)."""

from __future__ import annotations

import subprocess

import numpy as np
import pandas as pd
import pytest

from bench import revisions
from observer.errors import InputError


def test_extract_gives_the_committed_files_and_refuses_an_unknown_revision(tmp_path):
    commit = revisions.extract("HEAD", tmp_path)
    head = subprocess.run(["git", "-C", str(revisions.ROOT), "rev-parse", "HEAD"], capture_output=True,
                          text=True, check=True).stdout.strip()
    assert commit == head
    shown = subprocess.run(["git", "-C", str(revisions.ROOT), "show", "HEAD:observer/__init__.py"],
                           capture_output=True, text=True, check=True).stdout
    assert (tmp_path / "observer" / "__init__.py").read_text() == shown
    with pytest.raises(InputError) as info:
        revisions.extract("no-such-revision-h21", tmp_path / "x")
    assert info.value.field == "revision"
    assert revisions.main(["no-such-revision-h21", "--steps", "10"]) == 2


def test_a_timing_process_that_imports_another_tree_is_refused(tmp_path):
    """A directory without the package: the process imports the installed observer, which
    is not that tree's, and the timing is refused rather than attributed to it."""
    with pytest.raises(RuntimeError, match="not the tree"):
        revisions.TreeTimer(tmp_path, steps=10)


def test_summary_medians_spread_and_ratio():
    rng = np.random.default_rng(21)
    rows = []
    for process, (tree, scale) in enumerate([("revision", 40.0), ("current", 44.0)] * 2):
        for call in range(5):
            x = scale * (1 + 0.1 * rng.random())
            rows.append({"tree": tree, "commit": tree, "round": process // 2, "process": process, "call": call,
                         "steps": 100, "ns_per_step": x, "cpu_ns_per_step": x / 2, "loop_ns_per_step": x / 3,
                         "warmup_s": float(process), "engine": "compiled"})
    calls = pd.DataFrame(rows)
    table = revisions.summary(calls)
    assert len(table) == 6 and set(table.measure) == {"ns_per_step", "cpu_ns_per_step", "loop_ns_per_step"}
    for _, r in table.iterrows():
        x = calls.loc[calls.tree == r.tree, r.measure].to_numpy()
        base = np.median(calls.loc[calls.tree == "revision", r.measure])
        assert r.calls == 10 and r["median"] == np.median(x) and r["min"] == x.min() and r["max"] == x.max()
        assert r.q25 <= r["median"] <= r.q75
        assert r.ratio == pytest.approx(np.median(x) / base, rel=1e-15)
        per_process = [np.median(calls.loc[calls.process == p, r.measure])
                       for p in sorted(set(calls.loc[calls.tree == r.tree, "process"]))]
        assert r.median_of_processes == pytest.approx(np.median(per_process), rel=1e-15)
    cur = table[(table.tree == "current") & (table.measure == "ns_per_step")].iloc[0]
    assert 1.0 < cur.ratio < 1.25 and cur.warmup_s == 2.0          # processes 1 and 3: median 2
