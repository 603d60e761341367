"""``panto linearise`` and ``panto parameters`` offer the force-excited models (issue 20; thesis
Fig. 2.6 and section 4.4): the force pantograph is linearised where its displacement twin rests at
(eta, p) and shows the slow unstable rigid-body mode of section 4.4 (+0.226 1/s, doubling time
3.1 s); the force oscillators are grounded by k1 and stable; their parameter files hold their own
parameters (no contact spring: the force is the input).
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from panto.cli import main
from panto.fmu_src.models import Model, default_parameters, load_parameters
from panto.fmu_src.operating_point import displacement_twin, force_model_inputs


def _linearise(tmp_path, capsys, model: str) -> tuple[dict, str]:
    path = tmp_path / f"{model}.json"
    assert main(["linearise", "--model", model, "--eta", "2.0", "--p", "4.0",
                 "--json", str(path)]) == 0
    return json.loads(path.read_text()), capsys.readouterr().out


def _numerical_jacobian(model: Model, x0: np.ndarray, inputs: tuple) -> np.ndarray:
    """dx'/dx by central differences of the nonlinear right-hand side (a second path to A)."""
    columns = []
    for i in range(x0.size):
        step = np.zeros_like(x0)
        step[i] = 1e-6 * max(1.0, abs(x0[i]))
        columns.append((model.derivatives(x0 + step, *inputs)
                        - model.derivatives(x0 - step, *inputs)) / (2 * step[i]))
    return np.column_stack(columns)


def test_linearise_force_pantograph_shows_the_unstable_rigid_body_mode(tmp_path, capsys):
    result, printed = _linearise(tmp_path, capsys, "PantographForce")
    twin = Model("Pantograph")
    rest = twin.equilibrium(2.0, 4.0)
    # held by the twin's bellow torque k_p p and contact force, it rests where the twin does
    assert result["inputs"]["M_b"] == pytest.approx(twin.parameters["k_p"] * 4.0)
    assert result["inputs"]["F_c"] == pytest.approx(float(twin.outputs(rest, 2.0, 4.0)[2]))
    np.testing.assert_allclose(list(result["equilibrium"].values()), rest, atol=1e-9)
    eigenvalues = np.array([complex(re, im) for re, im in result["eigenvalues"]])
    unstable = eigenvalues[eigenvalues.real > 0]
    assert unstable.size == 1 and unstable[0].imag == 0.0
    assert unstable[0].real == pytest.approx(0.226, abs=0.001)  # section 4.4 (docs/thesis.md)
    assert "unstable eigenvalues [1/s]: +0.226" in printed
    # the written A is the Jacobian of the nonlinear model at the point (a second path)
    force = Model("PantographForce")
    a_matrix = _numerical_jacobian(force, np.array(list(result["equilibrium"].values())),
                                   tuple(result["inputs"].values()))
    np.testing.assert_allclose(result["A"], a_matrix, rtol=1e-5, atol=1e-5 * np.abs(a_matrix).max())


@pytest.mark.parametrize("model", ["TwoMassForce", "ThreeMassForce"])
def test_linearise_force_oscillators_grounded_by_k1_are_stable(tmp_path, capsys, model):
    result, printed = _linearise(tmp_path, capsys, model)
    twin = Model(displacement_twin(model))
    np.testing.assert_allclose(list(result["equilibrium"].values()), twin.equilibrium(2.0, 4.0),
                               atol=1e-9)
    assert all(re < 0 for re, _ in result["eigenvalues"])
    assert "unstable" not in printed


def test_displacement_models_keep_eta_and_p_as_their_inputs(tmp_path, capsys):
    result, printed = _linearise(tmp_path, capsys, "Pantograph")
    assert result["inputs"] == {"eta": 2.0, "p": 4.0}
    assert "unstable" not in printed and "inputs:" not in printed


def test_force_model_inputs_take_the_shared_parameters():
    """A heavier head presses harder: the twin sees the force model's own parameter values."""
    light = force_model_inputs("PantographForce", 2.0, 4.0)
    heavy = force_model_inputs("PantographForce", 2.0, 4.0, {"m_c": 20.0})
    assert heavy["M_b"] == light["M_b"] and heavy["F_c"] < light["F_c"]
    with pytest.raises(ValueError, match="no force-excited model"):
        force_model_inputs("Pantograph", 2.0, 4.0)


def test_parameters_lists_the_force_oscillators_parameters(tmp_path, capsys):
    path = tmp_path / "two_mass_force.json"
    assert main(["parameters", "--model", "TwoMassForce", "--out", str(path)]) == 0
    written = json.loads(path.read_text())
    assert written["model"] == "TwoMassForce"
    assert list(written["parameters"]) == list(default_parameters("TwoMassForce").names)
    assert {"m1", "k1", "c1", "m2", "k2", "c2", "F_0"} <= set(written["parameters"])
    assert "k_E" not in written["parameters"]  # the force is the input: no contact spring
    assert written["parameters"]["k1"]["unit"] == "N/m"
    assert load_parameters(path).values == default_parameters("TwoMassForce").values
