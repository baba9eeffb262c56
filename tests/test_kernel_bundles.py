"""The kernel fed by named bundles (issue 21): the same trajectories, bit for bit.

* every built-in scenario, in every compiled loop (lean or scalar, general, projected,
  summary), records exactly the arrays main recorded before the kernel took bundles: the
  sha256 digests in ``tests/data/kernel_fingerprints.json`` were written by
  ``python tests/kernel_fingerprint.py`` on main at d26e40e (positional kernel arguments),
  and are recomputed here on the current kernel;
* every kernel entry point takes at most 12 parameters, and each bundle's fields are the
  ones the loop's constructors fill (by name).
"""

from __future__ import annotations

import inspect
import json

import pytest

from observer import kernel
from observer.loop import compile_time
from observer.scenarios import SCENARIOS

from kernel_fingerprint import PATH, result_digest, variants

STORED = json.loads(PATH.read_text())


@pytest.fixture(scope="module", autouse=True)
def compiled():
    compile_time()


def test_the_table_covers_every_builtin_scenario():
    assert set(STORED) == set(SCENARIOS)
    assert all({"alone", "observers", "summary"} <= set(v) for v in STORED.values())


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_trajectories_are_bitwise_those_of_main(name):
    import observer

    sc = observer.load_scenario(name)
    got = {v: result_digest(observer.simulate(sc, engine="compiled", **kw)) for v, kw in variants(name).items()}
    assert got == STORED[name]


@pytest.mark.parametrize("entry", ["advance", "advance_scalar", "summary_start", "project_closed"])
def test_entry_points_take_at_most_12_parameters(entry):
    fn = getattr(kernel, entry)
    fn = getattr(fn, "py_func", fn)              # the compiled ones' Python source
    assert len(inspect.signature(fn).parameters) <= 12


def test_bundles_are_filled_by_name_and_typed_alike():
    """Every field of every bundle is set by its constructor; two runs of different sizes give
    bundles of the same numba types (one specialization per entry point)."""
    import numba
    import numpy as np

    import observer
    import observer.loop as loop

    def bundles(name, S):
        sc = observer.load_scenario(name)
        st = observer.MoreauJean(sc.system, sc.law, sc.h, 10 * sc.h, sc.theta)
        inp = loop.LoopInput(st, np.stack([sc.q0] * S), np.stack([sc.u0] * S), np.array([False] * S), False)
        rec, R = loop._allocate(inp, 1, False)
        sig = loop.signal_tables(st.system)
        return (loop.system_bundle(inp), loop.law_bundle(st), sig, loop.observer_bundle(inp),
                loop.state_bundle(inp), loop.storage_bundle(rec, 1, False, None),
                loop.summary_bundle(inp, False, (1e-3,), R),
                loop.window_bundle(inp, sig, 0, 10, st.time(np.arange(11))))

    a, b = bundles("double_mass", 2), bundles("rocking_chain", 2)
    for x, y in zip(a, b):
        assert type(x) is type(y) and all(f is not None for f in x)
        assert numba.typeof(x) == numba.typeof(y)

