"""The bellow: valve characteristic and pneumatic dynamics, and the PI loop with anti-windup."""
import math

import numpy as np
import pytest

from panto.rig.pneumatics import ValveParameters, ValvePlant
from panto.rig.pressure import PressureController, PressureControllerOptions

DT = 0.002


def test_valve_characteristic_is_monotonic_with_dead_band_and_saturation():
    valve = ValveParameters()
    u = np.linspace(0.0, 24.0, 4801)
    p = valve.static_pressure(u)
    assert np.all(np.diff(p) >= 0.0)
    assert np.all(p[u <= valve.dead_band] == 0.0)
    assert np.all(p[u >= valve.saturation_voltage] == valve.max_pressure)
    assert p[-1] == 7.5 and valve.supply_pressure == 10.0
    slope = np.diff(p) / np.diff(u)
    inside = (u[1:] > valve.dead_band + 0.1) & (u[1:] < valve.saturation_voltage - 0.1)
    assert np.ptp(slope[inside]) > 0.1 * slope[inside].max()  # nonlinear, not a straight line
    targets = np.linspace(0.01, 7.49, 50)
    assert np.allclose(valve.static_pressure(valve.voltage_for(targets)), targets, atol=1e-12)


def test_plant_without_delay_is_the_exact_first_order_response():
    valve = ValveParameters(delay=0.0, vent_time_constant=None, time_constant=0.4)
    plant = ValvePlant(valve, initial_pressure=1.0)
    voltage = 15.0
    target = float(valve.static_pressure(voltage))
    t = np.arange(1, 1501) * DT
    p = np.array([plant.step(voltage, DT) for _ in t])
    assert np.allclose(p, target + (1.0 - target) * np.exp(-t / 0.4), rtol=0, atol=1e-12)


def test_plant_delay_and_slower_venting():
    valve = ValveParameters(delay=0.05, time_constant=0.3, vent_time_constant=0.6)
    hold = float(valve.voltage_for(5.0))
    plant = ValvePlant(valve, initial_pressure=5.0)
    p = np.array([plant.step(0.0, DT) for _ in range(1000)])  # vent from 5 bar to 0
    delay_steps = round(0.05 / DT)
    assert np.allclose(p[:delay_steps], 5.0, atol=1e-12)  # nothing happens within the delay
    t = (np.arange(1000) + 1 - delay_steps) * DT
    assert np.allclose(p[delay_steps:], 5.0 * np.exp(-t[delay_steps:] / 0.6), atol=1e-12)
    assert hold > valve.dead_band


def closed_loop(demand, *, anti_windup, initial=2.0, valve=None):
    valve = valve or ValveParameters()
    plant = ValvePlant(valve, initial_pressure=initial)
    pi = PressureController(PressureControllerOptions(anti_windup=anti_windup),
                            initial_voltage=float(valve.voltage_for(initial)))
    pressure, voltage = [], []
    p = initial
    for d in demand:
        u = pi.step(d, p)
        p = plant.step(u, DT)
        pressure.append(p)
        voltage.append(u)
    return np.array(pressure), np.array(voltage)


@pytest.mark.parametrize("method", ["conditional", "back-calculation"])
def test_pi_tracks_a_step_within_the_valve_limits(method):
    demand = np.full(3000, 5.0)  # 2 bar -> 5 bar, 6 s
    pressure, voltage = closed_loop(demand, anti_windup=method)
    assert np.all((voltage >= 0.0) & (voltage <= 24.0))
    assert abs(pressure[-1] - 5.0) < 1e-3  # integral action: no steady-state error
    assert np.max(pressure) < 5.0 + 0.1 * 3.0  # overshoot below 10 % of the step
    assert np.argmax(pressure > 4.7) * DT < 2.0


def test_pi_is_the_discrete_pi_law_when_unsaturated():
    options = PressureControllerOptions(kp=3.0, ki=7.0)
    pi = PressureController(options, initial_voltage=10.0)
    errors = np.random.default_rng(0).uniform(-0.5, 0.5, 200)
    outputs = [pi.step(4.0 + e, 4.0) for e in errors]
    integral = 10.0 + 7.0 * DT * np.concatenate([[0.0], np.cumsum(errors)[:-1]])
    assert np.allclose(outputs, 3.0 * errors + integral, rtol=0, atol=1e-12)


def recovery_time(method):
    """Demand 9 bar (beyond the valve's 7.5 bar) for 3 s, then 4 bar: time to settle."""
    demand = np.concatenate([np.full(1500, 9.0), np.full(3000, 4.0)])
    pressure, voltage = closed_loop(demand, anti_windup=method)
    after = pressure[1500:]
    outside = np.flatnonzero(np.abs(after - 4.0) > 0.1)
    return (outside[-1] + 1) * DT if outside.size else 0.0, voltage


def test_anti_windup_shortens_recovery_after_saturation():
    plain, voltage = recovery_time("none")
    assert np.all(voltage[1000:1500] == 24.0)  # the valve was saturated
    for method in ("conditional", "back-calculation"):
        with_aw, _ = recovery_time(method)
        assert with_aw < 0.5 * plain, (method, with_aw, plain)


def test_anti_windup_reduces_overshoot_after_a_saturating_step():
    demand = np.full(4000, 7.3)  # close to the valve's 7.5 bar: the output saturates
    overshoot = {}
    for method in ("none", "conditional", "back-calculation"):
        pressure, voltage = closed_loop(demand, anti_windup=method, initial=0.5)
        assert np.any(voltage == 24.0)
        overshoot[method] = pressure.max() - 7.3
    assert overshoot["conditional"] < overshoot["none"]
    assert overshoot["back-calculation"] < overshoot["none"]


def test_options_are_checked():
    with pytest.raises(ValueError, match="anti_windup"):
        PressureControllerOptions(anti_windup="magic")
    with pytest.raises(ValueError, match="exponent"):
        ValveParameters(exponent=0.5)
    assert math.isinf(PressureControllerOptions(ki=0.0).effective_tracking_time())
