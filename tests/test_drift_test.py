"""The residual drift test (identification/diagnosis/support.py ``drift_test``): its false alarms
on stationary coloured residuals, and its power against a gain that swings within the record,
which a trend test alone misses."""
from __future__ import annotations

import numpy as np
from scipy import signal

from panto.identification.diagnosis.support import drift_test

RATE, SECONDS = 50.0, 20.0


def _record(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A prediction (a mean of 100 plus a random multisine, like a contact force) and coloured
    measurement noise (white noise through a first-order low pass at 5 Hz, 1 % of the
    prediction's spread)."""
    t = np.arange(int(RATE * SECONDS)) / RATE
    frequencies = rng.uniform(0.2, 8.0, 6)
    y_hat = 100.0 + sum(5.0 * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
                        for f in frequencies)
    b, a = signal.butter(1, 5.0 / (RATE / 2))
    noise = signal.lfilter(b, a, rng.standard_normal(len(t)))
    return t, y_hat, 0.01 * np.std(y_hat) * noise / np.std(noise)


def test_stationary_residuals_rarely_drift():
    """300 stationary records: each term is tested by a trend and a swing test at alpha = 0.01
    with Bonferroni over the two terms, so at most 2 % of the records should be flagged (6 of
    300); allowed up to 14 (the binomial's 3-sigma range about 6)."""
    rng = np.random.default_rng(7)
    flagged = 0
    for _ in range(300):
        _, _, noise = _record(rng)
        y_hat = _record(rng)[1]
        flagged += bool(drift_test(noise, y_hat))
    assert flagged <= 14, flagged


def test_a_gain_swinging_within_the_record_is_found():
    """The measured force is the true one times ``1 + 0.05 sin(2 pi t / 14 s + phi)`` (the
    benchmark families' time-varying sensor gain, a swing of one to one and a half periods in
    the record): found for nearly every phase; the trend test alone (the serial test switched
    off by too few blocks) misses many of them."""
    rng = np.random.default_rng(11)
    both, trend_only, cases = 0, 0, 40
    for phase in np.linspace(0.0, 2 * np.pi, cases, endpoint=False):
        t, y_hat, noise = _record(rng)
        measured = y_hat * (1.0 + 0.05 * np.sin(2 * np.pi * t / 14.0 + phase)) + noise
        residual = measured - y_hat
        both += bool(drift_test(residual, y_hat))
        trend_only += bool(drift_test(residual, y_hat, serial_blocks=2))
    assert both >= cases - 2, (both, trend_only)
    assert trend_only <= cases // 2, (both, trend_only)
