"""The signals f(t), ν(t), ν̇(t): what each engine evaluates, and that both evaluate the same.

* :class:`observer.model.Harmonic` evaluates ``c_j + Σ_terms a_j·trig(ω t + p_j)`` column by
  column, summed in the order of the terms: checked bitwise against that formula written out
  here entry by entry (and the derivative against ``Σ a_j·ω·trig'(ω t + p_j)``), on seeded
  random harmonics with repeated and distinct phases, zero columns and no terms;
* :meth:`Harmonic.entries` lists exactly those summands (column, coefficient, ω, phase,
  function): summing them reproduces the evaluation bitwise;
* on the time grid both engines take each wave from :func:`observer.model.grid_wave` (angle
  addition from anchors every :data:`~observer.model.GRID_BLOCK` points): within its stated
  bound of the exact value (extended precision) and of the direct evaluation, at the anchors
  bitwise the direct evaluation, and any window bitwise its part of the whole grid;
  :meth:`Harmonic.on_grid` is the formula with those waves, bitwise;
* the compiled kernel's tables (:func:`observer.loop.signal_tables`,
  :func:`observer.loop.wave_table`), combined the way the kernel combines them (constant, then
  the entries of each varying column in order; f̄ = (1−θ)f_k + θf_{k+1}), reproduce the
  python engine's grid (:meth:`observer.stepping.Grid.window`) bitwise on every built-in
  scenario and the chain.
"""

from __future__ import annotations

import numpy as np
import pytest

import observer
from observer.kernel import WAVE_COS, WAVE_MINUS_SIN, WAVE_SIN
from observer.loop import signal_tables, wave_table
from observer.model import GRID_BLOCK, Harmonic, grid_wave
from observer.scenarios import SCENARIOS
from observer.stepping import Grid

FUNCS = {"cos": np.cos, "sin": np.sin, "-sin": lambda x: -np.sin(x)}


def random_harmonic(rng: np.random.Generator, d: int, kind: str) -> Harmonic:
    T = int(rng.integers(0, 4))
    amp = rng.standard_normal((T, d)) * (rng.random((T, d)) < 0.6)      # some zero columns
    phase = rng.choice([0.0, 0.3, -1.2], size=(T, d))                   # repeated phases
    return Harmonic(rng.standard_normal(d), amp, rng.random(T) * 5, phase, kind)


def by_formula(H: Harmonic, t: np.ndarray, derivative: bool) -> np.ndarray:
    """``c_j + Σ_terms a_j·trig(ω t + p_j)`` (or its derivative), one entry at a time."""
    out = np.empty(t.shape + (H.dim,))
    for j in range(H.dim):
        col = np.full(t.shape, 0.0 if derivative else H.constant[j])
        for a, w, p in zip(H.amplitude, H.omega, H.phase):
            if a[j] == 0.0:
                continue
            if derivative:
                trig = (lambda x: -np.sin(x)) if H.kind == "cos" else np.cos
                col = col + (a[j] * w) * trig(w * t + p[j])
            else:
                trig = np.cos if H.kind == "cos" else np.sin
                col = col + a[j] * trig(w * t + p[j])
        out[..., j] = col
    return out


def bits(x: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=np.float64).view(np.int64)


@pytest.mark.parametrize("kind", ["cos", "sin"])
@pytest.mark.parametrize("d", [1, 3, 7])
def test_harmonic_is_its_formula_bitwise(kind, d):
    rng = np.random.default_rng(100 + d)
    t = np.concatenate([rng.random(200) * 100.0, [0.0, 2.5]])
    for _ in range(15):
        H = random_harmonic(rng, d, kind)
        for derivative in (False, True):
            f = H.derivative if derivative else H
            want = by_formula(H, t, derivative)
            assert np.array_equal(bits(f(t)), bits(want))
            assert np.array_equal(bits(f(t[7])), bits(want[7]))            # scalar t


@pytest.mark.parametrize("kind", ["cos", "sin"])
def test_entries_are_the_summands(kind):
    rng = np.random.default_rng(7)
    t = rng.random(300) * 50.0
    for _ in range(20):
        H = random_harmonic(rng, 4, kind)
        for derivative in (False, True):
            out = np.empty(t.shape + (H.dim,))
            out[...] = 0.0 if derivative else H.constant
            entries = H.entries(derivative)
            for col, coef, w, ph, fn in entries:
                out[:, col] += coef * FUNCS[fn](w * t + ph)
            assert np.array_equal(bits(out), bits(H.derivative(t) if derivative else H(t)))
            nonzero = int(np.count_nonzero(H.amplitude))
            assert len(entries) == nonzero                       # one summand per nonzero a_j


def kernel_signals(system, h: float, theta: float, t0: float, k0: int, k1: int):
    """f̄, ν, ν̇ of steps k0..k1 from the kernel's tables, combined as the kernel does."""
    w_om, w_ph, w_fn, e_ptr, e_col, e_coef, e_wave, v_ptr, v_col, f_c, nu_c = signal_tables(system)
    t = t0 + np.arange(k0, k1 + 1) * h
    waves = wave_table(t0, h, k0, k1, w_om, w_ph, w_fn)
    sig = [np.tile(f_c, (t.size, 1)), np.tile(nu_c, (t.size, 1)), np.zeros((t.size, nu_c.size))]
    for s in range(3):
        for i in range(e_ptr[s], e_ptr[s + 1]):
            sig[s][:, e_col[i]] += e_coef[i] * waves[e_wave[i]]
    f, nu, nu_dot = sig
    return (1.0 - theta) * f[:-1] + theta * f[1:], nu, nu_dot, (v_ptr, v_col, e_ptr, e_col)


CASES = [(name, {}) for name in SCENARIOS] + [("rocking_chain", {"param.N": 10})]


@pytest.mark.parametrize("name,overrides", CASES)
def test_kernel_tables_reproduce_the_grid_bitwise(name, overrides):
    sc = observer.load_scenario(name, overrides)
    k0, k1 = 1000, 1400
    g = Grid.window(sc.system, sc.h, sc.theta, 0.25, k0, k1)
    fbar, nu, nu_dot, (v_ptr, v_col, e_ptr, e_col) = kernel_signals(sc.system, sc.h, sc.theta, 0.25,
                                                                    k0, k1)
    assert np.array_equal(bits(fbar), bits(g.fbar))
    assert np.array_equal(bits(nu), bits(g.nu)) and np.array_equal(bits(nu_dot), bits(g.nu_dot))
    for s in range(3):     # the varying columns are exactly the columns with an entry
        assert sorted(v_col[v_ptr[s]:v_ptr[s + 1]]) == sorted(set(e_col[e_ptr[s]:e_ptr[s + 1]]))


def test_waves_are_shared_and_coded():
    """One wave per distinct (ω, phase, function); the codes give cos, sin and −sin."""
    gap = Harmonic(np.zeros(2), np.array([[1.0, 2.0]]), np.array([3.0]), np.array([[0.5, 0.5]]), "sin")
    force = Harmonic(np.zeros(3), np.array([[1.0, 0.0, 4.0]]), np.array([3.0]), np.zeros((1, 3)), "cos")
    system = observer.LinearSystem(np.eye(3), np.zeros((3, 3)), np.eye(3), np.eye(3)[:, :2], force, gap)
    w_om, w_ph, w_fn, e_ptr, *_ = signal_tables(system)
    # f: cos(3t) (columns 0 and 2 share it); ν: sin(3t + 0.5); ν̇: cos(3t + 0.5)
    assert sorted(zip(w_om, w_ph, w_fn)) == sorted([(3.0, 0.0, WAVE_COS), (3.0, 0.5, WAVE_SIN),
                                                     (3.0, 0.5, WAVE_COS)])
    assert list(e_ptr) == [0, 2, 4, 6]
    tab = wave_table(0.5, 0.25, 0, 300, np.array([2.0, 2.0, 2.0]), np.array([0.1, 0.1, 0.1]),
                     np.array([WAVE_COS, WAVE_SIN, WAVE_MINUS_SIN]))
    want = [grid_wave(0.5, 0.25, 0, 300, 2.0, 0.1, fn) for fn in ("cos", "sin", "-sin")]
    assert np.array_equal(bits(tab), bits(np.stack(want)))
    x = 2.0 * (0.5 + np.arange(301) * 0.25) + 0.1
    assert np.allclose(tab, np.stack([np.cos(x), np.sin(x), -np.sin(x)]), rtol=0, atol=1e-13)


# --- grid_wave: the waves on the time grid ----------------------------------------------
GRID_CASES = [  # (t0, h, k0, k1, ω, phase): long and short grids, ω = 0, large ω·t, offsets
    (0.0, 1e-4, 0, 40_000, 3.0, 0.0), (0.25, 1e-3, 5, 3_000, 17.3, -1.2),
    (-3.0, 0.01, 0, 2_000, 0.0, 0.7), (0.0, 1e-4, 9_990_000, 10_001_000, 3.0, 0.3),
    (100.0, 1e-5, 123, 20_123, 251.3, 2.9), (0.0, 0.125, 0, 513, 1.0, 0.0)]


def exact_wave(t0, h, k0, k1, w, ph, fn):
    """fn(ω t_k + phase) in extended precision at the float grid times t_k = t0 + k·h."""
    t = (t0 + np.arange(k0, k1 + 1) * h).astype(np.longdouble)
    x = np.longdouble(w) * t + np.longdouble(ph)
    return {"cos": np.cos(x), "sin": np.sin(x), "-sin": -np.sin(x)}[fn]


@pytest.mark.parametrize("case", GRID_CASES)
@pytest.mark.parametrize("fn", ["cos", "sin", "-sin"])
def test_grid_wave_is_within_its_bound(case, fn):
    """|grid_wave − fn(ω t_k + phase)| ≤ 4(|ω|·max|t| + |phase| + 1)·ε against extended
    precision; the direct evaluation is within the same bound, so the two agree to twice it."""
    t0, h, k0, k1, w, ph = case
    assert np.finfo(np.longdouble).eps < 1e-18                  # x87 extended: a real reference
    v = grid_wave(t0, h, k0, k1, w, ph, fn)
    t = t0 + np.arange(k0, k1 + 1) * h
    bound = 4.0 * (abs(w) * (np.abs(t).max() + GRID_BLOCK * h) + abs(ph) + 1.0) * np.finfo(float).eps
    ex = exact_wave(*case, fn)
    direct = FUNCS[fn](w * t + ph)
    assert v.shape == t.shape
    assert float(np.max(np.abs(v - ex))) <= bound
    assert float(np.max(np.abs(direct - ex))) <= bound
    assert float(np.max(np.abs(v - direct))) <= 2 * bound


@pytest.mark.parametrize("fn", ["cos", "sin", "-sin"])
def test_grid_wave_anchors_are_the_direct_value_and_windows_the_whole(fn):
    t0, h, w, ph = 0.3, 1e-3, 7.1, 0.4
    whole = grid_wave(t0, h, 0, 5_000, w, ph, fn)
    k = np.arange(0, 5_001, GRID_BLOCK)                          # the anchors: bitwise direct
    assert np.array_equal(bits(whole[k]), bits(FUNCS[fn](w * (t0 + k * h) + ph)))
    for k0, k1 in ((0, 0), (1, 1), (127, 129), (300, 1_000), (4_999, 5_000), (17, 4_111)):
        assert np.array_equal(bits(grid_wave(t0, h, k0, k1, w, ph, fn)), bits(whole[k0:k1 + 1]))


@pytest.mark.parametrize("kind", ["cos", "sin"])
def test_on_grid_is_the_formula_with_grid_waves(kind):
    """:meth:`Harmonic.on_grid` sums the same summands in the same order as :meth:`__call__`,
    each wave from :func:`grid_wave`: bitwise that sum, and within the waves' bound of
    :meth:`__call__` at the grid times."""
    rng = np.random.default_rng(11)
    t0, h, k0, k1 = 0.1, 2e-3, 250, 2_300
    t = t0 + np.arange(k0, k1 + 1) * h
    for _ in range(15):
        H = random_harmonic(rng, 3, kind)
        for derivative in (False, True):
            out = np.empty(t.shape + (H.dim,))
            out[...] = 0.0 if derivative else H.constant
            for col, coef, w, ph, fn in H.entries(derivative):
                out[:, col] += coef * grid_wave(t0, h, k0, k1, w, ph, fn)
            got = H.on_grid(t0, h, k0, k1, derivative)
            assert np.array_equal(bits(got), bits(out))
            scale = (np.abs(H.amplitude) * (H.omega[:, None] if derivative else 1.0)).sum() + 1.0
            direct = H.derivative(t) if derivative else H(t)
            assert np.allclose(got, direct, rtol=0, atol=1e-12 * scale)
