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
