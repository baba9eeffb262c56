"""``python -m proofs_checks`` run options (issue 20): ``--h`` and ``--t-end`` are refused in one
line unless finite, > 0 and with a finite inverse; the extreme accepted values run. (In the
mutation-test selection of ``proofs_checks/cli.py``.)"""

from __future__ import annotations

import numpy as np
import pytest
from cli_exit import ExitCode

from observer.validation import INV_MIN
from proofs_checks.cli import main as proofs_main


@pytest.mark.parametrize("argv, line", [
    (["--h", "1e-320"], "error: --h: must be finite with a finite inverse, got 1e-320"),
    (["--t-end", "inf"], "error: --t-end: must be finite with a finite inverse, got inf"),
    (["--h", "0"], "error: --h: must be > 0, got 0.0"),
    (["--t-end", "nan"], "error: --t-end: must be > 0, got nan"),
    (["--h", "fast"], "error: argument --h: invalid float value: 'fast' (see --help)"),
])
def test_proofs_checks_run_options_are_refused_in_one_line(argv, line, capsys):
    with ExitCode() as code:                    # argparse errors exit through SystemExit
        code.value = proofs_main(["double_mass", "--only", "mass_spd", *argv])
    out, err = capsys.readouterr()
    assert code.value == 2 and err.splitlines() == [line] and out == ""


def test_proofs_checks_accepts_the_extreme_finite_run_options(capsys):
    """The boundaries: the smallest h whose inverse is finite, the largest finite t_end."""
    assert proofs_main(["double_mass", "--only", "mass_spd", "--h", repr(INV_MIN),
                        "--t-end", repr(float(np.finfo(float).max))]) == 0
    assert "mass_spd" in capsys.readouterr().out
