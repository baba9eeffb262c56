"""Issue 36, item 15: a fitted order with one point is a defined symbol with its legend, never ``nan``."""

from __future__ import annotations

import numpy as np
import pandas as pd

from reports.analysis import fit_power
from reports.sections.work_precision import NO_FIT, NO_FIT_LEGEND, orders_table


def _row(order: float) -> dict:
    return {"scenario": "double_mass", "target": "master", "law": "newton", "solver": "pivoting",
            "integrator": "timestepping", "reference": "closed form", "points": 1 if np.isnan(order) else 4,
            "h_min": 1e-4, "h_max": 1e-4 if np.isnan(order) else 1e-3, "order": order,
            "order_max": order, "work_slope": order, "best_err": 1e-6, "best_cpu": 0.1}


def test_one_point_is_no_fit_with_its_legend():
    p, _ = fit_power([1e-4], [1e-6])                 # one step size: nothing to fit
    table = orders_table(pd.DataFrame([_row(p), _row(1.0)]))
    cells = [c for row in table.rows for c in row]
    assert not any("nan" in c.lower() for c in cells)
    assert table.rows[0].count(NO_FIT) == 3 and table.rows[1][7] == "1.00"
    assert table.note == NO_FIT_LEGEND and NO_FIT_LEGEND.startswith(NO_FIT + ": ")


def test_a_table_with_every_order_fitted_has_no_legend():
    assert orders_table(pd.DataFrame([_row(2.0)])).note == ""
