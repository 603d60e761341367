"""Preprocessing of section 4.2: zero-phase low-pass, 500 -> 50 Hz, the aliasing check."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from panto.identification.data.plots import plot_aliasing_check
from panto.identification.data.preprocessing import (PreprocessingError, check_aliasing, design_lowpass,
                                          lowpass_zero_phase, resample_dataset)
from panto.rig.dataset import Dataset, RunMetadata


def _dataset(rate: float, duration: float, channels, unit: str = "N") -> Dataset:
    time = np.arange(int(round(duration * rate))) / rate
    values = {name: function(time) for name, function in channels.items()}
    units = {name: unit for name in channels}
    return Dataset(time, values, units, RunMetadata(sample_rate=rate, source="emulator"))


def _amplitude_phase(x: np.ndarray, time: np.ndarray, frequency: float) -> complex:
    """Complex amplitude of `frequency` by least squares (cos, sin)."""
    basis = np.column_stack([np.cos(2 * np.pi * frequency * time),
                             np.sin(2 * np.pi * frequency * time), np.ones_like(time)])
    (a, b, _), *_ = np.linalg.lstsq(basis, x, rcond=None)
    return complex(a, -b)  # x = Re(c exp(j w t))


def test_design_meets_its_figures_on_the_frequency_response():
    design = design_lowpass(500.0)
    _, response = signal.sosfreqz(design.sos, worN=[design.passband, design.stopband, 30.0],
                                  fs=500.0)
    zero_phase_db = 20 * np.log10(np.abs(response) ** 2)  # forward + backward
    assert zero_phase_db[0] >= -0.1 - 1e-9
    assert zero_phase_db[1] <= -40.0
    assert zero_phase_db[2] < zero_phase_db[1]  # monotone beyond the stop band edge


def test_lowpass_keeps_5hz_without_delay_and_removes_30hz():
    rate = 500.0
    time = np.arange(0, 20.0, 1 / rate)
    slow = 1.3 * np.sin(2 * np.pi * 5.0 * time + 0.4)
    fast = 0.8 * np.sin(2 * np.pi * 30.0 * time)
    out = lowpass_zero_phase(slow + fast, rate)
    inner = slice(1000, -1000)  # away from the ends
    kept = _amplitude_phase(out[inner], time[inner], 5.0)
    truth = _amplitude_phase(slow[inner], time[inner], 5.0)
    assert abs(kept) == pytest.approx(abs(truth), rel=2e-3)
    assert abs(np.angle(kept / truth)) < 1e-3  # zero phase: no delay (< 0.03 ms at 5 Hz)
    left = _amplitude_phase(out[inner] - slow[inner], time[inner], 30.0)
    assert 20 * np.log10(abs(left) / 0.8) <= -40.0


def test_resample_500_to_50_keeps_5hz_and_removes_30hz():
    data = _dataset(500.0, 20.0, {"slow": lambda t: 2.0 * np.cos(2 * np.pi * 5.0 * t - 1.0),
                                  "fast": lambda t: 1.0 * np.sin(2 * np.pi * 30.0 * t)})
    out = resample_dataset(data, 50.0)
    assert out.metadata.sample_rate == 50.0
    assert np.allclose(np.diff(out.time), 0.02)
    assert out.time[0] == data.time[0]
    inner = slice(50, -50)
    t = out.time[inner]
    slow = _amplitude_phase(out["slow"][inner], t, 5.0)
    assert abs(slow) == pytest.approx(2.0, rel=2e-3)
    assert np.angle(slow) == pytest.approx(-1.0, abs=1e-3)
    # 30 Hz aliases to 20 Hz at 50 Hz: whatever is left anywhere is 40 dB down
    assert np.max(np.abs(out["fast"][inner])) <= 10 ** (-40 / 20)
    record = out.metadata.extra["preprocessing"][-1]
    assert record["from_rate_hz"] == 500.0 and record["to_rate_hz"] == 50.0
    assert record["filter"]["stopband_hz"] == 20.0


def test_resample_puts_nan_back_where_the_filter_touched_a_gap():
    data = _dataset(500.0, 10.0, {"laser_1": lambda t: 2.0 + 0.01 * np.sin(2 * np.pi * t)},
                    "m")
    values = np.array(data["laser_1"])
    values[2000:2050] = np.nan  # a 0.1 s dropout at 4.0 s
    gappy = Dataset(data.time, {"laser_1": values, "led": (data.time > 5).astype(float)},
                    {"laser_1": "m", "led": "1"}, data.metadata)
    out = resample_dataset(gappy, 50.0)
    design = design_lowpass(500.0)
    nan_rows = np.flatnonzero(np.isnan(out["laser_1"]))
    first, last = nan_rows[0] * 10, nan_rows[-1] * 10  # input indices of the NaN outputs
    assert first >= 2000 - design.support - 10 and first <= 2000 - design.support + 10
    assert last <= 2049 + design.support + 10 and last >= 2049 + design.support - 10
    assert np.all(np.isfinite(np.delete(out["laser_1"], nan_rows)))
    finite = np.isfinite(out["laser_1"])
    truth = 2.0 + 0.01 * np.sin(2 * np.pi * out.time)
    assert np.max(np.abs(out["laser_1"][finite] - truth[finite])) < 2e-4
    assert set(np.unique(out["led"])) <= {0.0, 1.0}  # bits are picked, not filtered


def test_resample_refuses_a_non_integer_ratio_and_a_too_high_stopband():
    data = _dataset(487.0, 2.0, {"force": np.sin})
    with pytest.raises(PreprocessingError, match="not a whole number"):
        resample_dataset(data, 50.0)
    with pytest.raises(PreprocessingError, match="Nyquist"):
        resample_dataset(_dataset(500.0, 2.0, {"force": np.sin}), 50.0, stopband=30.0)


def _force(frequencies_amplitudes, seed):
    rng = np.random.default_rng(seed)
    phases = rng.uniform(0, 2 * np.pi, len(frequencies_amplitudes))

    def force(t):
        noise = np.random.default_rng(seed + int(t.size)).normal(0.0, 0.01, t.size)
        return 80.0 + noise + sum(a * np.sin(2 * np.pi * f * t + p)
                                  for (f, a), p in zip(frequencies_amplitudes, phases))
    return force


def test_aliasing_check_flags_a_sine_above_the_lower_nyquist():
    # 245 Hz lies between 243.5 Hz (487 Hz / 2) and 250 Hz: seen at 245 Hz at 500 Hz but
    # aliased to 242 Hz at 487 Hz; 400 Hz aliases to 100 Hz and 87 Hz.
    for tone in (245.0, 400.0):
        components = [(1.0, 5.0), (3.0, 1.0), (tone, 0.5)]
        first = _dataset(500.0, 30.0, {"force": _force(components, 1)})
        second = _dataset(487.0, 30.0, {"force": _force(components, 1)})
        check = check_aliasing(first, second, "force")
        assert check.coprime and check.aliasing_suspected, check.summary()
        aliases = [abs(tone - round(tone / r) * r) for r in check.rates]
        for alias in aliases:
            if alias <= check.max_frequency:
                assert any(low <= alias <= high for low, high, _ in check.where), (alias,
                                                                                    check.where)


def test_aliasing_check_passes_a_band_limited_signal(tmp_path):
    components = [(1.0, 5.0), (3.0, 1.0), (47.0, 0.2), (180.0, 0.05)]
    first = _dataset(500.0, 30.0, {"force": _force(components, 2)})
    second = _dataset(487.0, 30.0, {"force": _force(components, 2)})
    check = check_aliasing(first, second, "force")
    assert not check.aliasing_suspected, check.summary()
    assert np.all(np.abs(check.band_difference[check.relevant]) < 1.0)
    png = plot_aliasing_check(check, str(tmp_path / "aliasing.png"))
    assert (tmp_path / "aliasing.png").stat().st_size > 10_000 and png.endswith(".png")


def test_aliasing_check_refuses_equal_rates_and_missing_channels():
    data = _dataset(500.0, 5.0, {"force": np.sin})
    with pytest.raises(PreprocessingError, match="different"):
        check_aliasing(data, data)
    with pytest.raises(PreprocessingError, match="no channel 'pressure'"):
        check_aliasing(data, _dataset(487.0, 5.0, {"force": np.sin}), "pressure")


def test_panto_preprocess_and_aliasing_check_commands(tmp_path, capsys):
    from panto.cli import main
    from panto.rig.dataset import read_dataset

    components = [(1.0, 5.0), (3.0, 1.0), (245.0, 0.5)]
    first = _dataset(500.0, 20.0, {"force": _force(components, 3)})
    second = _dataset(487.0, 20.0, {"force": _force(components, 3)})
    first.write(tmp_path / "a.csv")
    second.write(tmp_path / "b.csv")
    assert main(["preprocess", str(tmp_path / "a.csv"), "--rate", "50",
                 "--out", str(tmp_path / "a50.csv")]) == 0
    resampled = read_dataset(tmp_path / "a50.csv", required=())
    assert resampled.metadata.sample_rate == 50.0 and len(resampled) == 1000
    assert main(["aliasing-check", str(tmp_path / "a.csv"), str(tmp_path / "b.csv"),
                 "--out", str(tmp_path / "alias.png"), "--json", str(tmp_path / "a.json")]) == 1
    assert "aliasing suspected in 240-243.5 Hz" in capsys.readouterr().out
    assert (tmp_path / "alias.png").is_file() and (tmp_path / "a.json").is_file()
    assert main(["preprocess", str(tmp_path / "b.csv"), "--out", str(tmp_path / "x.csv")]) == 65
    assert "not a whole number" in capsys.readouterr().err
