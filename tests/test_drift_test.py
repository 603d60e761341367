"""The residual drift test (identification/diagnosis/support.py ``drift_test``): its false alarms
on stationary coloured residuals, and its power against a gain that swings within the record,
which a trend test alone misses."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from panto.identification.diagnosis.support import drift_test

RATE, SECONDS = 50.0, 20.0


def _record(rng: np.random.Generator, cutoff: float = 5.0
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A prediction (a mean of 100 plus a random multisine, like a contact force) and coloured
    measurement noise (white noise through a first-order low pass at `cutoff` Hz, 1 % of the
    prediction's spread)."""
    t = np.arange(int(RATE * SECONDS)) / RATE
    frequencies = rng.uniform(0.2, 8.0, 6)
    y_hat = 100.0 + sum(5.0 * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
                        for f in frequencies)
    b, a = signal.butter(1, cutoff / (RATE / 2))
    noise = signal.lfilter(b, a, rng.standard_normal(len(t)))
    return t, y_hat, 0.01 * np.std(y_hat) * noise / np.std(noise)


def test_stationary_residuals_rarely_drift():
    """300 stationary records (noise correlated over a few samples): each term is tested by a
    trend and a swing test at alpha = 0.01 with Bonferroni over the two terms, so at most 2 % of
    the records should be flagged (6 of 300; measured 7); allowed up to 12 (the binomial's
    P(X >= 13) at 2 % is under 1 %)."""
    rng = np.random.default_rng(7)
    flagged = 0
    for _ in range(300):
        _, _, noise = _record(rng)
        y_hat = _record(rng)[1]
        flagged += bool(drift_test(noise, y_hat))
    assert flagged <= 12, flagged


def test_noise_correlated_over_the_blocks_adds_no_swing():
    """Noise low-passed at 0.3 Hz: neighbouring blocks (1.25 s) agree by the noise alone, so
    their estimates are not exchangeable. The swing test then takes fewer, longer blocks or none
    and adds at most 3 records to the trend test's own false alarms of 150 (measured 8 against
    5; with 16 blocks whatever the noise: 19)."""
    rng = np.random.default_rng(3)
    both = trend = 0
    for _ in range(150):
        _, y_hat, noise = _record(rng, cutoff=0.3)
        both += bool(drift_test(noise, y_hat))
        trend += bool(drift_test(noise, y_hat, serial_blocks=2))
    assert both <= trend + 3, (both, trend)


@pytest.mark.parametrize("swing, noise_scale, found, trend_at_most", [
    (0.05, 1.0, 38, 20),   # measured 40 and 0 of 40
    (0.005, 10.0, 20, 5),  # about 4 fit points against a 90 % noise ceiling: 28 and 1 of 40
])
def test_a_gain_swinging_within_the_record_is_found(swing, noise_scale, found, trend_at_most):
    """The measured force is the true one times ``1 + g sin(2 pi t / 14 s + phi)`` (the benchmark
    families' time-varying sensor gain, a swing of one to one and a half periods in the record):
    found for most phases; the trend test alone (the serial test switched off by too few
    blocks) misses most of them."""
    rng = np.random.default_rng(11)
    both, trend_only, cases = 0, 0, 40
    for phase in np.linspace(0.0, 2 * np.pi, cases, endpoint=False):
        t, y_hat, noise = _record(rng)
        measured = y_hat * (1.0 + swing * np.sin(2 * np.pi * t / 14.0 + phase)) + \
            noise_scale * noise
        residual = measured - y_hat
        both += bool(drift_test(residual, y_hat))
        trend_only += bool(drift_test(residual, y_hat, serial_blocks=2))
    assert both >= found, (both, trend_only)
    assert trend_only <= trend_at_most, (both, trend_only)
