"""Compact periodic vectors in scenario documents (issue 23): ``{n, pattern, head, tail}``.

A long vector that repeats a short pattern (zeros, the chain's gravity load [−mg, 0], a ground
motion on the first block only) is written as its period; the document of the default rocking
chain of 10⁵ blocks then fits the reader's 16 MiB limit, and reads back bit for bit.
Oracles: the arrays the built-in generated, compared bitwise after the TOML round trip.
"""

from __future__ import annotations

import numpy as np
import pytest

from observer import load_scenario
from observer import sparse as sps
from observer.errors import InputError
from observer.model import LinearSystem, harmonic_table
from observer.scenario import Scenario
from observer.scenarios import rocking_chain as rc
from observer.tomlio import MAX_BYTES, dumps, read_toml
from observer.validation import as_array, as_matrix


def unchecked_scenario(doc: dict) -> Scenario:
    """``Scenario.from_dict`` without the O(n) spectral checks of the system (Lanczos at
    N = 10⁵ costs seconds; the round trip of the document is what is tested)."""
    s = doc["system"]
    n = len(doc["initial"]["q"]) if isinstance(doc["initial"]["q"], list) else doc["initial"]["q"]["n"]
    system = LinearSystem(*(as_matrix(f"system.{k}", s[k], (n, n)) for k in "MCKW"),
                          harmonic_table("system.forcing", s["forcing"], n, "cos", "constant"),
                          harmonic_table("system.gap", s["gap"], n, "sin", "offset"), check=False)
    return Scenario.from_dict(doc, "rocking_chain", system)


def vectors(sc: Scenario) -> dict:
    s = sc.system
    out = {"q0": sc.q0, "u0": sc.u0, "f.c": s.forcing.constant, "f.a": s.forcing.amplitude,
           "f.p": s.forcing.phase, "g.o": s.gap.constant, "g.a": s.gap.amplitude, "g.p": s.gap.phase}
    for key in ("q", "u"):
        out[f"obs.{key}"] = as_array(f"observer.{key}", sc.observer[key], (s.n,))
    return out


def test_default_chain_of_1e5_blocks_round_trips_through_a_compact_toml_file(tmp_path):
    N = 100_000
    sc = unchecked_scenario(rc.document(N=N))
    doc = sc.to_dict()
    assert doc["initial"]["u"] == {"n": 2 * N, "pattern": [0.0]}
    assert doc["system"]["forcing"]["constant"] == {"n": 2 * N, "pattern": [-9.81, 0.0]}
    path = tmp_path / "chain.toml"
    path.write_text(dumps(doc))
    size = path.stat().st_size
    assert size < 12 * 2 ** 20 < MAX_BYTES          # was 20.4 MiB, all lists
    back = unchecked_scenario(read_toml(path))
    got = vectors(back)
    for name, x in vectors(sc).items():
        y = got[name]
        assert y.shape == x.shape and np.array_equal(y.view(np.int64), x.view(np.int64)), name
    for k in "MCKW":
        assert (getattr(back.system, k) != getattr(sc.system, k)).nnz == 0


def test_small_systems_keep_plain_lists_and_a_mid_size_one_runs_from_its_compact_file(tmp_path):
    small = load_scenario("rocking_chain", {"param.N": 10}).to_dict()
    assert isinstance(small["initial"]["u"], list) and isinstance(small["system"]["forcing"]["constant"], list)
    sc = load_scenario("rocking_chain", {"param.N": 300})
    path = tmp_path / "c.toml"
    path.write_text(dumps(sc.to_dict()))
    assert "[initial.u]" in path.read_text()
    back = load_scenario(path)                      # the full checks, through the public path
    got = vectors(back)
    for name, x in vectors(sc).items():
        assert np.array_equal(got[name], x), name


@pytest.mark.parametrize("value, field, hint", [
    ({"n": 5, "pattern": [0.0]}, "initial.u.n", "length 4"),
    ({"pattern": [0.0]}, "initial.u.n", "n and pattern required"),
    ({"n": 4}, "initial.u.pattern", "pattern required"),
    ({"n": 4, "pattern": [0.0], "period": 2}, "initial.u.period", "keys n, pattern, head, tail"),
    ({"n": 4, "pattern": [], "head": [1.0]}, "initial.u.pattern", "non-empty"),
    ({"n": 4, "pattern": [0.0], "head": [1.0, 2.0, 3.0], "tail": [4.0, 5.0]}, "initial.u.pattern", "at most 4"),
    ({"n": 4.0, "pattern": [0.0]}, "initial.u.n", "length 4"),
    ({"n": 4, "pattern": ["0"]}, "initial.u.pattern", "string"),
])
def test_bad_compact_vectors_name_the_field(value, field, hint):
    doc = load_scenario("rocking_chain", {"param.N": 2}).to_dict()
    doc["initial"]["u"] = value
    with pytest.raises(InputError, match=hint) as err:
        Scenario.from_dict(doc)
    assert err.value.field == field


def test_compact_vector_expands_head_pattern_tail_and_scalar_fields_accept_it():
    v = as_array("x", {"n": 7, "head": [9.0], "pattern": [1.0, 2.0], "tail": [5.0]}, (None,))
    assert v.tolist() == [9.0, 1.0, 2.0, 1.0, 2.0, 1.0, 5.0]
    x = np.concatenate([[3.0], np.tile([1.5, -2.0], 400), [7.0, 8.0]])
    form = sps.vector_document(x)
    assert form == {"n": 803, "head": [3.0], "pattern": [1.5, -2.0], "tail": [7.0, 8.0]}
    assert np.array_equal(as_array("x", form, (803,)), x)
    assert isinstance(sps.vector_document(np.arange(600.0)), list)       # not periodic: a list
