"""Sparse system matrices (issue 23): storage, TOML triplet form, O(n) checks and ω_max.

Oracles: dense computations of the same matrices at sizes where both are cheap (n = 600 …
1000, just above :data:`observer.sparse.DENSE_MAX_N` so that the sparse path is the one
taken), and tracemalloc for the absence of anything of size n² at N = 10⁴ blocks.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

from observer import load_scenario, simulate
from observer import sparse as sps
from observer.errors import InputError
from observer.health import omega_max, omega_max_method
from observer.model import LinearSystem
from observer.scenario import Scenario
from observer.scenarios import rocking_chain as rc
from observer.tomlio import dumps, loads
from observer.validation import check_independent_columns, check_psd, check_spd, extreme_eigenvalues


def chain(N: int):
    p = rc.PARAMETERS
    return rc.sparse_matrices(N, p["m"], p["b"], p["H"], p["a"], p["k"], p["c"])


def test_small_systems_stay_dense_large_ones_sparse():
    small = load_scenario("rocking_chain", {"param.N": 10}).system
    large = load_scenario("rocking_chain", {"param.N": 300}).system
    assert not small.sparse and isinstance(small.K, np.ndarray)
    assert large.sparse and all(sp.issparse(A) for A in (large.M, large.C, large.K, large.W))
    assert large.n == 600 > sps.DENSE_MAX_N >= small.n


def test_omega_max_by_lanczos_within_one_percent_of_dense_at_N500():
    system = load_scenario("rocking_chain", {"param.N": 500}).system
    assert system.sparse
    dense = float(np.sqrt(sla.eigh(system.K.toarray(), system.M.toarray(), eigvals_only=True,
                                   subset_by_index=[system.n - 1, system.n - 1])[0]))
    w = omega_max(system)
    assert "Lanczos" in omega_max_method(system)
    assert abs(w / dense - 1.0) < 1e-2
    assert abs(w / dense - 1.0) < 1e-3          # measured 1.0e-4 (LANCZOS_TOL_MAX = 1e-3)
    assert w <= dense * (1 + 1e-12)             # a Ritz value never exceeds λ_max


def test_sparse_extreme_eigenvalues_match_dense():
    M, C, K, W, _, _ = chain(300)
    lo, hi = extreme_eigenvalues(K)
    eig = np.linalg.eigvalsh(K.toarray())
    assert lo == pytest.approx(eig[0], rel=1e-8)
    assert hi == pytest.approx(eig[-1], rel=1e-3) and hi <= eig[-1] * (1 + 1e-12)
    lo_w, hi_w = extreme_eigenvalues(sp.csr_matrix(W.T @ W))
    ew = np.linalg.eigvalsh((W.T @ W).toarray())
    assert lo_w == pytest.approx(ew[0], rel=1e-8)


def test_sparse_checks_refuse_what_the_dense_ones_refuse():
    M, C, K, W, _, _ = chain(300)
    assert "Cholesky" in check_spd("system.M", M)
    assert "Cholesky" in check_psd("system.K", K)
    lo = np.linalg.eigvalsh(K.toarray())[0]
    indefinite = sp.csr_matrix(K - 2 * lo * sp.eye(K.shape[0]))
    with pytest.raises(InputError, match="not positive semi-definite") as err:
        check_psd("system.K", indefinite)
    assert err.value.field == "system.K"
    Mbad = M.tolil()
    Mbad[5, 5] = -1.0
    with pytest.raises(InputError, match="not positive definite") as err:
        check_spd("system.M", sp.csr_matrix(Mbad))
    assert err.value.field == "system.M"
    Wdep = W.tolil()
    Wdep[:, 1] = Wdep[:, 0]
    with pytest.raises(InputError, match="linearly independent") as err:
        check_independent_columns("system.W", sp.csr_matrix(Wdep))
    assert err.value.field == "system.W"
    asym = K.tolil()
    asym[0, 1] += 1.0
    with pytest.raises(InputError, match="not symmetric"):
        LinearSystem(M, C, sp.csr_matrix(asym), W, *_signals(300))


def _signals(N):
    sc = load_scenario("rocking_chain", {"param.N": 2})
    from observer.model import Harmonic
    return Harmonic.build("system.forcing", 2 * N), Harmonic.build("system.gap", 2 * N, kind="sin")


def test_triplet_toml_round_trip_keeps_the_matrices_sparse_and_equal():
    sc = load_scenario("rocking_chain", {"param.N": 300})
    doc = sc.to_dict()
    for name in "MCKW":                      # the triplet form, given explicitly
        doc["system"][name] = sps.triplet_document(getattr(sc.system, name))
    assert len(doc["system"]["K"]["values"]) == sc.system.K.nnz
    text = dumps(doc)
    assert len(text) < 100 * (sc.system.K.nnz + sc.system.C.nnz + sc.system.W.nnz + 10 * sc.system.n)
    back = Scenario.from_dict(loads(text, "round trip"))
    for name in "MCKW":
        A, B = getattr(sc.system, name), getattr(back.system, name)
        assert sp.issparse(B) and (A != B).nnz == 0
    assert np.array_equal(back.q0, sc.q0)


def test_banded_toml_round_trip_is_compact_sparse_and_equal():
    """The default document of a large chain: banded tables (the chain's diagonals periodic:
    the block's values, the top block's as a tail; symmetric matrices their lower half), read
    back to the same sparse matrices; an override round trip and ``show`` keep them sparse."""
    sc = load_scenario("rocking_chain", {"param.N": 300})
    doc = sc.to_dict()
    K, M, W = doc["system"]["K"], doc["system"]["M"], doc["system"]["W"]
    assert set(K) == set(sps.BANDED_KEYS) and K["symmetric"] is True and K["offsets"] == [-2, 0]
    J = rc.PARAMETERS["m"] * (4 * rc.PARAMETERS["b"] ** 2 + rc.PARAMETERS["H"] ** 2) / 12
    assert M["offsets"] == [0] and M["diagonals"] == [{"pattern": [1.0, J]}]     # [m, J] alternate
    k, a = rc.PARAMETERS["k"], rc.PARAMETERS["a"]
    assert K["diagonals"][1] == {"pattern": [4 * k, 4 * k * a * a], "tail": [2 * k, 2 * k * a * a]}
    assert "symmetric" not in W
    stored = sum(len(x) for t in (K, M, W) for d in t["diagonals"] for x in d.values())
    assert stored <= 20
    text = dumps(doc)
    back = Scenario.from_dict(loads(text, "round trip"))
    over = back.with_overrides({"simulation.h": 1e-3})
    for name in "MCKW":
        A, B, C = getattr(sc.system, name), getattr(back.system, name), getattr(over.system, name)
        assert sp.issparse(B) and sp.issparse(C) and (A != B).nnz == 0 and (A != C).nnz == 0
    assert dumps(back.to_dict()) == text                                  # show: the same text


def test_small_banded_table_is_the_dense_matrix_and_constant_diagonals_expand():
    doc = load_scenario("double_mass").to_dict()
    K = np.array(doc["system"]["K"])
    doc["system"]["K"] = {"shape": [2, 2], "offsets": [-1, 0], "diagonals": [[K[1, 0]], K.diagonal().tolist()],
                          "symmetric": True}
    doc["system"]["M"] = {"shape": [2, 2], "offsets": [0], "diagonals": [2.5]}
    sc = Scenario.from_dict(doc)
    assert isinstance(sc.system.K, np.ndarray) and np.array_equal(sc.system.K, K)
    assert np.array_equal(sc.system.M, 2.5 * np.eye(2))


@pytest.mark.parametrize("edit, field, hint", [
    (lambda t: t.update(offsets=[0, 0]), "system.K.offsets", "distinct"),
    (lambda t: t.update(offsets=[1, 0]), "system.K.offsets", "integers in -1..0"),
    (lambda t: t.pop("diagonals"), "system.K.diagonals", "missing"),
    (lambda t: t.update(diagonals=[[1.0, 2.0], [1.0, 2.0]]), "system.K.diagonals[0]", "wrong shape"),
    (lambda t: t.update(diagonals=[[1.0]]), "system.K.diagonals", "one per offset"),
    (lambda t: t.update(symmetric="yes"), "system.K.symmetric", "true or false"),
    (lambda t: t.update(lower=1), "system.K.lower", "unknown key"),
])
def test_bad_banded_tables_name_the_field(edit, field, hint):
    doc = load_scenario("double_mass").to_dict()
    table = {"shape": [2, 2], "offsets": [-1, 0], "diagonals": [[-1.0], [2.0, 2.0]], "symmetric": True}
    edit(table)
    doc["system"]["K"] = table
    with pytest.raises(InputError, match=hint) as err:
        Scenario.from_dict(doc)
    assert err.value.field == field


def test_small_triplet_table_is_the_dense_matrix():
    doc = load_scenario("double_mass").to_dict()
    K = np.array(doc["system"]["K"])
    r, c = np.nonzero(K)
    doc["system"]["K"] = {"shape": list(K.shape), "rows": r.tolist(), "cols": c.tolist(),
                          "values": K[r, c].tolist()}
    sc = Scenario.from_dict(doc)
    assert isinstance(sc.system.K, np.ndarray) and np.array_equal(sc.system.K, K)


@pytest.mark.parametrize("edit, field, hint", [
    (lambda t: t.update(rows=[t["shape"][0]] + t["rows"][1:]), "system.K.rows", "integers in"),
    (lambda t: t.pop("values"), "system.K.values", "missing"),
    (lambda t: t.update(dense=1), "system.K.dense", "unknown key"),
    (lambda t: t.update(shape=[2.5, 2]), "system.K.shape", "positive integers"),
    (lambda t: t.update(values=t["values"][:-1]), "system.K.rows", "wrong shape"),
])
def test_bad_triplet_tables_name_the_field(edit, field, hint):
    doc = load_scenario("double_mass").to_dict()
    K = np.array(doc["system"]["K"])
    r, c = np.nonzero(K)
    table = {"shape": list(K.shape), "rows": r.tolist(), "cols": c.tolist(), "values": K[r, c].tolist()}
    edit(table)
    doc["system"]["K"] = table
    with pytest.raises(InputError, match=hint) as err:
        Scenario.from_dict(doc)
    assert err.value.field == field


def test_sparse_and_dense_systems_run_the_same_trajectory():
    """N = 300 (n = 600): the sparse system against the same matrices given dense."""
    sc = load_scenario("rocking_chain", {"param.N": 300, "simulation.t_end": 0.15,
                                         "simulation.h": 1e-3})
    doc = sc.to_dict()
    for name in "MCKW":
        doc["system"][name] = getattr(sc.system, name).toarray().tolist()
    sd = Scenario.from_dict(doc)
    assert sc.system.sparse and not sd.system.sparse
    a = simulate(sc, observers=["jump", "nojump"])
    b = simulate(sd, observers=["jump", "nojump"])
    for x, y in [(a.q, b.q), (a.u, b.u)] + [(a.slaves[k].q, b.slaves[k].q) for k in a.slaves]:
        assert np.max(np.abs(x - y)) <= 1e-13 * max(1.0, np.max(np.abs(y)))
    assert a.metadata["health"]["computed_by"]["omega_max"].startswith("Lanczos")
    assert a.metadata["health"]["computed_by"]["K_definite"].startswith("verified")     # banded K − cI
    assert b.metadata["health"]["computed_by"]["K_definite"].startswith("eigenvalues")  # a dense K
    assert a.metadata["health"]["h_omega_max"] == pytest.approx(b.metadata["health"]["h_omega_max"], rel=1e-3)


def test_event_engine_refuses_a_large_system_naming_its_size():
    sc = load_scenario("rocking_chain", {"param.N": 300})
    with pytest.raises(InputError, match="n = 600"):
        simulate(sc, h=1e-3, t_end=0.01, integrator="event")


def test_loading_and_checking_a_large_chain_allocates_nothing_of_size_n_squared():
    """N = 10⁴ blocks (n = 2·10⁴): one dense n × n matrix would be 3.2 GB; the load (generator,
    document, validation), an override round trip and ω_max stay below 64 MB."""
    tracemalloc.start()
    try:
        sc = load_scenario("rocking_chain", {"param.N": 10_000})
        sc = sc.with_overrides({"simulation.h": 1e-3})
        w = omega_max(sc.system)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert sc.system.sparse and w > 0
    assert peak < 64 * 2**20, f"peak {peak / 2**20:.0f} MB"


@pytest.mark.parametrize("steps, n, systems", [(1000, 200_000, 3), (10**6, 20, 3), (1000, 20, 1),
                                               (50_000, 20_000, 3)])
def test_summary_rows_are_bounded_for_any_size(steps, n, systems):
    from observer.engines.timestepping import SUMMARY_ROW_VALUES, summary_record_every
    k = summary_record_every(steps, n, systems)
    rows = steps // k + 1
    assert rows * 2 * n * systems <= SUMMARY_ROW_VALUES + 2 * n * systems     # within one row
    assert rows <= 10_001
    if steps * 2 * n * systems < SUMMARY_ROW_VALUES:                       # small: as before
        assert k == max(1, steps // 10_000)


def test_closed_set_projection_matches_the_dense_projection():
    """K⁻¹W_I and L_I from the banded factor of K (once), against the dense K⁻¹W and L
    restricted to I; the projected state closes the gaps of I exactly (to round-off)."""
    from observer.stepping import ClosedSetProjection
    M, C, K, W, _, _ = chain(300)
    proj = ClosedSetProjection(K, W)
    Kd, Wd = K.toarray(), W.toarray()
    KinvW = np.linalg.solve(Kd, Wd)
    L = Wd.T @ KinvW
    rng = np.random.default_rng(3)
    closed = np.sort(rng.choice(W.shape[1], 7, replace=False))
    KinvWI, LI = proj.matrices(closed)
    np.testing.assert_allclose(KinvWI, KinvW[:, closed], rtol=0, atol=1e-12 * np.abs(KinvW).max())
    np.testing.assert_allclose(LI, L[np.ix_(closed, closed)], rtol=0, atol=1e-12 * np.abs(L).max())
    q = rng.normal(size=K.shape[0]) * 1e-3
    g = Wd[:, closed].T @ q - 1e-4                  # gaps of the closed contacts (ν = −1e-4)
    q1, sigma = proj.project(q, g, closed)
    assert np.max(np.abs(Wd[:, closed].T @ q1 - 1e-4)) <= 1e-14 * max(1.0, np.abs(q).max())
    with pytest.raises(InputError) as err:
        ClosedSetProjection(sp.csr_matrix(K - 2e6 * sp.eye(K.shape[0])), W)
    assert err.value.field == "system.K"


def test_factored_gram_matches_the_dense_block_and_its_cache_stays_consistent():
    """Ĝ_AA = sym(W_AᵀN⁻¹W_A) from the banded factor of N with a two-column cache, against
    dense algebra; a set larger than the cache, then one that evicts the least recently used
    column; the cache maps stay inverse to each other and every cached column is N⁻¹W_j."""
    from observer.kernel import factored_gram
    from observer.loop import column_cache
    M, C, K, W, _, _ = chain(30)
    N = sp.csr_matrix(K + 1e3 * M)
    bw = sps.bandwidth(N)
    fac = sla.cholesky_banded(sps.to_band(N, bw), lower=True)
    Wc = sp.csc_matrix(W)
    Wc.sort_indices()
    Wp, Wi, Wv = (Wc.indptr.astype(np.int64), Wc.indices.astype(np.int64), Wc.data.copy())
    NinvW = np.linalg.solve(N.toarray(), W.toarray())
    cols, slot_of, owner, stamp = (x[0] for x in column_cache(1, N.shape[0], W.shape[1], C=2))
    work, G = np.empty(N.shape[0]), np.empty((8, 8))
    for act in ([3, 7, 11], [7, 20], [5, 20, 7]):
        act = np.array(act, dtype=np.int64)
        factored_gram(act, act.size, Wp, Wi, Wv, fac, bw, cols, slot_of, owner, stamp, work, G)
        ref = W.toarray()[:, act].T @ NinvW[:, act]
        np.testing.assert_allclose(G[:act.size, :act.size], 0.5 * (ref + ref.T), rtol=1e-12,
                                   atol=1e-12 * np.abs(ref).max())
        for r, j in enumerate(owner):
            if j >= 0:
                assert slot_of[j] == r
                np.testing.assert_allclose(cols[r], NinvW[:, j], rtol=0, atol=1e-12 * np.abs(NinvW).max())
        assert np.count_nonzero(slot_of >= 0) == np.count_nonzero(owner >= 0) <= 2
    # the last set: 5 and 20 take the two rows (least recently used first), 7 has no row left
    # (both in use by this set) and is solved into the work vector
    assert set(owner) == {5, 20}


def test_factored_contact_data_run_the_dense_contact_datas_trajectory(monkeypatch):
    """The chain N = 40 (n = 80, banded) with master, jump and nojump: the factored contact
    data (forced below their size threshold) against the precomputed dense Â⁻¹W, Ĝ, K⁻¹W, L,
    both engines, to the rounding of their solves: per step at most κ₂(Â)·u relative (first
    order, a backward-stable solve), summed over the steps (the scheme is passive: it does not
    amplify them); the factored bundles hold nothing of size n × m or m × m."""
    import observer.stepping as stepping
    from observer.loop import LoopInput, observer_bundle, system_bundle
    sc = load_scenario("rocking_chain", {"param.N": 40})
    kw = dict(h=1e-3, t_end=0.6, observers=["jump", "nojump"], coupling=(0.2, 0.6))
    ref = simulate(sc, **kw)
    monkeypatch.setattr(stepping, "FACTORED_MIN_N", 0)
    st = stepping.MoreauJean(sc.system, sc.law, 1e-3, 0.6, structure="auto")
    assert st.S.factored and st.S.AinvW is None and st.S.L is None
    inp = LoopInput(st, np.stack([sc.q0] * 3), np.stack([sc.u0] * 3), np.array([False, True, False]), False)
    sb, ob = system_bundle(inp), observer_bundle(inp)
    assert sb.AinvWT.size == sb.Ghat.size == ob.KinvWT.size == ob.L.size == 1
    assert ob.Kch.shape == (1, sb.bw + 1, sc.system.n)
    from observer.loop import ENGINES                  # the registry's time-stepping engines
    s = sc.system
    A_hat = s.M + 0.5e-3 * s.C + 0.25e-6 * s.K          # Â = M + hθC + h²θ²K, θ = ½
    steps = round(kw["t_end"] / kw["h"])
    agree = steps * np.linalg.cond(A_hat) * np.finfo(float).eps / 2
    for engine in ENGINES:
        got = simulate(sc, engine=engine, **kw)
        assert int(got.active.sum()) == int(ref.active.sum()) > 20          # contacts did close
        for x, y in [(got.q, ref.q), (got.u, ref.u)] + [(got.slaves[k].q, ref.slaves[k].q) for k in ref.slaves]:
            assert np.max(np.abs(x - y)) <= agree * max(1.0, np.max(np.abs(y)))
        assert np.abs(got.slaves["jump"].sigma).max() > 0                    # it did project


def _traced_run_peak(N: int) -> tuple[float, object]:
    """tracemalloc's peak over a whole run of the chain (load, checks, master + jump + nojump
    over 30 steps with contacts, summary storage, health) and its result."""
    tracemalloc.start()
    try:
        sc = load_scenario("rocking_chain", {"param.N": N, "param.Omega": 20.0})
        res = simulate(sc, h=1e-3, t_end=0.03, observers=["jump", "nojump"], store="summary",
                       coupling=(0.0, 0.03))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return peak, res


def test_a_whole_run_at_N_1e4_allocates_O_n():
    """N = 10⁴ blocks (n = m = 2·10⁴, bandwidth 3): one n × m matrix would be 3.2 GB. The whole
    run's peak stays below 12 KiB per degree of freedom (measured 7.7: the two caches of solved
    columns, 256 each, are 4 KiB of it; records, Lanczos bases, the banded factors the rest),
    and grows like n between N = 10³ and 10⁴, not like n² (the ratio would be 100)."""
    simulate("rocking_chain", h=1e-3, t_end=0.002)              # the kernel compiled beforehand
    small, _ = _traced_run_peak(1000)
    peak, res = _traced_run_peak(10_000)
    n = res.system.n
    assert res.stats.contact_solves > 0 and np.abs(res.slaves["jump"].sigma).max() > 0   # it projected
    assert peak < 12 * 1024 * n, f"peak {peak / n:.0f} B per degree of freedom"
    assert peak / small < 10 * 1.5, f"peak ratio {peak / small:.1f} for 10× the size"


def test_periodic_diagonals_round_trip_mixed_with_constant_and_plain_ones():
    """A periodic diagonal (head, pattern, tail) beside a constant and an aperiodic one: the
    writer makes them all tables (TOML's array of tables), the reader gives A back exactly."""
    n = 40
    main = np.concatenate([[7.0], np.tile([1.0, 3.0], 19), [5.0]])
    A = sp.diags([np.full(n - 1, 2.0), main, np.arange(n - 1.0)], [-1, 0, 1]).tocsr()
    doc = sps.banded_document(A)
    assert doc["diagonals"][1] == {"pattern": [1.0, 3.0], "head": [7.0], "tail": [5.0]}
    assert doc["diagonals"][0] == {"pattern": [2.0]} and len(doc["diagonals"][2]["pattern"]) == n - 1
    back = sps.banded_matrix("system.K", loads(dumps({"system": {"K": doc}}), "x")["system"]["K"])
    assert (A != back).nnz == 0
    with pytest.raises(InputError) as err:
        sps.banded_matrix("system.K", {**doc, "diagonals": [{"pattern": [1.0], "head": [0.0] * 41}] * 3})
    assert err.value.field == "system.K.diagonals[0].pattern"


def test_other_projection_metrics_are_refused_with_factored_contact_data():
    """n = 600: the M-metric design would need the dense n × n metric; refused by name."""
    sc = load_scenario("rocking_chain", {"param.N": 300})
    with pytest.raises(InputError, match="other than K") as err:
        simulate(sc, h=1e-3, t_end=0.01, observers=["jump_mass"])
    assert err.value.field == "observers"
