"""The peers section reads what bench recorded about Siconos when the suite ran (the suite's
metadata, ``bench.peers.siconos_record``), never this machine; results written before that
record say plainly that they do not know.

Each test writes results as a bench run does (a case store and
:func:`bench.run.write_suite_meta`) under a Siconos interpreter chosen by the test, then builds
the section with another one in place (a missing one): what the page says can only come from
the metadata.
"""

from __future__ import annotations

import json

import pytest

from bench import peers
from bench.results import CaseStore
from bench.run import results_path, unavailable_path, write_suite_meta
from bench.suites import Suite
from observer.results_io import meta_path
from reports.context import load_context
from reports.sections import peers as section

ROW = {"kind": "observers", "scenario": "oscillator", "name": "osc", "status": "ok"}
NOTE = {"peers:impact_oscillator:h=0.0001": "Siconos absent: no interpreter at /gone/python3; "
                                            + peers.HOW_TO_GET}
FAKE_VERSION = "9.9.9 (recorded by the suite run)"


@pytest.fixture
def suite_run(tmp_path, monkeypatch):
    """``write(available)``: results of suite ``s`` written with Siconos found (version
    :data:`FAKE_VERSION`) or absent (no interpreter at ``/gone/python3``); afterwards this
    process has no Siconos interpreter at all (``/nonexistent/bin/python3``)."""
    monkeypatch.setattr(peers, "_RECORDS", {})

    def write(available: bool):
        monkeypatch.setattr(peers, "SICONOS_PYTHON", "/gone/python3")
        if available:
            monkeypatch.setattr(peers, "siconos_available", lambda python=None: (True, FAKE_VERSION))
        store = CaseStore(results_path("s", tmp_path))
        store.write_case("s", "observers:a", [ROW])
        write_suite_meta(Suite("s", "one case", ()), tmp_path)
        monkeypatch.setattr(peers, "SICONOS_PYTHON", "/nonexistent/bin/python3")
        monkeypatch.setattr(peers, "siconos_available", lambda python=None: pytest.fail("probed"))
        return store.path
    return write


def _text(folder, tmp_path) -> tuple[str, list[str], object]:
    ctx = load_context([folder], tmp_path / "r")
    sec = section.build(ctx)
    paragraphs = " ".join(b.content for b in sec.blocks if b.kind == "p")
    kinds = [b.kind for b in sec.blocks]
    return paragraphs, kinds, ctx


def _drop_siconos(tmp_path) -> None:
    """The suite's metadata as bench wrote it before it recorded Siconos."""
    path = meta_path("s", tmp_path)
    meta = json.loads(path.read_text())
    del meta["siconos"]
    path.write_text(json.dumps(meta))


def test_recorded_absence_is_reported_with_the_recorded_reason(suite_run, tmp_path):
    folder = suite_run(False)
    text, kinds, _ = _text(folder, tmp_path)
    assert "these suites have no peer cases" in text and "python -m bench run peers" in text
    assert ("Siconos was not available when the suite ran: no interpreter at /gone/python3; "
            + peers.HOW_TO_GET) in text
    assert "/nonexistent" not in text and "table" not in kinds


def test_recorded_presence_is_reported_with_the_recorded_version(suite_run, tmp_path):
    folder = suite_run(True)
    text, _, _ = _text(folder, tmp_path)
    assert f"Siconos was available when the suite ran ({FAKE_VERSION})" in text
    assert "not available" not in text


def test_skipped_peer_cases_say_how_to_get_siconos_from_the_record(suite_run, tmp_path):
    folder = suite_run(False)
    unavailable_path("s", tmp_path).write_text(json.dumps(NOTE))
    text, kinds, ctx = _text(folder, tmp_path)
    assert text.startswith("No peer results: Siconos was not available when the suite ran. "
                           f"To get it: {peers.HOW_TO_GET}; then run the suite again")
    assert kinds == ["p", "list"]
    assert any(k.startswith("Peers: no Siconos results") for k in ctx.key_numbers)


@pytest.mark.parametrize("notes", [False, True], ids=["no peer cases", "skipped peer cases"])
def test_results_without_the_record_say_they_do_not_know(suite_run, tmp_path, notes):
    folder = suite_run(True)
    _drop_siconos(tmp_path)
    if notes:
        unavailable_path("s", tmp_path).write_text(json.dumps(NOTE))
    text, kinds, _ = _text(folder, tmp_path)
    assert section.UNKNOWN in text
    assert "was available" not in text and "was not available" not in text
    assert FAKE_VERSION not in text
    assert kinds == (["p", "list"] if notes else ["p"])


@pytest.mark.parametrize("record", [None, "yes", {"available": "yes"}, {"available": True},
                                    {"available": False, "reason": "x"}],
                         ids=["null", "text", "not a bool", "no version", "no how-to"])
def test_an_unreadable_record_reads_as_unknown(suite_run, tmp_path, record):
    folder = suite_run(True)
    path = meta_path("s", tmp_path)
    path.write_text(json.dumps({**json.loads(path.read_text()), "siconos": record}))
    text, _, _ = _text(folder, tmp_path)
    assert section.UNKNOWN in text


def test_results_without_any_metadata_say_they_do_not_know(suite_run, tmp_path):
    folder = suite_run(False)
    meta_path("s", tmp_path).unlink()
    text, _, _ = _text(folder, tmp_path)
    assert section.UNKNOWN in text and "was not available" not in text
