"""How the report's figures are rendered (issue 22, the page's build time): one draw per figure,
no text outside the canvas (the settling matrix's long row labels, the fixed layouts), log
labels without mathtext, and the process pool giving the same PNG bytes as rendering in place.
"""

from __future__ import annotations

import base64

import numpy as np
import pandas as pd
import pytest

from reports import figures


def _outside(fig) -> list[float]:
    """How far (inches: left, bottom, right, top) what ``fig`` draws leaves its canvas: the
    figure's tight bounding box (what ``bbox_inches="tight"`` would have saved) against its
    size; all ≤ 0 when nothing is clipped."""
    fig.canvas.draw()
    bb = fig.get_tightbbox(fig.canvas.get_renderer())
    w, h = fig.get_size_inches()
    return [-bb.x0, -bb.y0, bb.x1 - w, bb.y1 - h]


@pytest.fixture
def captured(monkeypatch):
    """The figures passed to rendering, laid out as rendering lays them out, not closed."""
    figs = []

    def keep(fig, fit):
        figures._tidy_log_axes(fig.axes)
        if fit and fig.get_layout_engine() is None:
            fig.tight_layout()
        figs.append(fig)
        return "data:image/png;base64,"
    monkeypatch.setattr(figures, "_render", keep)
    yield figs
    for f in figs:
        figures.plt.close(f)


def _matrix(rows: list[str]) -> pd.DataFrame:
    recs = []
    for i, label in enumerate(rows):
        for j, d in enumerate(("jump", "nojump", "jump_mass", "jump_identity")):
            med = np.inf if (i + j) % 3 == 0 else 1.5 + i + j
            recs.append({"label": label, "integrator": "time-stepping", "design": d, "rho": 1e-6,
                         "n": 100, "median": med, "q10": 1.0, "q90": np.inf, "never": 0.3 * np.isinf(med)})
    return pd.DataFrame(recs)


def test_settling_matrix_labels_stay_on_the_canvas(captured):
    """Long row labels (a random system with the projected master) and the colour bar fit."""
    rows = ["double_mass", "random_system (seed 41, 8 DOF, 4 contacts) (projected master)",
            "persistent contact (double_mass, F = 0)"]
    assert figures.settling_matrix_figure(_matrix(rows)) is not None
    (fig,) = captured
    assert max(_outside(fig)) <= 0.01
    labels = [t.get_text() for t in fig.axes[0].get_yticklabels()]
    assert any("\n" in s for s in labels)                      # the long one wrapped
    assert [s.replace("\n", " ") for s in labels] == [f"{r} · time-stepping" for r in rows]


def test_fixed_layout_scenario_figure_stays_on_the_canvas(captured):
    t = np.linspace(0.0, 10.0, 400)
    V = 0.06 * np.exp(-2.0 * t)
    traj = pd.DataFrame({"t": t, "master_g": np.abs(np.sin(t)) * 0.02, "master_q": -0.25 + 0 * t,
                         "jump_g": np.abs(np.sin(t)) * 0.021, "jump_q": -0.24 + 0 * t, "V_jump": V,
                         "nojump_g": np.abs(np.sin(t)) * 0.03, "nojump_q": -0.23 + 0 * t,
                         "V_nojump": V * np.exp(t)})
    assert figures.scenario_figure(traj, "double_mass", ["jump", "nojump"], (0.0, 10.0),
                                   "q₁ (m)", "gap (m)") is not None
    (fig,) = captured
    assert max(_outside(fig)) <= 0.01
    labels = [t.get_text() for t in fig.axes[2].get_yticklabels() if t.get_text()]
    assert labels and all(s.startswith("10") and "$" not in s for s in labels)   # no mathtext


@pytest.mark.parametrize("x,text", [(1e-6, "10⁻⁶"), (1.0, "10⁰"), (1e3, "10³"), (2e-6, "2e-06"),
                                    (0.0, ""), (-1.0, "")])
def test_decade_labels(x, text):
    assert figures.decade_label(x) == text


def _figure():
    fig, ax = figures.plt.subplots(figsize=(4, 3))
    ax.semilogy(np.arange(50), np.exp(-np.arange(50) / 5.0), label="V")
    ax.legend()
    ax.set_title("a title")
    return fig


def test_parallel_rendering_gives_the_same_png_as_rendering_in_place():
    """The pool renders the pickled figure with the same code: the same bytes (the property)."""
    here = figures.to_data_uri(_figure())
    with figures.parallel_rendering(2):
        pending = figures.to_data_uri(_figure())
        assert isinstance(pending, figures.Pending)
        fig = figures.resolve(figures.Figure(pending, "alt"))
    assert isinstance(fig.src, str) and fig.src == here
    png = base64.b64decode(here.split(",", 1)[1])
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert not figures._POOL                                   # the pool is gone after the block
