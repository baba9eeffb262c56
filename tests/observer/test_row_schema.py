"""observer.row_schema: one typed row per case kind; the runners' rows are checked against it."""

import numpy as np
import pytest

from observer.row_schema import ROWS, check_row
from observer.metrics import RHOS, settle_column, sync_column


def _row(kind):
    values = {str: "x", float: 1.0, int: 1, bool: True}
    return {c: values[t[0] if isinstance(t, tuple) else t] for c, t in ROWS[kind].items()} | {"kind": kind}


@pytest.mark.parametrize("kind", list(ROWS))
def test_declared_row_passes_and_numpy_scalars_count(kind):
    row = _row(kind)
    assert check_row(row) is row
    row["h"] = np.float64(1e-3)
    row["n"] = np.int64(2)
    check_row(row)


def test_missing_column_and_wrong_type_are_named():
    row = _row("robustness")
    del row[settle_column(1e-6)]
    with pytest.raises(ValueError, match="t_settle_1e-06"):
        check_row(row)
    with pytest.raises(ValueError, match=r"missing \[\]") as info:
        check_row(_row("observers") | {"h": "0.1"})
    assert "h (str)" in str(info.value)
    row = _row("work_precision")
    del row["err_mean"]
    with pytest.raises(ValueError, match="err_mean"):
        check_row(row)
    with pytest.raises(ValueError, match="passed"):
        check_row(_row("checks") | {"passed": 1.0})
    with pytest.raises(ValueError, match="seed"):
        check_row(_row("checks") | {"seed": None})


def test_not_applicable_observer_row_needs_only_the_case():
    cols = {c for c in ROWS["observers"] if c in ROWS["checks"] and c not in ("cpu_time_s", "wall_time_s", "cpu_scope")}
    row = {c: _row("observers")[c] for c in cols} | {"observer": "jump", "status": "n/a"}
    check_row(row)


def test_threshold_columns_follow_the_one_list():
    for rho in RHOS:
        assert sync_column(rho) in ROWS["observers"] and settle_column(rho) in ROWS["robustness"]
    assert sync_column(1e-6) == "t_sync_1e-06"
