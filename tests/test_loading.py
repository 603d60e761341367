"""Loading identification data from files: the library function against data built by hand."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from panto.identification.data.datasets import data_from_dataset
from panto.identification.data.loading import (LoadOptions, load_identification_data,
                                               read_table, select_rows)
from panto.identification.data.preprocessing import decimate_zero_phase
from panto.identification.estimation.base import IdentificationData
from panto.rig.dataset import Dataset, RunMetadata

RATE = 200.0


def _columns(n: int = 400) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(3)
    drive = np.cumsum(rng.standard_normal(n)) * 0.01
    return {"drive": drive, "response": np.convolve(drive, [0.5, 0.3, 0.2])[:n]}


def _write_csv(path, columns, time=None) -> None:
    names = ([] if time is None else ["time"]) + list(columns)
    values = ([] if time is None else [time]) + list(columns.values())
    rows = [",".join(names)] + [",".join(f"{v:.6f}" for v in row) for row in zip(*values)]
    path.write_text("\n".join(rows) + "\n")


def _assert_same(data: IdentificationData, expected: IdentificationData) -> None:
    assert data.input_names == expected.input_names
    assert data.output_names == expected.output_names
    assert np.allclose(data.time, expected.time, rtol=0, atol=1e-12)
    assert np.allclose(data.inputs, expected.inputs, rtol=0, atol=1e-12)
    assert np.allclose(data.outputs, expected.outputs, rtol=0, atol=1e-12)


def _by_hand(columns, period, rows=slice(None)) -> IdentificationData:
    u = np.round(columns["drive"], 6)[rows, None]
    y = np.round(columns["response"], 6)[rows, None]
    return IdentificationData(np.arange(len(u)) * period, u, y, ("u",), ("y",))


def test_a_table_with_a_time_column_gives_the_hand_built_data(tmp_path):
    columns = _columns()
    _write_csv(tmp_path / "run.csv", columns, time=np.arange(400) / RATE)
    options = LoadOptions(inputs={"u": "drive"}, outputs={"y": "response"})
    data = load_identification_data(tmp_path / "run.csv", options)
    _assert_same(data, _by_hand(columns, 1 / RATE))
    assert data.source == str(tmp_path / "run.csv")


def test_a_table_without_time_uses_the_sample_rate_and_the_rows(tmp_path):
    columns = _columns()
    _write_csv(tmp_path / "run.csv", columns)
    rows = slice(50, 300)
    options = LoadOptions(inputs={"u": "drive"}, outputs={"y": "response"}, sample_rate=RATE,
                          rows=rows)
    _assert_same(load_identification_data(tmp_path / "run.csv", options),
                 _by_hand(columns, 1 / RATE, rows))
    with pytest.raises(ValueError, match="no time column; give --sample-rate"):
        load_identification_data(tmp_path / "run.csv", LoadOptions(
            inputs={"u": "drive"}, outputs={"y": "response"}))


def test_decimation_is_an_eighth_order_zero_phase_butterworth(tmp_path):
    columns = _columns(800)
    _write_csv(tmp_path / "run.csv", columns, time=np.arange(800) / RATE)
    options = LoadOptions(inputs={"u": "drive"}, outputs={"y": "response"}, rate=RATE / 4)
    data = load_identification_data(tmp_path / "run.csv", options)
    sos = signal.butter(8, 0.8 / 4, output="sos")  # 0.8 of the new Nyquist frequency
    full = _by_hand(columns, 1 / RATE)
    expected = IdentificationData(full.time[::4],
                                  signal.sosfiltfilt(sos, full.inputs, axis=0)[::4],
                                  signal.sosfiltfilt(sos, full.outputs, axis=0)[::4],
                                  ("u",), ("y",))
    _assert_same(data, expected)
    assert data.sample_period == pytest.approx(4 / RATE)
    assert np.array_equal(decimate_zero_phase(full.inputs, 1), full.inputs)


def test_a_product_dataset_goes_through_data_from_dataset(tmp_path):
    columns = _columns()
    dataset = Dataset(np.arange(400) / RATE, columns, {"drive": "V", "response": "m"},
                      RunMetadata(sample_rate=RATE, source="emulator"))
    path = dataset.write(tmp_path / "run.csv")
    options = LoadOptions(inputs={"u": "drive"}, outputs={"y": "response"}, rows=slice(10, 90))
    data = load_identification_data(path, options)
    expected = select_rows(data_from_dataset(dataset, inputs={"u": "drive"},
                                             outputs={"y": "response"}, rate=None),
                           slice(10, 90))
    _assert_same(data, expected)
    assert data.units == {"u": "V", "y": "m"}


def test_clear_errors_name_the_file_and_the_columns(tmp_path):
    _write_csv(tmp_path / "run.csv", _columns(), time=np.arange(400) / RATE)
    with pytest.raises(ValueError, match="--inputs and --outputs name the columns"):
        load_identification_data(tmp_path / "run.csv", LoadOptions(inputs={"u": "drive"}))
    with pytest.raises(ValueError, match=r"run.csv: no column\(s\) \['force'\]"):
        load_identification_data(tmp_path / "run.csv", LoadOptions(
            inputs={"u": "drive"}, outputs={"y": "force"}))
    assert sorted(read_table(tmp_path / "run.csv")) == ["drive", "response", "time"]


def test_lowpass_removes_what_lies_above_its_cut_off_and_keeps_the_band_below():
    t = np.arange(4000) / 1000.0
    slow, fast = np.sin(2 * np.pi * 5 * t), 0.5 * np.sin(2 * np.pi * 200 * t)
    table = {"time": t, "u": slow + fast, "y": 2 * slow}
    options = LoadOptions(inputs={"u": "u"}, outputs={"y": "y"}, lowpass=25.0,
                          rows=slice(200, -200))
    data = load_identification_data(table, options)
    assert len(data) == 3600 and data.time[0] == 0.0
    # 5 Hz lies far below the 4th-order 25 Hz cut-off (gain 1 - 1e-5 after two passes); 200 Hz far
    # above it (gain (25/200)^8 ~ 6e-8)
    assert np.max(np.abs(data.inputs[:, 0] - slow[200:-200])) < 1e-3
    assert np.max(np.abs(data.outputs[:, 0] - 2 * slow[200:-200])) < 1e-3
    with pytest.raises(ValueError, match="Nyquist"):
        load_identification_data(table, LoadOptions(inputs={"u": "u"}, outputs={"y": "y"},
                                                    lowpass=600.0))
    with pytest.raises(ValueError, match="positive"):
        LoadOptions(lowpass=-1.0)
