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


@pytest.mark.parametrize("N", [1, 2, 5, 9])
def test_expm_matches_scipy_and_numpy(N):
    """exp(A) to 1e-12 of scipy's (norms 1e-3 … 60, scaling and squaring included) and the
    very floats of the numpy version."""
    rng = np.random.default_rng(N)
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
