"""The demo's overview: a vector figure drawn from the steps' data, units on every axis, legends
off the data, and no start-up spike setting the scale."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from panto.overview import draw_overview, thin, write_overview

SPIKE = 350.0  # [N], the start-up transient of a co-simulation at t = 0


def _demo_folder(out):
    """A demo folder with the data two steps save: identification fit series and the cosim."""
    t = np.arange(0.0, 10.0, 0.02)
    force = 100 + 20 * np.sin(2 * np.pi * 0.5 * t)
    simulated = force + 2.0
    simulated[:3] = SPIKE  # the model's start-up transient
    (out / "identification").mkdir(parents=True)
    pd.DataFrame({"time [s]": t, "F_c_measured [N]": force, "F_c_simulated [N]": simulated,
                  "y_cb_measured [m]": 2 + 0.01 * np.sin(t), "y_cb_simulated [m]":
                  2 + 0.01 * np.sin(t) + 1e-3}).to_csv(
        out / "identification" / "fit_validation.csv", index=False)
    position = np.arange(0.0, 600.0, 0.5)
    contact = 120 + 30 * np.sin(2 * np.pi * position / 60.0)
    contact[position < 5.0] = SPIKE
    (out / "cosim").mkdir()
    pd.DataFrame({"time [s]": position / 83.3, "position [m]": position,
                  "contact_force [N]": contact}).to_csv(out / "cosim" / "en50318-2002_300kmh.csv",
                                                         index=False)
    (out / "cosim" / "en50318-2002_300kmh.csv.json").write_text(json.dumps(
        {"section_m": [240.0, 360.0], "support_positions_m": [240.0, 300.0, 360.0],
         "statistics": {"mean": float(contact[(position >= 240) & (position <= 360)].mean())}}))
    return {"identification": {"pareto": {"objectives": [[60.0, 10.0], [40.0, 30.0],
                                                         [-500.0, 50.0]],
                                          "objective_names": ["y_cb", "F_c"],
                                          "knee_fit": {"y_cb": 40.0, "F_c": 30.0},
                                          "polished_fit": {"y_cb": 62.0, "F_c": 34.0}}},
            "doe": {"table": [{"parameter": "m1", "value": 22.0, "std_designed": 2.0,
                               "std_conventional": 6.0}]},
            "cosim": {"line": "en50318-2002", "speed_kmh": 300.0}}


def test_overview_is_vector_with_units_and_no_spike(tmp_path):
    summary = _demo_folder(tmp_path)
    png = write_overview(tmp_path, summary)
    svg = (tmp_path / "overview.svg").read_text()
    assert png.is_file() and (tmp_path / "overview.pdf").stat().st_size > 0
    assert "<image" not in svg  # drawn, not a picture of pictures
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    figure = draw_overview(tmp_path, summary)
    FigureCanvasAgg(figure)
    figure.draw_without_rendering()
    axes = [a for sub in figure.subfigs if sub.get_visible() for a in sub.axes]
    assert len(axes) == 5  # fit (two outputs), Pareto, DoE, contact force; no data, no panel
    renderer = figure.canvas.get_renderer()
    for axis in axes:
        assert "[" in axis.get_ylabel(), axis.get_ylabel()
        if axis.get_xlabel():  # the upper of two stacked axes shares the lower one's
            assert "[" in axis.get_xlabel() or axis.get_xlabel() == "parameter"
        legend = axis.get_legend()
        if legend is not None:  # above the frame, not on the data
            box, frame = legend.get_window_extent(renderer), axis.get_window_extent(renderer)
            assert box.y0 >= frame.y1 - 1.0
    force_axis = next(a for a in axes if a.get_ylabel() == "contact force [N]")
    low, high = force_axis.get_ylim()
    assert high < SPIKE and low < 90.0 and high > 150.0  # the section's range, not the spike
    assert force_axis.get_xlim()[0] >= 240.0 - 12.0
    fit_axis = next(a for a in axes if a.get_ylabel() == "F_c [N]")
    assert fit_axis.get_ylim()[1] < SPIKE and fit_axis.get_ylim()[1] > 122.0
    assert "start-up" in next(a for a in axes if a.get_xlabel().startswith("time")).get_xlabel()


def test_overview_without_data_is_none(tmp_path):
    assert write_overview(tmp_path, {}) is None


def test_thinning_keeps_the_envelope():
    x = np.linspace(0, 1, 100_001)
    y = np.sin(2 * np.pi * 50 * x)
    y[12_345] = 7.0  # a single-sample peak survives
    xs, ys = thin(x, y, 1000)
    assert len(xs) <= 1000 and np.all(np.diff(xs) > 0)
    assert ys.max() == 7.0 and ys.min() == pytest.approx(-1.0, abs=1e-3)


def test_overview_laid_out_once_looks_as_laid_out_per_save_and_draws_once_per_format(
        tmp_path, monkeypatch):
    from matplotlib.figure import Figure
    from matplotlib.image import imread

    summary = _demo_folder(tmp_path)
    independent = draw_overview(tmp_path, summary)  # its own constrained layout in savefig
    independent.savefig(tmp_path / "per_save.png", dpi=100)
    draws = []
    original = Figure.draw
    monkeypatch.setattr(Figure, "draw", lambda self, renderer: (draws.append(self),
                                                                original(self, renderer))[1])
    png = write_overview(tmp_path, summary)
    assert len(draws) == 3  # SVG, PDF, PNG: no second (layout) draw per save
    assert (tmp_path / "overview.svg").stat().st_size > 0
    np.testing.assert_array_equal(imread(png), imread(tmp_path / "per_save.png"))
