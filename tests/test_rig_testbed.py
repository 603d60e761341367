"""The virtual test bed's plant: each imperfection does what its physics says, and nothing else."""
import math
from dataclasses import replace

import numpy as np
import pytest

from panto.fmu_src.models import Model
from panto.fmu_src.simulation import SolverOptions, simulate_model
from panto.rig.imperfections import RigImperfections
from panto.rig.testbed import VirtualTestBed

DT = 0.002


@pytest.fixture(scope="module")
def pantograph_fmu(project_fmus):
    return project_fmus["Pantograph.fmu"].path


def _run(fmu, imperfections, slider, *, pressure=4.0, voltage=None, seed=0):
    """Drive the plant with slider positions sampled at 500 Hz; return samples (incl. t = 0)."""
    with VirtualTestBed(fmu, imperfections=imperfections, seed=seed) as bed:
        samples = [bed.initialise(slider_position=slider[0], pressure=pressure)]
        if voltage is not None:
            bed.write_valve_voltage(voltage)
        velocity = np.gradient(slider, DT)
        for k in range(1, len(slider)):
            samples.append(bed.on_slider_sample(k * DT, slider[k], velocity[k]))
    return samples


def _truth(samples, name):
    return np.array([s.truth[name] for s in samples])


def _sensor(samples, name):
    return np.array([s.sensors[name] for s in samples])


def test_ideal_rig_measures_the_python_model(pantograph_fmu):
    """Imperfections off: the sensors read the nominal model (independent Python path, held input)."""
    time = np.arange(0, 1.0 + DT / 2, DT)
    slider = 0.01 * np.sin(2 * np.pi * 3.0 * time)
    samples = _run(pantograph_fmu, RigImperfections.none(), slider)
    model = Model("Pantograph")
    x0 = model.equilibrium(2.0, 4.0)
    # The plant holds the mean of each step's end samples over the step (the held input at t_k
    # belongs to the step [t_k, t_k+1]).
    eta_held = 2.0 + 0.5 * (slider + np.concatenate([slider[1:], slider[-1:]]))
    response = simulate_model(model, time, {"eta": eta_held, "p": np.full_like(time, 4.0)},
                              initial_state=x0, interpolation="hold",
                              solver=SolverOptions(method="LSODA", rtol=1e-9, atol=1e-11))
    force = _sensor(samples, "force")
    assert np.ptp(force) > 50  # it really is excited
    # Output at t_k with the bar height of sample k (the held input belongs to the next step).
    expected_force = model.parameters.values["k_ph"] * (response["xi"] - (2.0 + slider))
    np.testing.assert_allclose(force, expected_force, atol=1e-3 * np.ptp(force))
    np.testing.assert_allclose(_sensor(samples, "laser_1"), response["y_cb"], atol=2e-5)


def test_bar_inertia_enters_the_force_signal(pantograph_fmu):
    """F_sensor - F_c = -m_bar a_bar: amplitude m_bar w^2 A at the excitation frequency."""
    mass, amplitude, frequency = 1.5, 0.004, 8.0
    time = np.arange(0, 1.0 + DT / 2, DT)
    slider = amplitude * np.sin(2 * np.pi * frequency * time)
    samples = _run(pantograph_fmu, replace(RigImperfections.none(), bar_mass=mass), slider)
    difference = _sensor(samples, "force") - _truth(samples, "contact_force")
    steady = time > 0.25
    omega = 2 * np.pi * frequency
    # Least-squares amplitude of the difference at the excitation frequency.
    basis = np.column_stack([np.sin(omega * time[steady]), np.cos(omega * time[steady])])
    coefficients, *_ = np.linalg.lstsq(basis, difference[steady], rcond=None)
    expected = mass * omega**2 * amplitude  # 15 N at 8 Hz
    assert math.hypot(*coefficients) == pytest.approx(expected, rel=0.03)
    assert coefficients[0] > 0  # in phase with +sin: -m a = +m w^2 A sin


def test_robot_mode_rings_at_its_frequency_and_yields_statically(pantograph_fmu):
    imperfections = replace(RigImperfections.none(), robot_compliance=2e-6, robot_frequency=15.0,
                            robot_damping_ratio=0.02)
    time = np.arange(0, 2.0 + DT / 2, DT)
    slider = np.where(time < 0.1, 0.0, -0.002)  # press the bar 2 mm down at 0.1 s
    samples = _run(pantograph_fmu, imperfections, slider)
    z = _truth(samples, "robot_displacement")
    force = _truth(samples, "contact_force")
    # Static: the stator yields by compliance * force (the bar pushes the robot up).
    assert z[-1] == pytest.approx(2e-6 * force[-1], rel=0.05)
    # Ringing after the step at the mode's frequency (damped by the pantograph as well).
    ring = z[(time > 0.1) & (time < 1.0)] - z[-1]
    spectrum = np.abs(np.fft.rfft(ring * np.hanning(ring.size), n=8 * ring.size))
    peak = np.fft.rfftfreq(8 * ring.size, DT)[np.argmax(spectrum)]
    assert peak == pytest.approx(15.0, rel=0.1)
    # The bar is where the drive says plus the robot's displacement.
    np.testing.assert_allclose(_truth(samples, "eta"), 2.0 + slider + z, atol=1e-12)


def test_bellow_follows_the_measured_pressure_with_delay_and_lag(pantograph_fmu):
    lag, delay = 0.1, 0.03
    imperfections = replace(RigImperfections.none(), bellow_lag=lag, bellow_delay=delay)
    time = np.arange(0, 1.0 + DT / 2, DT)
    samples = _run(pantograph_fmu, imperfections, np.zeros_like(time), voltage=18.0)
    measured = _truth(samples, "measured_pressure")
    bellow = _truth(samples, "bellow_pressure")
    # Discrete reference: delay by delay/DT samples, then the exact first-order step response.
    shifted = np.concatenate([np.full(int(round(delay / DT)), measured[0]), measured])[:measured.size]
    expected = np.empty_like(measured)
    expected[0] = measured[0]
    decay = math.exp(-DT / lag)
    for k in range(1, measured.size):
        expected[k] = shifted[k] + (expected[k - 1] - shifted[k]) * decay
    assert measured[-1] - measured[0] > 0.5  # the valve really moved
    np.testing.assert_allclose(bellow, expected, atol=1e-12)
    assert np.all(bellow[1:] <= measured[1:] + 1e-12)  # a rising pressure arrives late


def test_sensor_noise_offset_and_quantisation(pantograph_fmu):
    imperfections = replace(RigImperfections.none(), force_noise=0.5, force_offset=2.0,
                            force_quantum=0.05, laser_noise=1.5e-3)
    time = np.arange(0, 2.0 + DT / 2, DT)
    samples = _run(pantograph_fmu, imperfections, np.zeros_like(time), seed=3)
    error = _sensor(samples, "force") - _truth(samples, "contact_force")
    assert np.mean(error) == pytest.approx(2.0, abs=4 * 0.5 / math.sqrt(error.size))
    assert np.std(error) == pytest.approx(math.sqrt(0.5**2 + 0.05**2 / 12), rel=0.1)
    steps = _sensor(samples, "force") / 0.05
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-9)
    laser_error = _sensor(samples, "laser_1") - _truth(samples, "y_cb")
    assert np.std(laser_error) == pytest.approx(1.5e-3, rel=0.1)
    # Same seed, same noise; another seed, other noise.
    again = _run(pantograph_fmu, imperfections, np.zeros_like(time[:50]), seed=3)
    other = _run(pantograph_fmu, imperfections, np.zeros_like(time[:50]), seed=4)
    assert _sensor(again, "force").tolist() == _sensor(samples[:50], "force").tolist()
    assert _sensor(other, "force").tolist() != _sensor(samples[:50], "force").tolist()


def test_unilateral_contact_loses_the_head_and_the_truth_is_recorded(pantograph_fmu):
    time = np.arange(0, 0.6 + DT / 2, DT)
    slider = np.where(time < 0.1, 0.0, 0.25)  # bar jumps 250 mm up: the head cannot follow at once
    samples = _run(pantograph_fmu, replace(RigImperfections.none(), unilateral_contact=True), slider)
    force = _truth(samples, "contact_force")
    assert force[0] > 50
    assert np.any(force[time > 0.1] == 0.0)
    assert np.all(force >= 0.0)
    with VirtualTestBed(pantograph_fmu, imperfections=RigImperfections()) as bed:
        record = bed.truth_record()
    assert record["imperfections"]["bar_mass"] == 1.5
    assert record["pantograph_parameters"]["T_f"] == RigImperfections().hinge_friction_torque


def test_impossible_imperfections_are_refused():
    with pytest.raises(ValueError, match="bar_mass"):
        RigImperfections(bar_mass=-1.0)
    with pytest.raises(ValueError, match="unknown imperfection"):
        RigImperfections().with_only("gremlins")
    only = RigImperfections().with_only("bar_mass")
    assert only.bar_mass == 1.5 and only.robot_compliance == 0 and not only.unilateral_contact
