"""Behaviour of :class:`panto.fmu_src.response.TimeResponse`: access, files, resampling, checks, plots."""
from __future__ import annotations

import json
import pickle

import numpy as np
import pytest

from panto.fmu_src.dataformat import format_header, metadata_path_for, parse_header
from panto.fmu_src.response import TimeResponse, is_close


@pytest.fixture
def response() -> TimeResponse:
    """A damped oscillation and the force it implies, on an uneven time grid."""
    time = np.concatenate([np.linspace(0.0, 0.5, 51), np.linspace(0.51, 2.0, 40)])
    x = 0.01 * np.exp(-time) * np.cos(2 * np.pi * time)
    return TimeResponse(time, {"x": x, "F_c": 120.0 - 5000.0 * x, "xi": 0.5 + 0 * time},
                        units={"x": "m", "F_c": "N", "xi": "1"},
                        metadata={"model": "Toy", "interface": "ME",
                                  "parameters": {"k": 5000.0, "c": 20.0}})


def test_index_by_name_and_names_keep_order(response):
    assert response.names == ("x", "F_c", "xi")
    assert np.array_equal(response["F_c"], 120.0 - 5000.0 * response["x"])
    assert response["time"] is response.time
    assert "x" in response and "y" not in response
    assert len(response) == response.time.size


def test_unknown_name_lists_the_valid_ones(response):
    with pytest.raises(KeyError, match=r"'y'.*\['x', 'F_c', 'xi'\]"):
        response["y"]


def test_response_is_immutable_and_owns_its_arrays():
    x = np.array([1.0, 2.0, 3.0])
    response = TimeResponse([0.0, 1.0, 2.0], {"x": x})
    x[0] = 99.0
    assert response["x"][0] == 1.0
    with pytest.raises(ValueError):
        response["x"][0] = 5.0
    with pytest.raises(TypeError):
        response.signals["y"] = x
    with pytest.raises(AttributeError):
        response.time = x


def test_response_survives_pickling(response):
    # what a process-pool executor does with a result returned by a worker
    again = pickle.loads(pickle.dumps(response))
    assert is_close(again, response, rtol=0.0)
    assert dict(again.metadata) == dict(response.metadata)
    assert not again["x"].flags.writeable


def test_missing_units_are_empty_and_metadata_is_kept(response):
    plain = TimeResponse([0.0, 1.0], {"a": [1, 2], "b": [3, 4]}, units={"a": "m"})
    assert dict(plain.units) == {"a": "m", "b": ""}
    assert response.metadata["parameters"]["k"] == 5000.0


def test_to_pandas_is_indexed_by_time_with_units_in_attrs(response):
    frame = response.to_pandas()
    assert frame.index.name == "time"
    assert np.array_equal(frame.index.to_numpy(), response.time)
    assert list(frame.columns) == ["x", "F_c", "xi"]
    assert frame.attrs["units"] == {"time": "s", "x": "m", "F_c": "N", "xi": "1"}
    assert frame.attrs["metadata"]["model"] == "Toy"
    assert np.array_equal(frame["F_c"].to_numpy(), response["F_c"])


def test_csv_has_units_in_the_header_and_round_trips_exactly(response, tmp_path):
    path = response.to_csv(tmp_path / "toy.csv")
    lines = path.read_text().splitlines()
    assert lines[0] == "time [s],x [m],F_c [N],xi [1]"
    assert len(lines) == len(response) + 1
    again = TimeResponse.from_csv(path)
    assert again.names == response.names
    assert dict(again.units) == dict(response.units)
    assert np.array_equal(again.time, response.time)
    for name in response.names:
        assert np.array_equal(again[name], response[name]), name
    assert again.metadata["parameters"] == {"k": 5000.0, "c": 20.0}
    assert again.metadata["source"] == str(path)
    assert json.loads(metadata_path_for(path).read_text())["interface"] == "ME"


def test_csv_keeps_missing_samples_and_bracketed_names(tmp_path):
    response = TimeResponse([0.0, 0.1, 0.2], {"q[1]": [1.0, np.nan, 3.0], "flag": [0, 1, 0]},
                            units={"q[1]": "rad"})
    path = response.to_csv(tmp_path / "gaps.csv", write_metadata=False)
    assert path.read_text().splitlines()[:2] == ["time [s],q[1] [rad],flag", "0.0,1.0,0.0"]
    assert not metadata_path_for(path).exists()
    again = TimeResponse.from_csv(path)
    assert again.names == ("q[1]", "flag")
    assert again.units["q[1]"] == "rad" and again.units["flag"] == ""
    assert is_close(again, response)


@pytest.mark.parametrize("header, expected", [
    ("F_c [N]", ("F_c", "N")),
    ("xi", ("xi", "")),
    ("q[1] [rad]", ("q[1]", "rad")),
    ("q[1]", ("q[1]", "")),
    ("d_phi1 [rad/s]", ("d_phi1", "rad/s")),
], ids=["unit", "no-unit", "bracketed-name-with-unit", "bracketed-name", "compound-unit"])
def test_header_parsing_inverts_formatting(header, expected):
    assert parse_header(header) == expected
    assert format_header(*expected) == header


def test_from_csv_rejects_a_file_without_time_first(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("F_c [N],time [s]\n1,0\n2,1\n")
    with pytest.raises(ValueError, match=r"bad\.csv.*first column must be time"):
        TimeResponse.from_csv(path)


def test_from_csv_names_the_file_when_time_goes_backwards(tmp_path):
    path = tmp_path / "backwards.csv"
    path.write_text("time [s],x [m]\n0,1\n0.2,2\n0.1,3\n")
    with pytest.raises(ValueError, match=r"backwards\.csv.*strictly increasing"):
        TimeResponse.from_csv(path)


def test_resample_interpolates_linearly_against_an_analytic_function():
    time = np.linspace(0.0, 1.0, 2001)
    response = TimeResponse(time, {"line": 3.0 * time - 1.0, "sine": np.sin(2 * np.pi * time)},
                            units={"line": "m", "sine": "1"}, metadata={"model": "analytic"})
    new_time = np.sort(np.random.default_rng(7).uniform(0.0, 1.0, 300))
    resampled = response.resample(new_time)
    assert np.array_equal(resampled.time, new_time)
    # linear interpolation is exact for a straight line ...
    assert np.allclose(resampled["line"], 3.0 * new_time - 1.0, rtol=0, atol=1e-12)
    # ... and within h^2/8 max|f''| for a smooth function
    step = time[1] - time[0]
    bound = step**2 / 8 * (2 * np.pi) ** 2
    assert np.max(np.abs(resampled["sine"] - np.sin(2 * np.pi * new_time))) <= bound
    assert dict(resampled.units) == dict(response.units)
    assert resampled.metadata["model"] == "analytic"


def test_resample_refuses_to_extrapolate(response):
    with pytest.raises(ValueError, match="no extrapolation"):
        response.resample([0.0, 2.5])


@pytest.mark.parametrize("time, signals, message", [
    ([0.0, 1.0, 2.0], {"x": [1.0, 2.0]}, r"signal 'x' has 2 samples but time has 3"),
    ([0.0, 1.0, 1.0], {"x": [1.0, 2.0, 3.0]}, r"strictly increasing.*time\[1\]"),
    ([0.0, 2.0, 1.0], {"x": [1.0, 2.0, 3.0]}, r"strictly increasing"),
    ([0.0, np.nan], {"x": [1.0, 2.0]}, r"time must be finite"),
    ([[0.0, 1.0]], {"x": [1.0, 2.0]}, r"time must be one-dimensional"),
    ([0.0, 1.0], {"x": [[1.0, 2.0]]}, r"signal 'x' must be one-dimensional"),
    ([0.0, 1.0], {"x": ["a", "b"]}, r"signal 'x' must be numeric"),
    ([0.0, 1.0], {"time": [1.0, 2.0]}, r"'time' is reserved"),
], ids=["length-mismatch", "repeated-time", "decreasing-time", "nan-time", "2-d-time",
        "2-d-signal", "text-signal", "signal-named-time"])
def test_invalid_input_gives_a_clear_value_error(time, signals, message):
    with pytest.raises(ValueError, match=message):
        TimeResponse(time, signals)


def test_units_for_unknown_signals_are_refused():
    with pytest.raises(ValueError, match=r"units given for unknown signal\(s\) \['y'\]"):
        TimeResponse([0.0, 1.0], {"x": [1.0, 2.0]}, units={"y": "m"})


def test_plot_has_one_axis_per_signal_with_units(response):
    from matplotlib.figure import Figure

    figure = response.plot()
    assert isinstance(figure, Figure)
    assert len(figure.axes) == 3
    assert [axis.get_ylabel() for axis in figure.axes] == ["x [m]", "F_c [N]", "xi [1]"]
    assert figure.axes[-1].get_xlabel() == "time [s]"
    line = figure.axes[1].get_lines()[0]
    assert np.array_equal(line.get_ydata(), response["F_c"])


def test_plot_selected_names_and_overlay_on_existing_axes(response):
    figure = response.plot(["F_c"], label="simulated")
    assert len(figure.axes) == 1
    again = response.plot(["F_c"], ax=figure.axes, label="measured", linestyle="--")
    assert again is figure
    assert len(figure.axes[0].get_lines()) == 2
    with pytest.raises(ValueError, match="one Axes per signal"):
        response.plot(["x", "F_c"], ax=figure.axes)
    with pytest.raises(KeyError, match="no signal 'nope'"):
        response.plot(["nope"])


def test_plot_does_not_touch_pyplot(response):
    import matplotlib.pyplot as plt

    before = plt.get_fignums()
    response.plot()
    assert plt.get_fignums() == before


def test_save_plot_writes_an_image(response, tmp_path):
    path = response.save_plot(tmp_path / "toy.png", ["x", "F_c"])
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# --- one time-series type: tables with units, notebook views, conversions ----------------------

def test_to_pandas_can_name_columns_with_their_units(response):
    frame = response.to_pandas(units_in_names=True)
    assert frame.index.name == "time [s]"
    assert list(frame.columns) == ["x [m]", "F_c [N]", "xi [1]"]
    assert frame.attrs["units"]["F_c [N]"] == "N"
    assert np.array_equal(frame["F_c [N]"].to_numpy(), response["F_c"])
    plain = TimeResponse([0.0, 1.0], {"a": [1.0, 2.0]}).to_pandas(units_in_names=True)
    assert list(plain.columns) == ["a"]  # an unknown unit adds nothing


def test_html_view_is_an_escaped_table_of_signals_without_python_reprs():
    time = np.linspace(0.0, 2.0, 201)
    response = TimeResponse(time, {"<b>x</b>": np.sin(np.pi * time), "F_c": 100.0 + 0 * time,
                                   "gap": np.where(time < 1.0, np.nan, time)},
                            units={"<b>x</b>": "m", "F_c": "N"},
                            metadata={"model": "A & B", "interface": "ME"})
    page = response._repr_html_()
    assert page.count("<tr>") == 1 + 3
    assert "&lt;b&gt;x&lt;/b&gt;" in page and "<b>x" not in page
    assert "A &amp; B" in page
    # sin(pi t) on [0, 2] spans [-1, 1]; the NaN samples are counted, not shown as nan
    assert "<td>&lt;b&gt;x&lt;/b&gt;</td><td>m</td><td>-1</td><td>1</td><td>0</td>" in page
    assert f"<td>gap</td><td>?</td><td>1</td><td>2</td><td>{int(np.sum(time < 1.0))}</td>" in page
    for python_repr in ("nan", "np.float64", "None", "True", "array("):
        assert python_repr not in page


@pytest.mark.parametrize("value, text", [
    (np.float64(0.000123456), "0.0001235"), (np.int64(7), "7"), (True, "yes"), (np.bool_(False), "no"),
    (float("nan"), "—"), (None, "—"), ([1.0, 2.5], "1, 2.5"), ((), "—"), ({"k": 2.0}, "k: 2"),
    ("a<b", "a&lt;b"),
], ids=["numpy-float", "numpy-int", "bool", "numpy-bool", "nan", "none", "list", "empty",
        "mapping", "markup"])
def test_table_cells_are_plain_text(value, text):
    from panto.fmu_src.display import format_cell

    assert format_cell(value) == text


def test_html_table_refuses_a_ragged_row():
    from panto.fmu_src.display import html_table

    with pytest.raises(ValueError, match="row 1 has 1 cells for 2 headers"):
        html_table(["a", "b"], [[1, 2], [3]])


def test_identification_data_and_its_model_convert_to_responses():
    from panto.identification.estimation.base import IdentificationData, IdentificationResult

    time = np.arange(0.0, 1.0, 0.01)
    u = np.sin(2 * np.pi * time)
    data = IdentificationData(time, u[:, None], (3.0 * u)[:, None], ("eta",), ("F_c",),
                              units={"eta": "m", "F_c": "N"}, source="bench")
    measured = data.to_response()
    assert measured.names == ("eta", "F_c") and dict(measured.units) == {"eta": "m", "F_c": "N"}
    assert np.array_equal(measured["F_c"], data.output("F_c"))
    assert measured.metadata["source"] == "bench"
    gain = 2.5  # a static gain model: y = gain * u, known in closed form
    result = IdentificationResult(
        "gain", "by hand", {"gain": gain}, ("gain",), {"gain": 0.1}, np.eye(1), {"F_c": 0.0},
        True, "done", 0.0, 1, simulator=lambda d: gain * d.inputs)
    simulated = result.response(data)
    assert simulated.names == ("F_c",) and simulated.units["F_c"] == "N"
    assert np.allclose(simulated["F_c"], gain * u, rtol=0, atol=1e-15)
    figure = measured.plot(["F_c"], label="measured")
    simulated.plot(["F_c"], ax=figure.axes, label="model")
    assert len(figure.axes[0].get_lines()) == 2


def test_identification_result_html_marks_bounds_and_unidentifiable_parameters():
    from panto.identification.estimation.base import IdentificationResult
    from panto.identification.estimation.uncertainty import ParameterEstimate

    estimates = {
        "k": ParameterEstimate("k", 5000.0, "N/m", std=50.0, interval_95=(4902.0, 5098.0)),
        "m": ParameterEstimate("m", 0.5, "kg", verdict="at bound", at_bound="lower"),
        "c": ParameterEstimate("c", 20.0, "N.s/m", verdict="not identifiable", fixed=True,
                               reason="flat"),
    }
    result = IdentificationResult(
        "toy <2>", "levenberg-marquardt", {"k": 5000.0, "m": 0.5, "c": 20.0, "delay": 0.0},
        ("k", "m"), {"k": 50.0, "m": float("nan")}, np.eye(2), {"F_c": np.float64(93.456)},
        False, "stopped", 1.5, 42, simulator=lambda d: d.outputs, estimates=estimates)
    page = result._repr_html_()
    assert "toy &lt;2&gt;" in page and "FAILED: stopped" in page and "F_c 93.46 %" in page
    assert "<td>k</td><td>5000</td><td>N/m</td><td>50</td><td>[4902, 5098]</td>" in page
    assert "<td>m</td><td>0.5</td><td>kg</td><td>—</td><td>—</td><td>at lower bound</td>" in page
    assert "fixed at prior (not identifiable from this run)</td><td>not identifiable" in page
    assert "<td>delay</td><td>0</td><td></td><td>—</td><td>—</td><td>fixed</td>" in page
    for python_repr in ("nan", "np.float64", "None", "True", "False"):
        assert python_repr not in page


def test_rendered_profile_converts_to_a_response_with_units():
    from importlib.resources import files

    from panto.rig.profiles import load_profile, render_profile

    rendered = render_profile(load_profile(files("panto.rig") / "profiles" / "sine_1hz.json"))
    response = rendered.to_response()
    assert np.array_equal(response["motor_demand"],
                          response["motor_offset"] + response["motor_dynamic"])
    assert response.units["pressure_demand"] == "bar" and response.units["motor_demand"] == "m"
    assert np.array_equal(response.time, rendered.time)


def test_diagnosis_html_shows_verdict_effects_and_the_gap_closed():
    from panto.identification.diagnosis.pipeline import Diagnosis

    diagnosis = Diagnosis(
        verdict="explained", effects=("coulomb_friction",), structure="two-mass",
        output_names=("F_c",), fit_before={"F_c": 60.0}, fit_after={"F_c": 80.0},
        fit_train={"F_c": np.float64(85.0)}, nominal_parameters={}, final_parameters={},
        gap={}, remaining_gap={}, where={}, rounds=(), steps=(), summary="friction <closes> it",
        wall_time=1.0)
    page = diagnosis._repr_html_()
    # residual energy left: ((100 - 80) / (100 - 60))^2 = 1/4, so 75 % of the gap closed
    assert "<td>F_c</td><td>85</td><td>60</td><td>80</td><td>75</td>" in page
    assert "two-mass: explained" in page and "coulomb_friction" in page
    assert "friction &lt;closes&gt; it" in page and "np.float64" not in page


def test_plot_shows_as_a_picture_in_a_notebook_and_keeps_the_users_backend():
    """What IPython's display machinery asks of the last expression of a cell: a PNG; drawing it
    leaves the backend the user chose (here SVG) and never loads pyplot."""
    import subprocess
    import sys
    import textwrap

    script = textwrap.dedent("""
        import sys
        import matplotlib
        matplotlib.use("svg")
        from panto.fmu_src.response import TimeResponse
        figure = TimeResponse([0.0, 1.0, 2.0], {"F_c": [90.0, 110.0, 95.0]},
                              units={"F_c": "N"}).plot()
        picture = figure._repr_png_()
        print(picture[:4] == b"\\x89PNG", matplotlib.get_backend(), "matplotlib.pyplot" in sys.modules)
        """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["True", "svg", "False"]
