"""Fixtures shared by the report tests of several modules."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def stored_model_error_section():
    """The "Model error and sensors" section of the repository's stored results
    (``reports.sections.model_error.build_from(STORED, [])``), built once for
    tests/reports/test_model_error_section.py and tests/reports/test_model_error_curves.py
    (both only read it: ≈ 2 s CPU a build, its figures most of it)."""
    from reports.sections import model_error

    return model_error.build_from(model_error.STORED, [])
