"""The physical structures (linearised per candidate and FMU in the loop) and their identification."""
from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from panto.identification.estimation.base import IdentificationData, IdentificationError, fit_percent
from panto.identification.estimation.least_squares import fit_least_squares
from panto.identification.structures.physical import TABLE_4_1, PhysicalLinear, PhysicalNonlinear


def _inputs(duration: float, eta_amplitude: float, p_amplitude: float) -> IdentificationData:
    time = np.arange(0.0, duration, 0.02)
    eta = 2.0 + eta_amplitude * (np.sin(2 * np.pi * 0.7 * time) + 0.5 * np.sin(2 * np.pi * 3.1 * time))
    p = 4.0 + p_amplitude * np.sin(2 * np.pi * 0.23 * time + 0.4)
    return IdentificationData(time, np.column_stack([eta, p]), np.zeros((len(time), 2)),
                              ("eta", "p"), ("F_c", "y_cb"), source="synthetic inputs")


@pytest.fixture(scope="module")
def linear_fmu():
    from panto.build_fmu.project import project_fmu

    return project_fmu("PantographLinear")


def test_physical_linear_agrees_with_the_linear_fmu(linear_fmu):
    """Two paths: the structure's own linearisation and discretisation against the C code of
    PantographLinear (linearised about eta0, p0) integrated by CVODE with linear inputs."""
    from panto.build_fmu.simulate import FmuSimulator

    data = _inputs(10.0, 0.01, 0.3)
    parameters = {"m_c": 7.0, "k_c": 18000.0, "c1": 350.0, "k_p": 250.0}
    u0 = data.inputs[0]
    with FmuSimulator(linear_fmu, interface="ME") as fmu:
        response = fmu.simulate(data.time, {"eta": data.input("eta"), "p": data.input("p")},
                                parameters=parameters | {"eta0": u0[0], "p0": u0[1]},
                                solver_tolerance=1e-9)
    reference = np.column_stack([response["F_c"], response["y_cb"]])
    simulated = PhysicalLinear(operating_point="first").simulate(parameters, data)
    assert np.max(np.abs(simulated[:, 0] - reference[:, 0])) < 1e-3 * np.ptp(reference[:, 0])
    assert np.max(np.abs(simulated[:, 1] - reference[:, 1])) < 1e-3 * np.ptp(reference[:, 1])


def test_linearised_and_nonlinear_agree_for_small_signals():
    small = _inputs(8.0, 0.001, 0.02)
    linear = PhysicalLinear(operating_point="first").simulate({}, small)
    nonlinear = PhysicalNonlinear().simulate({}, small)
    assert np.all(fit_percent(nonlinear, linear) > 98.0)
    large = _inputs(8.0, 0.04, 1.0)  # and the difference grows with the amplitude
    assert np.all(fit_percent(PhysicalNonlinear().simulate({}, large),
                              PhysicalLinear(operating_point="first").simulate({}, large))
                  < fit_percent(nonlinear, linear))


def test_lm_recovers_physical_parameters_at_the_noise_floor():
    rng = np.random.default_rng(4)
    structure = PhysicalLinear()
    base = _inputs(40.0, 0.02, 0.5)
    truth = {"c1": 300.0, "k_c": 19000.0, "k_p": 250.0, "m_c": 6.5}
    clean = structure.simulate(truth, base)
    noise = np.array([1.0, 5e-4])
    data = IdentificationData(base.time, base.inputs, clean + noise * rng.standard_normal(clean.shape),
                              base.input_names, base.output_names)
    result = fit_least_squares(structure, data, free=tuple(truth),
                               initial={"c1": 200.0, "k_c": 25000.0, "k_p": 300.0, "m_c": 5.0})
    assert result.success, result.message
    for name, value in truth.items():
        low, high = result.details["intervals_95"][name]
        assert low <= value <= high, (name, value, low, high)
    floor = 100 * (1 - noise * math.sqrt(len(data)) / np.linalg.norm(clean - clean.mean(0), axis=0))
    assert result.fit["F_c"] == pytest.approx(floor[0], abs=0.2)
    assert result.fit["y_cb"] == pytest.approx(floor[1], abs=0.2)


def test_bad_physical_options_are_refused():
    with pytest.raises(IdentificationError, match="unknown model parameter"):
        PhysicalLinear(fixed={"mass": 1.0})
    with pytest.raises(IdentificationError, match="outside"):
        PhysicalLinear(fixed={"m1": -3.0})
    with pytest.raises(IdentificationError, match="unknown parameter"):
        PhysicalLinear().simulate({"l1": 2.0}, _inputs(1.0, 0.0, 0.0))
    assert "k_ph" not in PhysicalLinear(contact_stiffness=50000.0).default_free()


@pytest.fixture(scope="module")
def noisy_run(tmp_path_factory):
    """30 s of the training APRBS on the virtual test bed, ideal rig plus sensor noise."""
    from panto.build_fmu.project import project_fmu
    from panto.rig.imperfections import RigImperfections
    from panto.rig.profiles import load_profile
    from panto.rig.virtual import run_virtual_profile

    profile = load_profile(__import__("pathlib").Path(__file__).parents[1]
                           / "rig" / "profiles" / "aprbs_training.json")
    profile = dataclasses.replace(profile, duration=30.0, conditioning=dataclasses.replace(
        profile.conditioning, filter_cutoff=1.0))
    folder = tmp_path_factory.mktemp("vtb") / "run"
    imperfections = dataclasses.replace(RigImperfections.none(), force_noise=1.0,
                                        laser_noise=1.5e-3)
    run_virtual_profile(profile, fmu_path=project_fmu("Pantograph"), folder=folder,
                        imperfections=imperfections, seed=3)
    return folder


#: How late the emulated drive reports the slider: the position sampled at a SYNC is read one
#: 250 Hz cycle later (4 ms) and held for two 500 Hz samples (1 ms on average); measured in
#: tests/test_identification_latency.py against truth.csv.
DRIVE_LATENCY = 0.005


def test_table_4_1_from_the_virtual_test_bed(noisy_run):
    """All 13 parameters free from a perturbed start on an ideal rig with sensor noise.

    The data start at rest (the model's equilibrium start is then right) and ``motor_position``
    is advanced by the drive's latency. They are taken at 100 Hz: at 50 Hz the head's modes
    (9-12 Hz) next to the 20 Hz stopband leave LM a local minimum on the m_c/k_c/k_ph ridge from
    some starts (seen: a fit 0.05 points below the true parameters'). What holds (asserted): LM
    reaches a fit at least as good as the true parameters'; the linkage's inner parameters
    (m2, m3) are named not identifiable with the Fisher information's reason; every identifiable
    parameter lies within its 95 % interval. The intervals take the colour of the noise into
    account (the 20 Hz low-pass of the resampling makes it strongly coloured at 100 Hz; with a
    white-noise covariance m_c, k_c and k_ph were 2.5-3 sigma off, see panto.identification.estimation.uncertainty).
    """
    from panto.identification.data.datasets import pantograph_data

    data = pantograph_data(noisy_run, position_latency=DRIVE_LATENCY, rate=100.0)
    structure = PhysicalLinear()
    nominal = structure.nominal()
    rng = np.random.default_rng(1)
    start = {n: nominal[n] * rng.uniform(0.8, 1.25) for n in TABLE_4_1}
    result = fit_least_squares(structure, data, free=TABLE_4_1, initial=start)
    assert result.success, result.message
    at_truth = fit_percent(data.outputs, structure.simulate({}, data))
    cost = 0.5 * sum((1 - f / 100) ** 2 for f in result.fit.values())
    assert cost <= 0.5 * float(np.sum((1 - at_truth / 100) ** 2)) * 1.001
    report = result.details["identifiability"]
    assert set(report["identifiable"]) | set(report["not_identifiable"]) == set(TABLE_4_1)
    assert {"m2", "m3"} <= set(report["not_identifiable"])
    assert all("Fisher" in why or "relative standard deviation" in why
               for why in report["not_identifiable"].values())
    outside = [n for n in report["identifiable"]
               if not result.details["intervals_95"][n][0] <= nominal[n]
               <= result.details["intervals_95"][n][1]]
    assert outside == [], outside
    assert {"m_c", "c_c", "k_c", "k_ph", "k_p"} <= set(report["identifiable"])


def test_panto_identify_writes_a_parameter_file_the_model_accepts(noisy_run, tmp_path, capsys):
    from panto.fmu_src.models import default_parameters
    from panto.fmu_src.parameters import ParameterSet
    from panto.identification.structures.physical import linearise
    from panto.cli import main

    out = tmp_path / "identified"
    code = main(["identify", str(noisy_run), "--model", "physical-linear", "--free", "m_c",
                 "k_p", "--fix", "k_ph=12000", "--out", str(out), "--json",
                 str(tmp_path / "summary.json")])
    printed = capsys.readouterr().out
    assert code == 0 and "k_p" in printed and "fit on training" in printed
    # what panto.fmu_src.models.load_parameters reads (without its linkage check, which would compile
    # the full symbolic model here for a minute)
    params = ParameterSet.load(out / "parameters.json", default_parameters("Pantograph").specs,
                               "Pantograph")
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert params["k_ph"] == 12000.0
    assert params["m_c"] == pytest.approx(summary["parameters"]["m_c"]["value"])
    a = linearise(params.vector(), [2.0, 4.0])[0]
    assert np.all(np.linalg.eigvals(a).real < 0)
    assert (out / "fit.png").stat().st_size > 0
    assert main(["identify", str(noisy_run), "--free", "k_ph", "--fix", "k_ph=50000"]) != 0
    assert "both free and fixed" in capsys.readouterr().err
