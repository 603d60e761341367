"""EN 50318 statistics on analytic signals (panto.catenary_cosim.statistics)."""
import math

import numpy as np
import pytest

from panto.catenary_cosim.statistics import (STATISTIC_KEYS, compute_statistics, lowpass_filter,
                                       sample_rate)

RATE = 2000.0  # Hz


def _time(seconds: float) -> np.ndarray:
    return np.arange(int(round(seconds * RATE))) / RATE


def test_sine_statistics_and_50hz_component_removed():
    # 120 N mean, a 2 Hz sine of 30 N (kept by the 20 Hz filter) and a 50 Hz sine of 10 N
    # (removed): mean 120, std 30/sqrt(2), max/min 120 +- 30, stat max/min 120 +- 3 * 21.2
    t = _time(12.0)
    force = 120.0 + 30.0 * np.sin(2 * np.pi * 2.0 * t) + 10.0 * np.sin(2 * np.pi * 50.0 * t)
    section = (t >= 2.0) & (t < 10.0)  # whole periods of both sines, away from the ends
    stats = compute_statistics(t, force, section=section)
    sigma = 30.0 / math.sqrt(2.0)
    assert stats.mean == pytest.approx(120.0, abs=0.02)
    assert stats.std == pytest.approx(sigma, rel=1e-3)
    assert stats.stat_max == pytest.approx(120.0 + 3 * sigma, rel=1e-3)
    assert stats.stat_min == pytest.approx(120.0 - 3 * sigma, rel=1e-2)
    assert stats.max == pytest.approx(150.0, abs=0.05)
    assert stats.min == pytest.approx(90.0, abs=0.05)
    assert stats.loss_pct == 0.0
    # without the filter the 50 Hz part would add 10 N to the maximum: it is really removed
    assert np.max(force[section]) > 155.0


def test_filter_gain_is_butterworth_squared():
    # forward-backward 4th-order digital Butterworth (bilinear, prewarped):
    # |H|^2 = 1 / (1 + (tan(pi f / fs) / tan(pi 20 / fs))^8); -6 dB at the cut-off
    t = _time(20.0)
    for frequency in (10.0, 20.0, 30.0):
        filtered = lowpass_filter(np.sin(2 * np.pi * frequency * t), RATE)
        middle = slice(int(5 * RATE), int(15 * RATE))
        amplitude = math.sqrt(2.0) * np.std(filtered[middle])
        ratio = math.tan(math.pi * frequency / RATE) / math.tan(math.pi * 20.0 / RATE)
        assert amplitude == pytest.approx(1.0 / (1.0 + ratio ** 8), rel=1e-3)


def test_filter_is_zero_phase():
    t = _time(10.0)
    signal = np.sin(2 * np.pi * 5.0 * t)
    filtered = lowpass_filter(signal, RATE)
    middle = slice(int(2 * RATE), int(8 * RATE))
    # a delayed copy would correlate best at a non-zero lag; zero phase gives lag 0
    lags = range(-20, 21)
    best = max(lags, key=lambda k: np.dot(np.roll(filtered, k)[middle], signal[middle]))
    assert best == 0


def test_known_zero_force_fraction():
    # F = max(0, 50 + 100 sin(2 pi t)) is zero where sin < -1/2: one third of the time
    t = _time(10.0)
    force = np.maximum(0.0, 50.0 + 100.0 * np.sin(2 * np.pi * 1.0 * t))
    stats = compute_statistics(t, force)
    assert stats.loss_pct == pytest.approx(100.0 / 3.0, abs=0.05)


def test_loss_counted_on_raw_force_in_section_only():
    t = _time(4.0)
    force = np.full(t.shape, 100.0)
    force[(t >= 1.0) & (t < 1.1)] = 0.0        # 0.1 s loss inside the section
    force[(t >= 3.5) & (t < 3.9)] = 0.0        # outside the section: not counted
    section = (t >= 0.5) & (t < 2.5)
    stats = compute_statistics(t, force, section=section)
    assert stats.loss_pct == pytest.approx(100.0 * 0.1 / 2.0, abs=0.06)


def test_uplift_and_keys():
    t = _time(2.0)
    uplift = np.column_stack([0.01 * np.sin(t), 0.052 * np.sin(2 * t) ** 2])
    stats = compute_statistics(t, 100.0 + 0 * t, support_uplift=uplift)
    assert stats.uplift_max_mm == pytest.approx(1000 * np.max(uplift))
    assert tuple(stats.to_dict()) == STATISTIC_KEYS
    assert set(STATISTIC_KEYS) == {"mean", "std", "stat_max", "stat_min", "max", "min",
                                   "uplift_max_mm", "loss_pct"}


def test_bad_input_is_refused():
    t = _time(1.0)
    with pytest.raises(ValueError, match="uniformly"):
        sample_rate(np.concatenate([t[:10], t[11:]]))
    with pytest.raises(ValueError, match="too low"):
        lowpass_filter(np.ones(100), 30.0)
    with pytest.raises(ValueError, match="section"):
        compute_statistics(t, 0 * t, section=np.zeros(t.shape, bool))
