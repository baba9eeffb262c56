"""The compiled kernels of the event integrator (observer.event.kernels) against independent
references: scipy's expm and exact mpmath exponentials, CPython's math.fsum, 50-digit norms,
and the numpy implementations they replace (the same floats, so that the event engine's
results did not move)."""

from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest
import scipy.linalg as sla

import observer
from observer.event import kernels
from observer.event.flow import expm_pade13 as expm_numpy
from observer.event.flow import flow_for, norm_upper_reference


def _lapack_solve(a, b):
    """``a⁻¹b`` by scipy's LAPACK ``dgesv``: the routine numba's ``np.linalg.solve`` calls
    (numpy's own LAPACK may round differently: it does on some builds for N ≥ 9)."""
    _, _, x, info = sla.lapack.dgesv(a, b)
    assert info == 0
    return x


@pytest.mark.parametrize("N", [1, 2, 5, 9])
def test_expm_matches_scipy_and_numpy(N, monkeypatch):
    """exp(A) to 1e-12 of scipy's (norms 1e-3 … 60, scaling and squaring included) and the
    very floats of the numpy version, its solve taken from the LAPACK the kernel calls."""
    rng = np.random.default_rng(N)
    monkeypatch.setattr(np.linalg, "solve", _lapack_solve)
    for size in (1e-3, 0.7, 6.0, 60.0):
        A = rng.standard_normal((N, N)) * size / N
        E = kernels.expm_pade13(A)
        ref = sla.expm(A)
        assert np.max(np.abs(E - ref)) <= 1e-12 * max(1.0, np.max(np.abs(ref)))
        assert np.array_equal(E, expm_numpy(A))


def test_expm_rotation_closed_form():
    """exp of the rotation generator [[0, w], [−w, 0]] t is the rotation by wt (mpmath cos/sin)."""
    for wt in (1e-6, 0.3, 2.0, 40.0):
        E = kernels.expm_pade13(np.array([[0.0, wt], [-wt, 0.0]]))
        c, s = float(mpmath.cos(wt)), float(mpmath.sin(wt))
        assert np.max(np.abs(E - np.array([[c, s], [-s, c]]))) <= 64 * np.finfo(float).eps * max(1.0, wt)


def test_blocked_expm_is_the_flow_exponential():
    """``blocked_expm`` of a flow with two blocks (the oscillator: mechanics + forcing
    oscillator, and the constant state) equals exp(A dt) from 40-digit mpmath, and the
    entries between blocks are exactly zero."""
    fl = flow_for(observer.load_scenario("impact_oscillator").system)
    assert len(fl.blocks) == 2
    dt = 0.37
    E = kernels.blocked_expm(fl._balanced, fl.scale, *fl._block_layout, dt)
    with mpmath.workdps(40):
        ref = mpmath.expm(mpmath.matrix(fl.A.tolist()) * dt)
        ref = np.array([[float(ref[i, j]) for j in range(fl.N)] for i in range(fl.N)])
    assert np.max(np.abs(E - ref)) <= 1e-14 * np.max(np.abs(ref))
    inside = np.zeros((fl.N, fl.N), dtype=bool)
    for b in fl.blocks:
        inside[np.ix_(b, b)] = True
    assert np.all(E[~inside] == 0.0)
    assert np.array_equal(fl.expm(dt), E)


def test_blocked_expm_undoes_the_balancing():
    """With a scaling T = diag(2^k) that is not the identity and two blocks of a permuted
    block-diagonal A, ``blocked_expm(T⁻¹AT, T, …)`` is exp(A dt) (40-digit mpmath)."""
    rng = np.random.default_rng(11)
    N, dt = 6, 0.8
    blocks = [np.array([0, 3, 5]), np.array([1, 2, 4])]
    B = np.zeros((N, N))                               # the balanced matrix: entries O(1)
    for b in blocks:
        B[np.ix_(b, b)] = rng.standard_normal((b.size, b.size))
    scale = 2.0 ** rng.integers(-10, 10, N).astype(float)
    A = B * scale[:, None] / scale[None, :]            # A = T B T⁻¹ (exact: powers of two)
    order, starts = np.concatenate(blocks), np.array([0, 3, 6])
    E = kernels.blocked_expm(B, scale, order, starts, dt)
    with mpmath.workdps(40):
        ref = mpmath.expm(mpmath.matrix(A.tolist()) * dt)
        ref = np.array([[float(ref[i, j]) for j in range(N)] for i in range(N)])
    ratio = scale[:, None] / scale[None, :]          # compared in the balanced coordinates
    assert np.max(np.abs(E - ref) / ratio) <= 1e-14 * np.max(np.abs(ref / ratio))
    assert np.all(E[np.ix_(blocks[0], blocks[1])] == 0.0)


def test_exact_sum_is_fsum():
    """The correctly rounded sum: CPython's math.fsum on cancelling sums of widely spread
    magnitudes (where a plain sum loses every digit)."""
    rng = np.random.default_rng(7)
    for _ in range(500):
        n = int(rng.integers(1, 40))
        x = rng.standard_normal(n) * 10.0 ** rng.integers(-200, 200, n)
        x = np.concatenate([x, -x[: n // 2], [1e-300]])
        assert kernels.exact_sum(x) == math.fsum(x.tolist())
    x = np.array([1e100, 1.0, -1e100, 1e-100])
    assert kernels.exact_sum(x) == 1.0 + 1e-100 and float(np.sum(x)) != 1.0
    assert kernels.exact_sum(np.array([0.5, 2.0 ** -54, 2.0 ** -107])) == 0.5 + 2.0 ** -53


def test_norm_upper_bounds_and_matches_reference():
    """norm_upper ≥ ‖v‖₂ (50 digits) within 12u relative (u = 2^-53: the squares' roundings
    u/2, the sum's two ulps up ≤ 2u of the square root, the sqrt's 4u and its two ulps up ≤ 4u,
    with room for one more), and the same float as the Python reference; inf for a non-finite
    entry, 0 for zero. Every comparison is made at 50 digits (not at mpmath's global precision,
    which another test module may have changed)."""
    rng = np.random.default_rng(3)
    u = mpmath.mpf(2) ** -53
    for _ in range(300):
        n = int(rng.integers(1, 25))
        v = rng.standard_normal(n) * 10.0 ** rng.integers(-300, 300, n)
        b = kernels.norm_upper(v)
        with mpmath.workdps(50):
            exact = mpmath.sqrt(mpmath.fsum(mpmath.mpf(float(x)) ** 2 for x in v))
            assert mpmath.mpf(b) >= exact
            assert mpmath.mpf(b) <= exact * (1 + 12 * u) + mpmath.mpf(1e-310)
        assert b == norm_upper_reference(v)
    assert kernels.norm_upper(np.array([1.0, np.nan])) == np.inf
    assert kernels.norm_upper(np.zeros(3)) == 0.0


def _screen_reference(d, both, za, scale, support, inflate, third_norm, growth, w):
    """The numpy expressions of :func:`observer.event.roots.first_zero` and ``_safe_step``
    that :func:`kernels.screen_step` replaced (as they were written there)."""
    from observer.event.flow import norm_upper

    finite = bool(np.isfinite(za).all() and np.isfinite(d).all())
    errs = inflate * both[3:]
    U = np.finfo(float).eps / 2.0
    bound = np.nextafter(third_norm * (growth * norm_upper(za[support] / scale[support]))
                         * (1.0 + 4.0 * U), np.inf)
    l0, l1, l2 = d[0] - errs[0], d[1] - errs[1], d[2] - errs[2]
    quick = (l0 > 0.0) & (
        l0 + np.minimum(l1, 0.0) * w + np.minimum(l2, 0.0) * w * w / 2 - bound * w ** 3 / 6 > 0.0)
    return finite, errs, bound, bool(np.isfinite(bound).all()), quick


def test_screen_step_is_the_numpy_expressions_bit_for_bit():
    """``screen_step`` gives the very floats and booleans of the numpy expressions it
    replaced in the safe step (errors, third-derivative bounds, quick test, finiteness), on
    random data spanning 1e-12 … 1e12 with signed zeros, quick tests on both sides and
    non-finite states; and it is the search's own: a flow's functional set screens a state
    as the reference does."""
    rng = np.random.default_rng(7)
    quick_seen = set()
    for trial in range(400):
        p, N = int(rng.integers(1, 5)), int(rng.integers(2, 10))
        mag = 10.0 ** rng.uniform(-12, 12, (4, p))
        d = rng.standard_normal((4, p)) * mag
        d[0] = np.abs(d[0])
        if trial % 7 == 0:
            d[1, 0] = -0.0
            d[2, 0] = 0.0
        both = np.abs(rng.standard_normal((6, p))) * mag[[0, 1, 2, 0, 1, 2]] * 10.0 ** rng.uniform(-16, -1)
        za = rng.standard_normal(N) * 10.0 ** rng.uniform(-6, 6)
        if trial % 50 == 0:
            za[int(rng.integers(N))] = np.inf if trial % 100 else np.nan
        scale = 2.0 ** rng.integers(-8, 8, N).astype(float)
        support = np.sort(rng.choice(N, int(rng.integers(1, N + 1)), replace=False)).astype(np.int64)
        third = np.abs(rng.standard_normal(p)) * 10.0 ** rng.uniform(-3, 3)
        growth, w = float(rng.uniform(1.0, 1.7)), float(10.0 ** rng.uniform(-6, 1))
        if trial % 2:                  # the quick test on its edge: ψ(a) just cancels the cubic's drop
            errs, bound = _screen_reference(d, both, za, scale, support, 1.0 + 1e-15, third, growth,
                                            w)[1:3]
            d[1], d[2] = -np.abs(d[1]), -np.abs(d[2])
            drop = ((d[1] - errs[1]) * w + (d[2] - errs[2]) * w * w / 2 - bound * w ** 3 / 6)
            d[0] = errs[0] - drop * (1.0 + rng.integers(-4, 5, p) * np.finfo(float).eps)
        args = (d, both, za, scale, support, 1.0 + 1e-15, third, growth, w)
        got = kernels.screen_step(*args, w ** 3)
        ref = _screen_reference(*args)
        assert got[0] == ref[0] and got[3] == ref[3]
        for a, b in ((got[1], ref[1]), (got[2], ref[2])):
            assert np.array_equal(a, b, equal_nan=True) and np.array_equal(np.signbit(a), np.signbit(b))
        assert np.array_equal(got[4], ref[4])
        quick_seen.update(bool(q) for q in ref[4])
    assert quick_seen == {True, False}
    from observer.event.roots import WINDOW, functional_set

    fl = flow_for(observer.load_scenario("impact_oscillator").system)
    fs = functional_set(fl, fl.gap_rows)
    z = fl.z(0.3, np.array([0.1, -0.2]))
    d, *got = fs.screen(z, 1.3, WINDOW / fs.norm_bound)
    assert np.array_equal(d, fs.derivatives(z))
    S = np.arange(fl.N) if fs._full else fs.support      # the block of FunctionalSet.state_norm
    ref = _screen_reference(d, fs._abs_rows @ np.abs(z), z, fl.scale, S, fs._inflate,
                            fs.third_norm, 1.3, WINDOW / fs.norm_bound)
    assert fs.state_norm(z) == norm_upper_reference(z[S] / fl.scale[S])
    assert got[0] == ref[0] and np.array_equal(got[1], fs.sums(z)[1])
    assert all(np.array_equal(a, b) for a, b in zip(got[1:], ref[1:]))
