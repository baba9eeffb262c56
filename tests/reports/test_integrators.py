"""The report's integrator comparison, checked on hand-made work-precision rows."""

import numpy as np
import pandas as pd

from reports.analysis import integrator_comparison
from reports.sections.integrators import comparison_table, key_sentence


def _rows():
    hs = np.array([2e-3, 1e-3, 5e-4, 2.5e-4])
    ts = pd.DataFrame({"scenario": "osc", "law": "newton", "integrator": "time-stepping",
                       "solver": "pivoting", "target": "master", "status": "ok", "h": hs,
                       "err_mean": 0.5 * hs, "cpu_time_s": 1e-4 / hs})     # error ∝ h, CPU ∝ 1/h
    ev = pd.DataFrame([{"scenario": "osc", "law": "newton", "integrator": "event", "solver": "pivoting",
                        "target": "master", "status": "ok", "h": 2e-3, "err_mean": 1e-14,
                        "cpu_time_s": 0.02}])
    ref = ts.assign(solver="reference", cpu_time_s=1.0)                  # ignored: not the fast solver
    return pd.concat([ts, ev, ref], ignore_index=True)


def test_comparison_recomputed_from_the_rows():
    cmp = integrator_comparison(_rows())
    (r,) = cmp.to_dict("records")
    assert r["ts_h"] == 2.5e-4 and r["ts_err"] == 0.5 * 2.5e-4 and r["ts_cpu"] == 1e-4 / 2.5e-4
    assert r["cpu_ratio"] == (1e-4 / 2.5e-4) / 0.02
    # CPU = 1e-4/h = 0.5e-4/err: at err = 1e-14 it is 5e9 s
    assert np.isclose(r["ts_cpu_at_event_err"], 5e9, rtol=1e-9)
    assert np.isclose(r["ratio_at_equal_error"], 5e9 / 0.02, rtol=1e-9)
    assert len(comparison_table(cmp).rows) == 1
    msg = key_sentence(cmp)
    assert msg.startswith("Event-driven integrator (osc): error 1.00e−14 against time-stepping's "
                          "1.25e−4 at its finest step, for 0.05× its CPU time")
    assert msg.endswith("250000000000× cheaper")


def test_no_extrapolation_without_a_decreasing_work_curve():
    rows = _rows()
    rows.loc[rows.integrator == "time-stepping", "cpu_time_s"] = 1.0        # flat: no work curve
    (r,) = integrator_comparison(rows).to_dict("records")
    assert np.isnan(r["ts_cpu_at_event_err"]) and np.isnan(r["ratio_at_equal_error"])


def test_without_event_rows_nothing_is_compared():
    rows = _rows()
    assert integrator_comparison(rows[rows.integrator != "event"]).empty
