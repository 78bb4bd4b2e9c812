"""``train.plots``: the evaluation's figures are written whatever the recorded episode did (a robot that never lands
in the window, one that falls at once)."""

from __future__ import annotations

import numpy as np
import pytest

from train.plots import plot_hops, plot_push_curve


def _hop_series(steps: int, landings: tuple = ()) -> dict:
    impulse = np.zeros((steps, 2))
    for k in landings:
        impulse[k] = (0.5, 6.0)
    return {"hop": {"com_height": list(np.linspace(0.78, 0.9, steps)), "target": 0.88}, "mode": ["stick"] * steps,
            "contact_force": np.ones((steps, 2)), "weight": 147.15, "impulse": impulse}


@pytest.mark.parametrize("landings", [(), (40, 110)])
def test_hop_figure_with_and_without_landings(tmp_path, landings):
    series = {"standing": _hop_series(300), "hopping": _hop_series(300, landings), "fell at once": _hop_series(1)}
    path = plot_hops(series, tmp_path / "hops.png", dt=0.01)
    assert path.is_file() and path.stat().st_size > 1000


def test_push_curve_figure_with_a_controller_that_never_reaches_90_percent(tmp_path):
    rows = [{"impulse": 1.0, "survival_rate": 0.5}, {"impulse": 2.0, "survival_rate": 0.0}]
    path = plot_push_curve({"weak": rows, "strong": [dict(r, survival_rate=1.0) for r in rows]}, {"weak": 0.0, "strong": 2.0},
                           tmp_path / "push_curve.png")
    assert path.is_file() and path.stat().st_size > 1000
