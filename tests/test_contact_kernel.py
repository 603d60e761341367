"""The unilateral contact's compiled recursion against its NumPy reference.

:mod:`panto.identification.diagnosis.contact_kernel` runs the algorithm of
``unilateral_contact._switched_numpy`` / ``_within`` in C, and the run in contact sample by sample
where the NumPy path filters it in modal coordinates. The two paths differ only by rounding: the
summation order of the small matrix products (BLAS sums in its own order, with fused
multiply-adds) and the modal against the direct recursion of the contact run, some 1e-13 of a
state's range over 300 samples. The tolerance, 1e-9 of each state's range (or size), leaves
room for a switch decided by a force within rounding of zero (the switch is placed inside its
sub-step, so the state moves continuously with it). Regimes: contact throughout, flight
throughout, many switches; inputs held and linear between samples; sub-steps 32 and 7. (A
bouncing head with held inputs is left out: there the NumPy path itself moves by up to the
states' size when its start moves by 1e-15, so no tolerance would mean anything.)
"""
from __future__ import annotations

import numpy as np
import pytest

from panto.identification.diagnosis import contact_kernel, unilateral_contact
from panto.identification.diagnosis.unilateral_contact import (ContactModel, UnilateralContact,
                                                               contact_column, resting_state,
                                                               simulate_switched)
from panto.identification.estimation.base import IdentificationData
from panto.identification.structures.oscillators import OscillatorStructure
from panto.identification.structures.physical import PhysicalLinear

OUTPUTS = ("y_cb", "xi", "F_c")
PERIOD = 0.02
OSCILLATOR = {"p_gain": 130.0, "F_0": -420.0, "y_0": 1.93, "c2": 150.0}
needs_kernel = pytest.mark.skipif(contact_kernel.load_kernel() is None,
                                  reason="no C compiler: the compiled kernel cannot be built")


def _slider(amplitude: float, frequency: float, pressure: float = 3.6,
            wobble: float = 0.0) -> IdentificationData:
    """A slider oscillating about 2 m, 6 s at 50 Hz, at `pressure` [bar] +- `wobble` at 1.3 Hz."""
    t = np.arange(0.0, 6.0, PERIOD)
    eta = 2.0 + amplitude * np.sin(2 * np.pi * frequency * t) * np.minimum(t / 0.5, 1.0)
    p = pressure + wobble * np.sin(2 * np.pi * 1.3 * t)
    return IdentificationData(t, np.column_stack([eta, p]),
                              np.zeros((len(t), 3)), ("eta", "p"), OUTPUTS, source="synthetic")


def _problem(structure, parameters, data):
    """ContactModel, inputs, starting state and hold of `structure` on `data`."""
    unilateral = UnilateralContact(structure)
    a, b, c, d, u, x0, hold = unilateral._linear_form(parameters, data)
    model = ContactModel(a, b, c[2], d[2], contact_column(b, d[2], 0))
    return model, u, resting_state(model, x0, u[0])


def _both(monkeypatch, model, u, x0, hold, substeps, period=PERIOD):
    """The compiled and the NumPy run of the same problem (the first checked to be compiled)."""
    monkeypatch.delenv(contact_kernel.SWITCH_VARIABLE, raising=False)
    runs = []
    for compiled in (True, False):
        monkeypatch.setattr(contact_kernel, "USE_COMPILED", compiled)
        assert contact_kernel.active_backend() == ("compiled" if compiled else "numpy")
        runs.append(simulate_switched(model, u, x0, period, hold=hold, substeps=substeps))
    return runs


def _assert_close(compiled, reference, model, u):
    scale = np.maximum(np.ptp(reference.states, axis=0), np.abs(reference.states).max(axis=0))
    error = np.max(np.abs(compiled.states - reference.states) / scale)
    assert error < 1e-9, error
    assert compiled.switched == reference.switched
    force = reference.states @ model.c_force + u @ model.d_force
    near_zero = np.abs(force) < 1e-9 * np.max(np.abs(force))
    assert np.all((compiled.in_contact == reference.in_contact) | near_zero)
    assert np.max(np.abs(compiled.force - reference.force)) <= 1e-9 * np.max(reference.force)


@needs_kernel
@pytest.mark.parametrize("hold", ["foh", "zoh"])
@pytest.mark.parametrize("substeps", [32, 7])
@pytest.mark.parametrize("regime", ["contact", "flight", "switches"])
def test_the_kernel_follows_the_numpy_recursion(regime, substeps, hold, monkeypatch):
    amplitude, frequency, pressure, wobble = {
        "contact": (0.002, 0.7, 3.6, 0.0), "flight": (0.002, 0.7, 2.0, 0.5),
        "switches": (0.015, 2.5, 3.6, 0.0)}[regime]
    structure, parameters = PhysicalLinear(outputs=OUTPUTS), {}
    if regime == "flight":  # uplift 130 p - 420 < 0: the head rests off the wire and stays off
        structure, parameters = OscillatorStructure(2, outputs=OUTPUTS), OSCILLATOR
    model, u, x0 = _problem(structure, parameters, _slider(amplitude, frequency, pressure, wobble))
    compiled, reference = _both(monkeypatch, model, u, x0, hold, substeps)
    _assert_close(compiled, reference, model, u)
    flight = 1.0 - reference.in_contact.mean()
    switches = np.count_nonzero(np.diff(reference.in_contact.astype(int)))
    if regime == "contact":
        assert not reference.switched and flight == 0.0
    elif regime == "flight":
        assert reference.switched and flight == 1.0  # the wire out of the head's reach
    else:
        assert switches >= 20 and 0.2 < flight < 0.8, (switches, flight)


@needs_kernel
def test_a_bouncing_oscillator_head_many_switches(monkeypatch):
    """The three-mass oscillator's light head on a fast slider: switches in many samples."""
    model, u, x0 = _problem(OscillatorStructure(3, outputs=OUTPUTS), OSCILLATOR | {"c3": 150.0},
                            _slider(0.01, 6.0))
    compiled, reference = _both(monkeypatch, model, u, x0, "foh", 32)
    _assert_close(compiled, reference, model, u)
    switches = np.count_nonzero(np.diff(reference.in_contact.astype(int)))
    assert switches >= 40, switches


@needs_kernel
def test_a_head_that_leaves_and_meets_the_wire_within_one_sample(monkeypatch):
    """The same head sampled three times coarser: in some samples it leaves the wire and meets
    it again (the kernel's sub-step loop across a second switch), seen as a sample that ends in
    the mode it started in."""
    model, u, x0 = _problem(OscillatorStructure(3, outputs=OUTPUTS), OSCILLATOR | {"c3": 150.0},
                            _slider(0.01, 6.0))
    returns = []
    original = unilateral_contact._within

    def counted(modes, mode, *rest):
        x, new = original(modes, mode, *rest)
        returns.append(new == mode)
        return x, new

    monkeypatch.setattr(unilateral_contact, "_within", counted)
    compiled, reference = _both(monkeypatch, model, u[::3], x0, "foh", 32, 3 * PERIOD)
    assert any(returns), "no sample with two switches: the case does not test the loop"
    _assert_close(compiled, reference, model, u[::3])


def test_without_a_compiler_the_numpy_loop_runs(monkeypatch, tmp_path):
    """No compiler and an empty kernel cache: no kernel, the NumPy loop, no error."""
    from panto.fmu_src import c_kernels

    model, u, x0 = _problem(PhysicalLinear(outputs=OUTPUTS), {}, _slider(0.015, 2.5))
    monkeypatch.setattr(contact_kernel, "USE_COMPILED", False)
    reference = simulate_switched(model, u, x0, PERIOD)
    monkeypatch.setattr(contact_kernel, "USE_COMPILED", True)
    monkeypatch.delenv(contact_kernel.SWITCH_VARIABLE, raising=False)
    monkeypatch.setenv("PANTO_KERNEL_CACHE", str(tmp_path))
    monkeypatch.setattr(c_kernels, "find_compiler", lambda: None)
    contact_kernel.load_kernel.cache_clear()
    try:
        assert contact_kernel.active_backend() == "numpy"
        run = simulate_switched(model, u, x0, PERIOD)
    finally:
        contact_kernel.load_kernel.cache_clear()
    assert run.switched and np.array_equal(run.states, reference.states)


def test_switched_off_the_numpy_loop_runs(monkeypatch):
    """``PANTO_CONTACT_KERNEL=0``: neither C path runs, and the result is the NumPy loop's, bit
    for bit."""
    model, u, x0 = _problem(PhysicalLinear(outputs=OUTPUTS), {}, _slider(0.015, 2.5))
    monkeypatch.setattr(contact_kernel, "USE_COMPILED", False)
    reference = simulate_switched(model, u, x0, PERIOD)
    monkeypatch.setattr(contact_kernel, "USE_COMPILED", True)
    monkeypatch.setenv(contact_kernel.SWITCH_VARIABLE, "0")
    assert contact_kernel.active_backend() == "numpy"
    assert contact_kernel.propagate(np.eye(2), np.zeros((3, 2)), np.zeros(2)) is None
    off = simulate_switched(model, u, x0, PERIOD)
    assert reference.switched and np.array_equal(off.states, reference.states)
    assert np.array_equal(off.in_contact, reference.in_contact)


@needs_kernel
def test_the_compiled_contact_run_is_the_recursion(monkeypatch):
    """``contact_kernel.propagate`` is ``x[k+1] = Phi x[k] + drive[k]`` (checked step by step)."""
    monkeypatch.delenv(contact_kernel.SWITCH_VARIABLE, raising=False)
    rng = np.random.default_rng(3)
    phi = 0.3 * rng.standard_normal((5, 5))
    drive, x0 = rng.standard_normal((40, 5)), rng.standard_normal(5)
    states = contact_kernel.propagate(phi, drive, x0)
    assert contact_kernel.active_backend() == "compiled"
    assert np.array_equal(states[0], x0)
    assert np.allclose(states[1:], states[:-1] @ phi.T + drive, rtol=1e-14, atol=1e-14)


@needs_kernel
def test_the_kernel_refuses_arrays_that_do_not_fit(monkeypatch):
    """The C code reads its tables unchecked: a start outside the record or a table of the wrong
    size is refused before the call."""
    monkeypatch.delenv(contact_kernel.SWITCH_VARIABLE, raising=False)
    model, u, x0 = _problem(PhysicalLinear(outputs=OUTPUTS), {}, _slider(0.015, 2.5))
    uc = unilateral_contact
    slope = np.diff(u, axis=0) / PERIOD
    modes = [uc._prepare(matrices, model, u, slope, PERIOD, 8) for matrices in uc._modes(model)]
    states = np.zeros((len(u), len(x0)))
    powers = (uc._powers(modes[0].phi, 4), uc._powers(modes[1].phi, 4))
    args = (model.c_force, model.d_force, PERIOD / 8, powers)
    for start, rows in ((-1, len(u)), (len(u) - 1, len(u)), (0, len(u) - 1)):
        with pytest.raises(ValueError, match="unilateral contact kernel"):
            contact_kernel.run_switched(modes, states, u[:rows], slope, start, *args)
    assert contact_kernel.run_switched(modes, states, u, slope, 0, *args)
