"""Bench storage verified (issue 20): a case file counts as done only if it opens, holds the
rows it was written with and its checksum matches; a damaged one is reported, moved aside and
computed again; concurrent clients compute each case once; a full disk is one line.
"""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import bench.__main__ as bench_cli
import bench.suites
from bench.results import CHECKSUM_KEY, DAMAGED_SUFFIX, CaseStore, load_results
from bench.run import results_path, run_suite
from bench.suites import Case, Suite

REPO = Path(__file__).resolve().parents[2]

TINY = Suite("tiny", "three quick work-precision points of the bouncing ball", tuple(
    Case("work_precision", "bouncing_ball", law="newton", h=h, t_end=0.3, observers=(),
         reference="closed form") for h in (4e-3, 2e-3, 1e-3)))
"""Cases of a few hundred steps (a closed-form reference, no event-driven run)."""


def _rows(n: int) -> list[dict]:
    return [{"x": float(i) + 0.5, "label": f"r{i}"} for i in range(n)]


def _stored(store: CaseStore, case_id: str):
    return pq.read_table(store.case_path(case_id))


# ------------------------------------------------------------------------- verification
def test_a_written_case_carries_a_checksum_and_counts_as_done(tmp_path):
    store = CaseStore(tmp_path / "s.cases")
    store.write_case("s", "a", _rows(3))
    table = _stored(store, "a")
    digest = table.schema.metadata[CHECKSUM_KEY].decode()
    assert len(digest) == 64 and int(digest, 16) >= 0          # a SHA-256 hex digest
    assert store.has("a") and store.damaged() == [] and store.done_ids() == {"a"}


def test_every_truncation_of_a_case_file_is_damaged_never_done(tmp_path):
    """A case file cut at every 7th byte: never done, always reported, never an exception."""
    store = CaseStore(tmp_path / "s.cases")
    path = store.write_case("s", "a", _rows(4))
    whole = path.read_bytes()
    for cut in range(0, len(whole), 7):
        path.write_bytes(whole[:cut])
        os.utime(path, ns=(cut, cut))                          # a new stamp: no stale verdict
        assert not store.has("a"), cut
        assert [p for p, _ in store.damaged()] == [path], cut
        assert store.rows() == [] and store.done_ids() == set()


def test_an_altered_value_fails_the_checksum(tmp_path):
    """A file that opens but whose rows differ from those written (an edited value, kept
    metadata) is damaged."""
    store = CaseStore(tmp_path / "s.cases")
    path = store.write_case("s", "a", _rows(2))
    table = _stored(store, "a")
    x = table.column("x").to_pylist()
    x[1] = 99.0
    altered = table.set_column(table.column_names.index("x"), "x", pa.array(x))
    pq.write_table(altered.replace_schema_metadata(table.schema.metadata), path)
    assert not store.has("a")
    [(where, reason)] = store.damaged()
    assert where == path and "checksum does not match" in reason


def test_a_file_without_checksum_or_with_missing_rows_is_damaged(tmp_path):
    store = CaseStore(tmp_path / "s.cases")
    path = store.write_case("s", "a", _rows(3))
    table = _stored(store, "a")
    pq.write_table(table.replace_schema_metadata(None), path)      # no checksum
    assert not store.has("a") and "no checksum" in store.damaged()[0][1]
    # two of the three rows, with the checksum of those two: the row count gives it away
    from bench.results import content_digest
    short = table.slice(0, 2).replace_schema_metadata(None)
    pq.write_table(short.replace_schema_metadata({CHECKSUM_KEY: content_digest(short).encode()}), path)
    assert not store.has("a") and "case_rows" in store.damaged()[0][1]


def test_quarantine_moves_damaged_files_aside_and_load_results_skips_them(tmp_path):
    store = CaseStore(tmp_path / "s.cases")
    store.write_case("s", "a", _rows(2))
    bad = store.write_case("s", "b", _rows(2))
    bad.write_bytes(bad.read_bytes()[:40])
    df = load_results([store.path])                       # no ArrowInvalid: the good case only
    assert set(df["case_id"]) == {"a"}
    [(moved, reason)] = store.quarantine()
    assert moved == bad.with_name(bad.name + DAMAGED_SUFFIX) and moved.exists()
    assert not bad.exists() and "does not open" in reason
    assert store.damaged() == [] and store.done_ids() == {"a"}


# --------------------------------------------------------------------------------- runs
@pytest.fixture
def tiny_suite(monkeypatch):
    monkeypatch.setitem(bench.suites._SUITE_BUILDERS, "tiny", lambda: TINY)
    return TINY


def test_bench_status_and_run_report_a_damaged_case_and_compute_it_again(tmp_path, tiny_suite,
                                                                        capsys):
    first = run_suite(TINY, tmp_path, progress=False, micro=False)
    assert first.ran == len(TINY.cases)
    store = CaseStore(results_path("tiny", tmp_path))
    victim = TINY.cases[1].case_id
    path = store.case_path(victim)
    path.write_bytes(path.read_bytes()[:-9])               # cut short: its footer is gone
    assert bench_cli.main(["status", "tiny", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert f"{len(TINY.cases) - 1}/{len(TINY.cases)} cases done" in out
    assert f"damaged case file {path.name} does not open" in out
    again = run_suite(TINY, tmp_path, progress=False, micro=False)
    assert (again.ran, again.skipped) == (1, len(TINY.cases) - 1)
    assert [p.name for p, _ in again.damaged] == [path.name + DAMAGED_SUFFIX]
    assert "moved aside" in again.text()
    assert store.has(victim) and (store.folder / (path.name + DAMAGED_SUFFIX)).exists()
    assert len(store.rows()) == len(TINY.cases)


def test_bench_run_on_a_full_disk_is_one_line_naming_the_file(tmp_path, tiny_suite, monkeypatch,
                                                             capsys):
    """The write of a case file fails as a full disk does (ENOSPC from write(), no file
    name): exit 2, one line naming the case file, no temporary file left behind."""
    def full_disk(table, where, **kwargs):
        Path(where).write_bytes(b"PAR1")                   # a torn first block, then the error
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(pq, "write_table", full_disk)
    code = bench_cli.main(["run", "tiny", "--out", str(tmp_path), "--workers", "0", "--no-micro",
                           "--no-progress"])
    out, err = capsys.readouterr()
    store = CaseStore(results_path("tiny", tmp_path))
    assert code == 2
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith(f"error: {store.folder}/") and err.rstrip().endswith(
        "No space left on device"), err
    assert ".parquet:" in err
    assert list(store.folder.glob(".*.tmp")) == [] and store.files() == []


CLIENT = textwrap.dedent("""
    import json, sys
    import bench.run
    from bench.suites import Case, Suite
    bench.run._KERNEL_TIME.append(0.0)       # no warm-up of the compiled kernel: cases use python
    suite = Suite("race", "", tuple(
        Case("work_precision", "bouncing_ball", law="newton", solver="lemke", h=h, t_end=0.4,
             observers=(), reference="closed form") for h in (4e-3, 3e-3, 2e-3, 1.5e-3)))
    s = bench.run.run_suite(suite, sys.argv[1], progress=False, micro=False)
    print(json.dumps({"ran": s.ran, "skipped": s.skipped, "failed": s.failed}))
""")


def test_two_concurrent_clients_compute_each_case_once(tmp_path):
    """Two ``run_suite`` clients started together on one folder, the same cases in the same
    order: the per-case lock makes one compute each case and the other find it done."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    procs = [subprocess.Popen([sys.executable, "-c", CLIENT, str(tmp_path)], cwd=REPO, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for _ in range(2)]
    results = []
    for p in procs:
        out, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
        results.append(json.loads(out.strip().splitlines()[-1]))
    assert all(r["failed"] == [] for r in results)
    assert sum(r["ran"] for r in results) == 4, results
    assert all(r["ran"] + r["skipped"] == 4 for r in results), results
    store = CaseStore(results_path("race", tmp_path))
    rows = store.rows()
    assert len(rows) == 4 and len({r["case_id"] for r in rows}) == 4
    assert store.damaged() == []


def test_bench_run_on_a_real_full_disk(tmp_path, tiny_suite, capsys):
    """``bench run`` into an 8 KiB tmpfs (root may mount one; elsewhere the ENOSPC test above
    stands in): exit 2, one line naming the case file, no temporary file left behind."""
    mnt = tmp_path / "small"
    mnt.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=8k", "tmpfs",
                                            str(mnt)], capture_output=True).returncode != 0:
        pytest.skip("cannot mount a tmpfs here")
    try:
        code = bench_cli.main(["run", "tiny", "--out", str(mnt), "--workers", "0", "--no-micro",
                               "--no-progress"])
        out, err = capsys.readouterr()
        store = CaseStore(results_path("tiny", mnt))
        assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
        assert err.startswith(f"error: {store.folder}/") and "No space left on device" in err
        assert list(store.folder.glob(".*.tmp")) == [] and store.files() == []
    finally:
        subprocess.run(["umount", str(mnt)], check=True)
