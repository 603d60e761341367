"""The Pantograph FMU's Model Exchange run locates contact loss and re-contact (issue 22).

The wire (input eta) steps up by 3 cm at t = 0.05 s while the head rests on it in equilibrium:
the head loses contact at the step (an input event) and the pantograph, pushed up by the bellow,
rises into the wire again. With the contact stiffness of EN 50318 (k_ph = 50 kN/m) the frame
overshoots, pulls the head off the wire and brings it back: contact loss and re-contact as state
events, which fmpy's CVode finds through the FMU's event indicator (the contact gap xi - eta).

The independent path is the recorded outputs themselves: the contact spring force
k_ph (xi - eta) computed from the recorded head height and wire height changes sign between two
samples of the regular output grid exactly where fmpy reports a state event, and its zero found
by a local cubic through the four nearest grid samples agrees with the reported instant.
"""
from __future__ import annotations

import numpy as np
import pytest
from fmpy import simulate_fmu

#: Contact stiffness of EN 50318 [N/m] (the parameter's description names it): stiff enough for
#: the frame's overshoot to lift the head off the wire again.
K_PH = 50000.0
ETA0, STEP, STEP_TIME, PRESSURE = 2.0, 0.03, 0.05, 4.0  # m, m, s, bar
STOP, INTERVAL = 0.6, 1e-3  # s
#: Agreement of a reported event with the zero of the cubic through the samples [s]. The cubic's
#: error is about INTERVAL^3 [g'''] / (24 |g'|): the gap's second derivative is continuous at a
#: switch (the spring force starts from zero), its third jumps by k_ph |g'| / m_c, so the error is
#: below 1e-9 s^3 * 8.3e3 s^-2 / 24 ~ 4e-7 s; 1 % of the output interval (1e-5 s, as for the
#: oscillators) leaves a factor 25.
ATOL = 1e-2 * INTERVAL


def _wire() -> np.ndarray:
    """eta(t): held at ETA0, stepping up by STEP at STEP_TIME (fmpy's repeated time = step)."""
    rows = [(0.0, ETA0, PRESSURE), (STEP_TIME, ETA0, PRESSURE),
            (STEP_TIME, ETA0 + STEP, PRESSURE), (STOP, ETA0 + STEP, PRESSURE)]
    return np.array(rows, dtype=[("time", float), ("eta", float), ("p", float)])


def _crossings(time: np.ndarray, gap: np.ndarray) -> np.ndarray:
    """Zeros of the sampled gap between grid samples of opposite sign (local cubic, 4 samples)."""
    roots = []
    for i in np.flatnonzero(np.sign(gap[:-1]) * np.sign(gap[1:]) < 0):
        window = slice(max(i - 1, 0), min(i + 3, time.size))
        cubic = np.polynomial.Polynomial.fit(time[window], gap[window], deg=3)
        real = [r.real for r in cubic.roots() if abs(r.imag) < 1e-12
                and time[i] <= r.real <= time[i + 1]]
        assert len(real) == 1, (time[i], real)
        roots.append(real[0])
    return np.array(roots)


@pytest.mark.parametrize("file", ["Pantograph.fmu", "Pantograph_fmi3.fmu"])
def test_model_exchange_locates_pantograph_contact_loss_and_recontact(project_fmus, file):
    result = simulate_fmu(str(project_fmus[file].path), fmi_type="ModelExchange", input=_wire(),
                          start_values={"unilateral_contact": True, "k_ph": K_PH},
                          output=["xi", "eta", "F_c"], relative_tolerance=1e-10,
                          output_interval=INTERVAL, stop_time=STOP)
    time, eta, force = result["time"], result["eta"], result["F_c"]
    gap = result["xi"] - eta  # the contact spring force is K_PH * gap
    repeated = np.diff(time) == 0.0  # fmpy records every event twice: before and after it
    events = time[1:][repeated]
    state_events = events[~np.isclose(events, STEP_TIME)]
    assert np.any(np.isclose(events, STEP_TIME))  # the step itself is an (input) event
    assert gap[time < STEP_TIME].min() > 0.0  # in contact until the step
    # Contact loss and re-contact: the wire must be re-touched, left and re-touched again.
    on_grid = ~np.isin(time, events)
    after = on_grid & (time > STEP_TIME)
    crossings = _crossings(time[after], gap[after])
    assert len(crossings) >= 3, crossings
    np.testing.assert_array_equal(np.sign(gap[after][0]), -1.0)  # lost at the step
    assert len(state_events) == len(crossings), (state_events, crossings)
    np.testing.assert_allclose(state_events, crossings, atol=ATOL)
    # Unilateral contact: the head only pushes, with the spring force while it touches the wire.
    assert np.all(force >= 0.0)
    np.testing.assert_allclose(force, K_PH * np.maximum(gap, 0.0), rtol=1e-9, atol=1e-9)
