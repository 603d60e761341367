"""An FMU's parameters from a mapping, a parameter file or an identification result
(:mod:`panto.build_fmu.parameter_sources`), in the simulator and in the co-simulation's set-up."""
from __future__ import annotations

import json

import numpy as np
import pytest

from panto.build_fmu.parameter_sources import fmu_parameter_values, model_family
from panto.fmu_src.models import default_parameters
from panto.identification.estimation.base import IdentificationResult

PANTOGRAPH = default_parameters("Pantograph").names


def _result(parameters: dict, free: tuple[str, ...], structure: str = "physical-linear"):
    """An identification result holding `parameters` (nothing is simulated with it here)."""
    return IdentificationResult(structure, "levenberg-marquardt", parameters, free,
                                {n: 0.0 for n in free}, np.eye(len(free)), {}, True, "", 0.0,
                                0, simulator=lambda data: data.outputs)


def _file(path, model, parameters: dict) -> str:
    path.write_text(json.dumps({"model": model, "parameters": parameters}))
    return str(path)


@pytest.mark.parametrize("model, family", [
    ("Pantograph", "Pantograph"), ("PantographLinear", "Pantograph"),
    ("PantographForceLinear", "Pantograph"), ("TwoMassForce", "TwoMass"), ("ThreeMass", "ThreeMass"),
], ids=["pantograph", "linear", "force-linear", "two-mass-force", "three-mass"])
def test_model_family_strips_the_variant_suffixes(model, family):
    assert model_family(model) == family


def test_a_parameter_file_in_grams_is_converted_to_the_models_kilograms(tmp_path):
    in_grams = _file(tmp_path / "g.json", "Pantograph", {"m_c": {"value": 6500.0, "unit": "g"}})
    in_kilograms = _file(tmp_path / "kg.json", "Pantograph", {"m_c": {"value": 6.5, "unit": "kg"}})
    grams = fmu_parameter_values(in_grams, model="Pantograph", parameter_names=PANTOGRAPH)
    assert grams == {"m_c": pytest.approx(6.5, rel=1e-12)}
    assert grams == pytest.approx(fmu_parameter_values(in_kilograms, model="Pantograph",
                                                       parameter_names=PANTOGRAPH))


def test_a_file_of_another_model_is_refused_even_when_the_names_overlap(tmp_path):
    two_mass = _file(tmp_path / "two.json", "TwoMass", {"m1": {"value": 15.0, "unit": "kg"}})
    names = default_parameters("ThreeMass").names
    assert "m1" in names  # taken by name it would be accepted
    with pytest.raises(ValueError, match=r"two\.json.*'TwoMass'.*'ThreeMass'"):
        fmu_parameter_values(two_mass, model="ThreeMass", parameter_names=names)


def test_the_linearised_fmu_takes_the_pantographs_file_without_its_missing_names(tmp_path):
    path = _file(tmp_path / "p.json", "Pantograph", {"k_ph": {"value": 6000.0, "unit": "N/m"},
                                                     "kappa_p": {"value": 0.0}})
    values = fmu_parameter_values(path, model="PantographForce",
                                  parameter_names=default_parameters("PantographForce").names)
    assert values == {}  # neither k_ph nor kappa_p is a parameter of the force-excited variant
    values = fmu_parameter_values(path, model="PantographLinear",
                                  parameter_names=PANTOGRAPH + ("eta0", "p0"))
    assert values == {"k_ph": 6000.0, "kappa_p": 0.0}


def test_a_plain_file_is_read_by_name_and_its_units_checked(tmp_path):
    names, units = ("gain", "delay"), {"gain": "N/m", "delay": "s"}
    good = _file(tmp_path / "good.json", "user", {"gain": {"value": 3.0, "unit": "N/m"},
                                                  "delay": 0.1})
    assert fmu_parameter_values(good, model="User", parameter_names=names,
                                units=units) == {"gain": 3.0, "delay": 0.1}
    unknown = _file(tmp_path / "unknown.json", "user", {"gian": 3.0})
    with pytest.raises(ValueError, match=r"unknown\.json: \['gian'\] are not parameters"):
        fmu_parameter_values(unknown, model="User", parameter_names=names, units=units)
    other_unit = _file(tmp_path / "ms.json", "user", {"delay": {"value": 100.0, "unit": "ms"}})
    with pytest.raises(ValueError, match=r"ms\.json: parameter 'delay' is given in 'ms'"):
        fmu_parameter_values(other_unit, model="User", parameter_names=names, units=units)
    (tmp_path / "broken.json").write_text("{")
    with pytest.raises(ValueError, match=r"broken\.json: cannot read"):
        fmu_parameter_values(tmp_path / "broken.json", model="User", parameter_names=names)


def test_a_result_gives_the_values_the_fmu_has_and_refuses_one_of_another_model():
    result = _result({"k_ph": 6000.0, "m4": 20.0, "eta_delay": 0.002}, free=("k_ph", "m4"))
    values = fmu_parameter_values(result, model="Pantograph", parameter_names=PANTOGRAPH)
    assert values == {"k_ph": 6000.0, "m4": 20.0}  # the measurement delay is not the model's
    two_mass = _result({"m1": 15.0, "k1": 50.0, "k2": 4200.0}, free=("m1", "k1", "k2"),
                       structure="two-mass")
    with pytest.raises(ValueError, match=r"two-mass result estimated \['k1', 'k2'\]"):
        fmu_parameter_values(two_mass, model="Pantograph", parameter_names=PANTOGRAPH)
    with pytest.raises(TypeError, match="got int"):
        fmu_parameter_values(3, model="Pantograph", parameter_names=PANTOGRAPH)


@pytest.fixture(scope="module")
def pantograph_fmu():
    from panto.build_fmu.project import project_fmu

    return project_fmu("Pantograph")


def test_simulator_runs_the_same_from_a_result_its_file_and_its_dict(pantograph_fmu, tmp_path):
    from panto.build_fmu.simulate import FmuSimulator
    from panto.identification.estimation.reporting import write_parameters

    nominal = default_parameters("Pantograph")
    identified = {"k_ph": 1.3 * nominal["k_ph"], "c3": 0.7 * nominal["c3"], "eta_delay": 0.0}
    result = _result(identified, free=("k_ph", "c3"))
    path = write_parameters(result, tmp_path / "parameters.json", parameter_set="Pantograph")
    time = np.linspace(0.0, 1.0, 201)
    inputs = {"eta": 2.0 + 0.01 * np.sin(2 * np.pi * 3.0 * time), "p": 4.0}
    with FmuSimulator(pantograph_fmu) as simulator:
        runs = {source: simulator.simulate(time, inputs, parameters=parameters)["F_c"]
                for source, parameters in (("result", result), ("file", path),
                                           ("dict", {"k_ph": identified["k_ph"],
                                                     "c3": identified["c3"]}), ("nominal", None))}
        used = simulator.simulate(time, inputs, parameters=result).metadata["parameters"]
    assert np.array_equal(runs["result"], runs["dict"])
    assert np.array_equal(runs["file"], runs["dict"])
    assert used["k_ph"] == identified["k_ph"] and used["c3"] == identified["c3"]
    # the values reach the model: a 30 % stiffer head spring changes the force
    assert np.max(np.abs(runs["result"] - runs["nominal"])) > 1e-3


def test_pantograph_setup_takes_a_result_or_its_file_and_keeps_its_own_line_settings(
        pantograph_fmu, tmp_path):
    from panto.catenary_cosim.pantographs import pantograph_setup
    from panto.identification.estimation.reporting import write_parameters

    result = _result({"k_ph": 6000.0, "m4": 20.0, "eta_delay": 0.0}, free=("k_ph", "m4"))
    path = write_parameters(result, tmp_path / "parameters.json", parameter_set="Pantograph")
    assert json.loads(path.read_text())["parameters"]["unilateral_contact"]["value"] == 0.0
    setup = pantograph_setup("physical").with_fmu(pantograph_fmu)
    from_dict = setup.with_parameters(k_ph=6000.0, m4=20.0).fmu_parameters(5.3, 250.0)
    from_result = setup.with_parameters(result).fmu_parameters(5.3, 250.0)
    from_file = setup.with_parameters(path).fmu_parameters(5.3, 250.0)
    assert from_result == from_dict
    assert {k: from_file[k] for k in from_dict} == pytest.approx(from_dict)
    assert from_file["unilateral_contact"] is True  # the line's contact, not the file's default
    assert setup.with_parameters(result, k_ph=7000.0).fmu_parameters(5.3, 250.0)["k_ph"] == 7000.0
