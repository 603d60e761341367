"""The recovery benchmark's premise: its independently written oscillator plants
(``benchmarks/plants.py``: force balance integrated by ``solve_ivp``) and the identification
structures (``two-mass``, ``three-mass``: matrices assembled apart, exact first-order-hold
discretisation) are the same model, so a fit can reach the truth exactly.

Two independent paths on the same parameters and inputs must agree within the plant's
integration error, estimated from the same plant integrated at a looser tolerance.
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from panto.identification.estimation.base import IdentificationData
from panto.identification.structures.oscillators import OscillatorStructure

_PLANTS = Path(__file__).resolve().parent.parent / "benchmarks" / "plants.py"


@pytest.fixture(scope="module")
def plants():
    spec = importlib.util.spec_from_file_location("recovery_plants", _PLANTS)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("masses", [2, 3], ids=["two-mass", "three-mass"])
@pytest.mark.parametrize("excitation", ["aprbs", "multisine"])
def test_independent_plant_and_structure_agree(plants, masses, excitation):
    rng = np.random.default_rng(7 + masses)
    truth = plants.draw_oscillator_truth(masses, rng)
    time, eta, pressure = plants.excitation_inputs(excitation, rng, duration=4.0)
    tight = plants.simulate_oscillator(truth, time, eta, pressure, rtol=1e-10, atol=1e-12)
    loose = plants.simulate_oscillator(truth, time, eta, pressure, rtol=1e-6, atol=1e-8)

    names = ("y_cb", "xi", "F_c")
    structure = OscillatorStructure(masses, outputs=names)
    data = IdentificationData(time, np.column_stack([eta, pressure]), np.zeros((len(time), 3)),
                              ("eta", "p"), names)
    simulated = structure.simulate({k: v for k, v in truth.items()
                                    if k in structure.parameter_names}, data)
    for j, name in enumerate(names):
        # the tight run's error is far below the loose run's distance from it
        integration_error = np.max(np.abs(loose[name] - tight[name]))
        scale = np.ptp(tight[name])
        assert scale > 0
        difference = np.max(np.abs(simulated[:, j] - tight[name]))
        assert difference <= integration_error + 1e-9 * scale, (name, difference, integration_error)


def test_plant_rests_in_static_equilibrium_with_constant_inputs(plants):
    """At rest the contact force carries the bellow force less the base spring's (force balance
    of the whole chain), whatever the masses and inner springs."""
    truth = plants.draw_oscillator_truth(3, np.random.default_rng(3))
    time = np.arange(200) / 100.0
    eta, pressure = np.full_like(time, 2.01), np.full_like(time, 4.2)
    out = plants.simulate_oscillator(truth, time, eta, pressure)
    assert np.ptp(out["F_c"]) < 1e-6
    x1 = plants._equilibrium(truth, 3, 2.01, 4.2)[0]
    expected = truth["p_gain"] * 4.2 + truth["F_0"] - truth["k1"] * (x1 - truth["y_0"])
    assert out["F_c"][0] == pytest.approx(expected, rel=1e-9)
