"""Result files that prove they are whole (issue 20).

Every file carries its row count and checksums (CSV: the sidecar; Parquet: the schema
metadata), written last; :func:`observer.read_result` refuses a file cut short, altered,
unfinished or unverifiable, or with ``partial=True`` returns its whole rows with the status
"partial". The references are the frames as written (``SimulationResult.to_frame``) and, for
killed runs, an uninterrupted run of the same steps: a row read back must equal the row
written, bit for bit.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from observer.errors import InputError
from observer.io import part_path, read_result, running_path, sidecar_path
from observer.result import RunState, RunStatus
from observer.simulate import simulate
from observer.stream import ChunkWriter

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def small_run():
    """6 rows of the double mass with one observer (14 columns)."""
    return simulate("double_mass", h=1e-3, t_end=0.005, observers=["jump"])


def _written(res, path: Path):
    res.write(path)
    df, meta = read_result(path)
    return df, meta


def _assert_rows_are_the_written_ones(df, ref) -> None:
    """``df`` is a prefix of ``ref`` (same columns, each row bit for bit), without NaN."""
    assert list(df.columns) == list(ref.columns)
    assert len(df) <= len(ref)
    for c in ref.columns:
        a = df[c].to_numpy(dtype=float)
        assert np.all(np.isfinite(a)), c
        assert np.array_equal(a, ref[c].to_numpy(dtype=float)[:len(df)]), c


# ---------------------------------------------------------------------------------------
# cut anywhere, altered anywhere
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("ext", ["csv", "parquet"])
def test_a_file_cut_anywhere_is_refused_or_read_as_its_whole_rows(small_run, tmp_path, ext):
    path = tmp_path / f"r.{ext}"
    ref, meta = _written(small_run, path)
    assert len(ref) == 6 and meta["status"]["state"] == "ok"
    data = path.read_bytes()
    cut = tmp_path / f"cut.{ext}"
    if ext == "csv":
        sidecar_path(cut).write_bytes(sidecar_path(path).read_bytes())
    partial_rows = set()
    for n in range(0, len(data), 7):
        cut.write_bytes(data[:n])
        with pytest.raises(InputError) as ei:
            read_result(cut)
        assert ei.value.field == str(cut)
        try:
            df, m = read_result(cut, partial=True)
        except InputError as exc:                     # nothing whole to return
            assert exc.field in (str(cut), "partial")
            continue
        assert m["status"]["state"] == "partial"
        _assert_rows_are_the_written_ones(df, ref)
        assert len(df) < len(ref) or ext == "csv"
        partial_rows.add(len(df))
    if ext == "csv":                                  # every prefix length of rows was met
        assert partial_rows == set(range(len(ref)))
    df, m = read_result(path)                         # the whole file still reads whole
    assert len(df) == len(ref) and m == meta


def _offsets(data: bytes, ext: str) -> list[int]:
    """Where to alter a byte: every 7th of a CSV; of a Parquet file, every 13th of its row
    groups (values and page headers) and 60 of its footer (schema, offsets, metadata), drawn
    with a fixed seed."""
    if ext == "csv":
        return list(range(3, len(data), 7))
    footer = len(data) - 8 - int.from_bytes(data[-8:-4], "little")
    assert data[:4] == data[-4:] == b"PAR1" and 4 < footer < len(data)
    rng = np.random.default_rng(20)
    return list(range(4, footer, 13)) + sorted(rng.choice(np.arange(footer, len(data) - 4), 60, replace=False))


@pytest.mark.parametrize("ext", ["csv", "parquet"])
def test_an_altered_byte_never_reads_as_a_different_result(small_run, tmp_path, ext):
    path = tmp_path / f"r.{ext}"
    ref, meta = _written(small_run, path)
    data = path.read_bytes()
    bad = tmp_path / f"bad.{ext}"
    if ext == "csv":
        sidecar_path(bad).write_bytes(sidecar_path(path).read_bytes())
    offsets = _offsets(data, ext)
    refused = 0
    for i in offsets:
        changed = bytearray(data)
        changed[i] ^= 0x04
        bad.write_bytes(bytes(changed))
        try:
            df, m = read_result(bad)
        except InputError as exc:
            assert exc.field == str(bad)
            refused += 1
            continue
        # read: then it is the same result (a byte Parquet's reader never looks at)
        assert ext == "parquet" and m == meta and df.equals(ref), i
    assert refused >= (len(offsets) if ext == "csv" else len(offsets) // 2)


def test_an_altered_sidecar_is_detected(small_run, tmp_path):
    path = tmp_path / "r.csv"
    _written(small_run, path)
    side = sidecar_path(path)
    text = side.read_text(encoding="utf-8")
    assert '"h": 0.001' in text
    side.write_text(text.replace('"h": 0.001', '"h": 0.002'), encoding="utf-8")
    with pytest.raises(InputError, match="metadata checksum"):
        read_result(path)
    side.write_text(text[:-20], encoding="utf-8")     # cut: not JSON
    with pytest.raises(InputError, match="damaged"):
        read_result(path)


def test_the_integrity_record_counts_rows_and_is_not_in_the_metadata(small_run, tmp_path):
    path = tmp_path / "r.csv"
    df, meta = _written(small_run, path)
    side = json.loads(sidecar_path(path).read_text(encoding="utf-8"))
    assert side["integrity"]["rows"] == len(df) == path.read_bytes().count(b"\n") - 1
    assert side["integrity"]["state"] == "complete" and "integrity" not in meta


# ---------------------------------------------------------------------------------------
# unfinished runs: a writer abandoned mid-run is what SIGKILL leaves
# ---------------------------------------------------------------------------------------
def _abandoned(res, path: Path, chunks: int) -> None:
    """Write ``chunks`` chunks of 3 rows of ``res`` and leave the writer open."""
    df = res.to_frame()
    df.attrs = {}
    w = ChunkWriter(path)
    for i in range(chunks):
        w.write(df.iloc[3 * i:3 * i + 3])


def test_an_unfinished_csv_is_refused_or_read_as_its_whole_rows(small_run, tmp_path):
    path = tmp_path / "run.csv"
    _abandoned(small_run, path, 2)
    side = json.loads(sidecar_path(path).read_text(encoding="utf-8"))
    assert side["integrity"]["state"] == "running"
    with pytest.raises(InputError, match="did not finish"):
        read_result(path)
    df, meta = read_result(path, partial=True)
    assert meta["status"]["state"] == "partial" and len(df) == 6
    assert RunStatus(meta["status"]["state"], meta["status"]["reason"]).state is RunState.PARTIAL
    _assert_rows_are_the_written_ones(df, small_run.to_frame())


def test_an_unfinished_parquet_is_refused_and_an_earlier_file_is_not_taken_for_it(small_run, tmp_path):
    path = tmp_path / "run.parquet"
    _abandoned(small_run, path, 2)
    assert running_path(path).exists() and part_path(path).exists() and not path.exists()
    for partial in (False, True):
        with pytest.raises(InputError, match="did not finish"):
            read_result(path, partial=partial)
    # a complete file from an earlier run, then a run over it that is killed
    other = tmp_path / "again.parquet"
    small_run.write(other)
    assert read_result(other)[1]["status"]["state"] == "ok"
    _abandoned(small_run, other, 1)
    with pytest.raises(InputError, match="earlier one"):
        read_result(other)


def test_a_finished_stream_leaves_no_running_sidecar(small_run, tmp_path):
    for ext in ("csv", "parquet"):
        path = tmp_path / f"s.{ext}"
        df = small_run.to_frame()
        df.attrs = {}
        with ChunkWriter(path) as w:
            w.write(df.iloc[:4])
            w.write(df.iloc[4:])
            w.finish(small_run)
        back, meta = read_result(path)
        assert meta["status"]["state"] == "ok" and len(back) == len(df)
        assert not part_path(path).exists()
        if ext == "parquet":
            assert not running_path(path).exists()


# ---------------------------------------------------------------------------------------
# the command line, killed
# ---------------------------------------------------------------------------------------
def _start(path: Path, *extra: str) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-m", "observer", "run", "impact_oscillator", "--t-end", "1e3",
                             "--h", "1e-4", "--observers", "none", "--out", str(path), *extra],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for(file: Path, size: int, proc: subprocess.Popen) -> None:
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and proc.poll() is None:
        if file.exists() and file.stat().st_size > size:
            return
        time.sleep(0.02)
    raise AssertionError(f"{file} never reached {size} bytes: {proc.poll()}")


def test_sigkill_leaves_a_running_sidecar_and_whole_rows(tmp_path):
    path = tmp_path / "long.csv"
    proc = _start(path)
    try:
        _wait_for(path, 400_000, proc)
        proc.kill()
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGKILL
    assert json.loads(sidecar_path(path).read_text(encoding="utf-8"))["integrity"]["state"] == "running"
    with pytest.raises(InputError, match="did not finish"):
        read_result(path)
    df, meta = read_result(path, partial=True)
    assert meta["status"]["state"] == "partial" and len(df) > 1000
    ref = simulate("impact_oscillator", h=1e-4, t_end=len(df) * 1e-4).to_frame()
    assert len(ref) > len(df)
    _assert_rows_are_the_written_ones(df, ref)


def test_a_second_signal_during_the_stop_leaves_a_readable_parquet(tmp_path):
    """SIGINT, then SIGTERM 50 ms later (while the stop builds and closes the file): the file
    is closed whole before the second signal is acted on."""
    path = tmp_path / "long.parquet"
    proc = _start(path)
    try:
        _wait_for(part_path(path), 2_000_000, proc)
        proc.send_signal(signal.SIGINT)
        time.sleep(0.05)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=240)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode in (130, 143, -signal.SIGTERM), err
    assert "Traceback" not in err
    df, meta = read_result(path)
    assert meta["status"]["state"] == "stopped" and meta["stopped"]["signal"] in ("SIGINT", "SIGTERM")
    assert len(df) == meta["stopped"]["step"] + 1 and np.all(np.isfinite(df.to_numpy(dtype=float)))
    assert not part_path(path).exists() and not running_path(path).exists()


def test_a_full_disk_while_streaming_parquet_is_one_line_and_leaves_no_partial_file(tmp_path):
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root")
    mnt = tmp_path / "small"
    mnt.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mnt)],
                      capture_output=True).returncode != 0:
        pytest.skip("mount -t tmpfs is not permitted here")
    try:
        out = mnt / "out.parquet"
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        res = subprocess.run([sys.executable, "-m", "observer", "run", "double_mass", "--t-end", "2",
                              "--out", str(out)], cwd=tmp_path, env=env, capture_output=True, text=True,
                             timeout=300)
        lines = res.stderr.splitlines()
        assert res.returncode == 2 and len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
        assert lines[0].startswith(f"error: {mnt}/") and lines[0].endswith("No space left on device")
        assert not part_path(out).exists() and not out.exists()
        with pytest.raises(InputError, match="did not finish|not found"):
            read_result(out)
    finally:
        subprocess.run(["umount", str(mnt)], check=True)
