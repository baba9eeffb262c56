"""Assertion helpers for users' own pytest suites: one ``assert_<check>`` per registered check.

Each helper runs its check and raises :class:`AssertionError` when it fails, with a
readable message carrying the margin, the tolerance and the witness; it returns the
:class:`~proofs_checks.result.CheckResult` otherwise. Two ways to call it:

* with the check function's own ingredients (matrices, a law, a run), e.g.
  ``assert_projection_psd(K, W, rng=np.random.default_rng(0))``;
* with a scenario (built-in name, TOML path or :class:`~observer.scenario.Scenario`) as the
  only positional argument: the check runs as in :func:`proofs_checks.run_checks` (same
  runs and horizons), with ``seed``, ``h``, ``t_end``, ``overrides`` and the other keywords
  passed as the check's options, e.g. ``assert_impact_monotone("my.toml", samples=200)``.

A check that is not applicable (``passed is None``) passes unless
``allow_not_applicable=False``. :func:`assert_checks` runs several checks at once and
reports every failure.

Example (a whole test)::

    import proofs_checks

    def test_my_oscillator_satisfies_the_theorem():
        proofs_checks.assert_checks("my_oscillator.toml", seed=1)
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

from observer.scenario import Scenario
from proofs_checks.assumptions import (check_constraints_independent, check_damping_pd, check_mass_spd,
                                       check_stiffness_spd)
from proofs_checks.designs import check_projection_energy
from proofs_checks.forcing import check_forcing_bounded
from proofs_checks.lyapunov import check_convergence, check_lyapunov_decrease
from proofs_checks.monotonicity import check_impact_monotone
from proofs_checks.projection import check_projection_closed_form, check_projection_psd
from proofs_checks.proposition import check_proposition1_exact, check_proposition1_h_scaling
from proofs_checks.registry import results_frame, run_checks
from proofs_checks.result import CheckResult
from proofs_checks.switching import check_switching_generated


def assert_result(result: CheckResult, *, allow_not_applicable: bool = True) -> CheckResult:
    """Raise :class:`AssertionError` (message: :meth:`CheckResult.message`) unless the check passed."""
    __tracebackhide__ = True
    if result.passed is False:
        where = f" on {result.scenario}" if result.scenario else ""
        raise AssertionError(f"proof check {result.name} failed{where}: margin {result.margin:.4g} "
                             f"(tolerance {result.tolerance:.3g}); {result.summary(200)}\n" + result.message())
    if result.passed is None and not allow_not_applicable:
        raise AssertionError(f"proof check {result.name} is not applicable: {result.reason}\n" + result.message())
    return result


def assert_checks(scenario: str | Path | Scenario, only=None, *, allow_not_applicable: bool = True,
                  **kwargs: Any) -> list[CheckResult]:
    """Run :func:`proofs_checks.run_checks` and raise one AssertionError listing every failure.

    The message starts with the results table (check, status, margin, tolerance, witness)
    and then gives each failed check's full witness. Returns the results otherwise.
    """
    results = run_checks(scenario, only, **kwargs)
    bad = [r for r in results if r.passed is False or (r.passed is None and not allow_not_applicable)]
    if bad:
        table = results_frame(results)[["check", "status", "margin", "tolerance", "witness"]]
        text = table.to_string(index=False, max_colwidth=70, float_format=lambda x: f"{x:.3g}")
        raise AssertionError(f"{len(bad)} of {len(results)} proof checks failed on {results[0].scenario}: "
                             f"{', '.join(r.name for r in bad)}\n{text}\n\n"
                             + "\n\n".join(r.message() for r in bad))
    return results


def _helper(name: str, fn: Callable[..., CheckResult]) -> Callable[..., CheckResult]:
    def helper(*args: Any, allow_not_applicable: bool = True, **kwargs: Any) -> CheckResult:
        __tracebackhide__ = True
        if len(args) == 1 and isinstance(args[0], (str, Path, Scenario)):
            run_kw = {k: kwargs.pop(k) for k in ("seed", "h", "t_end", "overrides") if k in kwargs}
            res = run_checks(args[0], [name], options={name: kwargs} if kwargs else None, **run_kw)[0]
        else:
            res = fn(*args, **kwargs)
        return assert_result(res, allow_not_applicable=allow_not_applicable)

    helper.__name__ = helper.__qualname__ = f"assert_{name}"
    helper.__doc__ = (f"Assert that :func:`{fn.__module__}.{fn.__name__}` passes.\n\n"
                      f"Call it with that function's arguments, or with a scenario (name, TOML path\n"
                      f"or Scenario) and keyword options; raises AssertionError with the margin and\n"
                      f"the witness. See :mod:`proofs_checks.asserts`.\n\n"
                      f"Checked: {next(iter((fn.__doc__ or '').strip().splitlines()), '')}")
    return helper


assert_mass_spd = _helper("mass_spd", check_mass_spd)
assert_stiffness_spd = _helper("stiffness_spd", check_stiffness_spd)
assert_damping_pd = _helper("damping_pd", check_damping_pd)
assert_constraints_independent = _helper("constraints_independent", check_constraints_independent)
assert_switching_generated = _helper("switching_generated", check_switching_generated)
assert_forcing_bounded = _helper("forcing_bounded", check_forcing_bounded)
assert_impact_monotone = _helper("impact_monotone", check_impact_monotone)
assert_projection_closed_form = _helper("projection_closed_form", check_projection_closed_form)
assert_projection_psd = _helper("projection_psd", check_projection_psd)
assert_projection_energy = _helper("projection_energy", check_projection_energy)
assert_proposition1_exact = _helper("proposition1_exact", check_proposition1_exact)
assert_proposition1_h_scaling = _helper("proposition1_h_scaling", check_proposition1_h_scaling)
assert_lyapunov_decrease = _helper("lyapunov_decrease", check_lyapunov_decrease)
assert_convergence = _helper("convergence", check_convergence)

__all__ = ["assert_checks", "assert_result", "assert_mass_spd", "assert_stiffness_spd", "assert_damping_pd",
           "assert_constraints_independent", "assert_switching_generated", "assert_forcing_bounded",
           "assert_impact_monotone", "assert_projection_closed_form", "assert_projection_psd",
           "assert_projection_energy",
           "assert_proposition1_exact", "assert_proposition1_h_scaling", "assert_lyapunov_decrease",
           "assert_convergence"]
