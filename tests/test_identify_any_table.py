"""``panto identify`` and the Python API on any table (issue 19, "Any table"): a plain CSV, a
DataFrame, a mapping of arrays, upper-case suffixes, clear errors, and large constant levels.

The data come from a two-mass oscillator written here (SciPy's ``solve_ivp`` on the equations of
motion, smooth inputs known in continuous time), not from the structure's own simulation.
"""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import solve_ivp

from panto.cli import main
from panto.identification.data.loading import LoadOptions, load_identification_data
from panto.identification.structures.registry import identifier

RATE, DURATION = 200.0, 10.0
#: The plant's true parameters (two-mass oscillator of thesis 2.6, masses from the bottom).
TRUTH = {"m1": 12.0, "m2": 6.0, "k1": 80.0, "k2": 5000.0, "c1": 60.0, "c2": 15.0,
         "k_E": 50000.0, "p_gain": 90.0, "F_0": -250.0, "y_0": 2.0}
COLUMNS = {"eta": "height", "p": "pressure", "F_c": "force", "y_cb": "bar"}
INPUTS = ["--inputs", "eta=height", "p=pressure"]
OUTPUTS = ["--outputs", "F_c=force", "y_cb=bar"]


def _inputs(t):
    """Wire height [m] (sum of sines to 4.7 Hz) and bellow pressure [bar] (slow sines)."""
    t = np.asarray(t, float)[..., None]
    eta = 2.0 + 0.004 * np.sum(np.sin(2 * np.pi * np.array([0.13, 0.37, 0.71, 1.3, 2.1, 3.3, 4.7])
                                      * t + np.arange(7)), axis=-1)
    p = 4.0 + 0.3 * np.sum(np.sin(2 * np.pi * np.array([0.11, 0.23, 0.41]) * t
                                  + np.array([0.5, 2.0, 4.0])), axis=-1)
    return eta, p


def _simulate_plant() -> pd.DataFrame:
    """Contact force and cross-bar height of the two-mass plant, from rest at equilibrium."""
    v = TRUTH

    def rhs(t, x):
        eta, p = _inputs(t)
        x1, x2, v1, v2 = x
        f1 = (-v["k1"] * (x1 - v["y_0"]) - v["c1"] * v1 - v["k2"] * (x1 - x2)
              - v["c2"] * (v1 - v2) + v["p_gain"] * p + v["F_0"])
        f2 = -v["k2"] * (x2 - x1) - v["c2"] * (v2 - v1) - v["k_E"] * (x2 - eta)
        return [v1, v2, f1 / v["m1"], f2 / v["m2"]]

    t = np.arange(int(DURATION * RATE)) / RATE
    eta, p = _inputs(t)
    stiffness = np.array([[v["k1"] + v["k2"], -v["k2"]], [-v["k2"], v["k2"] + v["k_E"]]])
    load = np.array([v["k1"] * v["y_0"] + v["p_gain"] * p[0] + v["F_0"], v["k_E"] * eta[0]])
    x0 = np.r_[np.linalg.solve(stiffness, load), 0.0, 0.0]
    solution = solve_ivp(rhs, (0.0, t[-1]), x0, t_eval=t, method="DOP853", rtol=1e-9,
                         atol=1e-12)
    assert solution.success
    return pd.DataFrame({"time": t, "height": eta, "pressure": p,
                         "force": v["k_E"] * (solution.y[1] - eta), "bar": solution.y[0]})


@pytest.fixture(scope="module")
def plant() -> pd.DataFrame:
    return _simulate_plant()


@pytest.fixture(scope="module")
def identified(plant, tmp_path_factory):
    """``panto identify`` on the plant's plain CSV: (exit code, folder, result.json, printed)."""
    folder = tmp_path_factory.mktemp("identify")
    plant.to_csv(folder / "train.csv", index=False)
    out = folder / "out"
    code = main(["identify", str(folder / "train.csv"), "--model", "two-mass", *INPUTS,
                 *OUTPUTS, "--out", str(out)])
    return code, folder, json.loads((out / "result.json").read_text())


def test_panto_identify_fits_a_plain_csv_and_recovers_the_plant(identified):
    code, folder, result = identified
    assert code == 0
    for name in ("parameters.json", "result.json", "fit.png"):
        assert (folder / "out" / name).stat().st_size > 0
    fits = result["training"]["fit_percent"]
    assert fits["F_c"] >= 95.0 and fits["y_cb"] >= 95.0
    values = {k: row["value"] for k, row in result["parameters"].items()}
    for name in ("m1", "m2", "k2", "c2", "p_gain"):  # the stiff, well-excited part
        assert values[name] == pytest.approx(TRUTH[name], rel=0.05), name
    assert "levels kept in the data" in result["message"]


def test_a_dataframe_through_the_python_api_gives_the_same_parameters(plant, identified):
    _, _, result = identified
    frame = plant.set_index("time")  # time as a float index, no time column
    options = LoadOptions(inputs={k: COLUMNS[k] for k in ("eta", "p")},
                          outputs={k: COLUMNS[k] for k in ("F_c", "y_cb")})
    data = load_identification_data(frame, options)
    from_csv = load_identification_data(identified[1] / "train.csv", options)
    assert np.array_equal(data.inputs, from_csv.inputs)
    assert np.array_equal(data.outputs, from_csv.outputs)
    assert np.allclose(data.time, from_csv.time, rtol=0, atol=1e-12)
    mapping = load_identification_data({c: plant[c].to_numpy() for c in plant.columns}, options)
    assert np.array_equal(mapping.outputs, data.outputs)
    from panto.identification.estimation.global_fit import GlobalFitOptions

    # what `panto identify` runs by default for two-mass: the global fit from the data, its
    # starts matched to the adequacy check's black box (fitted first)
    fitted = identifier("two-mass").identify(data, global_fit=GlobalFitOptions(), adequacy=True)
    for name, row in result["parameters"].items():
        assert fitted.parameters[name] == pytest.approx(row["value"], rel=1e-6), name


def test_suffixes_in_upper_case_are_accepted(plant, tmp_path):
    from scipy.io import savemat

    from panto.rig.dataset import Dataset, RunMetadata, read_dataset

    options = LoadOptions(inputs={"eta": "height"}, outputs={"F_c": "force"})
    plant.to_csv(tmp_path / "TRAIN.CSV", index=False)
    savemat(tmp_path / "TRAIN.MAT", {c: plant[c].to_numpy() for c in plant.columns})
    lower = load_identification_data(plant, options)
    for name in ("TRAIN.CSV", "TRAIN.MAT"):
        data = load_identification_data(tmp_path / name, options)
        assert np.array_equal(data.outputs, lower.outputs), name
    dataset = Dataset(plant["time"].to_numpy(), {"force": plant["force"].to_numpy()},
                      {"force": "N"}, RunMetadata(sample_rate=RATE, source="emulator"))
    assert np.array_equal(read_dataset(dataset.write(tmp_path / "run.CSV"), required=())["force"],
                          plant["force"].to_numpy())


def test_a_missing_column_is_one_clear_line(identified, capsys):
    _, folder, _ = identified
    capsys.readouterr()
    code = main(["identify", str(folder / "train.csv"), "--model", "two-mass", *INPUTS,
                 "--outputs", "F_c=contact_force"])
    error = capsys.readouterr().err.strip()
    assert code == 65 and "Traceback" not in error and len(error.splitlines()) == 1
    assert "train.csv" in error and "contact_force" in error
    assert "['bar', 'force', 'height', 'pressure', 'time']" in error
    code = main(["identify", str(folder / "train.csv"), "--model", "blackbox-2"])
    error = capsys.readouterr().err.strip()
    assert code == 65 and "--inputs and --outputs" in error and "'height'" in error
    (folder / "train.h5").write_bytes(b"")
    code = main(["identify", str(folder / "train.h5"), "--model", "two-mass", *INPUTS, *OUTPUTS])
    error = capsys.readouterr().err.strip()
    assert code == 65 and len(error.splitlines()) == 1
    assert "HDF5" in error or "train.h5" in error


def _fits(frame: pd.DataFrame, structure: str, outputs: tuple[str, ...],
          rate: float | None = 50.0):
    options = LoadOptions(inputs={"eta": "height", "p": "pressure"},
                          outputs={o: COLUMNS[o] for o in outputs}, rate=rate)
    return identifier(structure).identify(load_identification_data(frame, options))


@pytest.mark.parametrize("structure", ["linear-2", "blackbox-4"])
def test_large_constant_levels_fit_as_well_as_the_data_without_them(plant, structure):
    zero_mean = plant.copy()
    for column in ("height", "pressure", "force", "bar"):
        zero_mean[column] -= zero_mean[column].mean()
    all_levels = zero_mean.assign(height=zero_mean.height + 5.3, pressure=zero_mean.pressure + 4.0,
                                  force=zero_mean.force + 120.0, bar=zero_mean.bar + 5.2)
    force_level = zero_mean.assign(force=zero_mean.force + 120.0)  # about 2 standard deviations
    assert zero_mean.force.std() > 40.0
    reference = _fits(zero_mean, structure, ("F_c",))
    assert reference.fit["F_c"] > 50.0
    for levelled in (all_levels, force_level):
        result = _fits(levelled, structure, ("F_c",))
        assert result.fit["F_c"] == pytest.approx(reference.fit["F_c"], abs=0.1)
        assert result.details["levels"]["centred"]
        assert "removed the means of" in result.message and "added back" in result.message
    assert reference.details["levels"]["centred"] == structure.startswith("blackbox")


def test_the_oscillator_absorbs_levels_in_its_physical_offsets(plant, identified):
    _, _, result = identified
    shifted = plant.assign(height=plant.height + 3.3, bar=plant.bar + 3.3,
                           force=plant.force + 120.0)
    fitted = _fits(shifted, "two-mass", ("F_c", "y_cb"), rate=None)  # as the CLI: 200 Hz
    assert fitted.parameters["y_0"] == pytest.approx(TRUTH["y_0"] + 3.3, abs=0.02)
    for output, fit in result["training"]["fit_percent"].items():
        assert fitted.fit[output] == pytest.approx(fit, abs=0.1), output
    for name in ("m1", "m2", "k2", "c2", "p_gain"):
        assert fitted.parameters[name] == pytest.approx(result["parameters"][name]["value"],
                                                        rel=1e-3), name
    assert "levels kept in the data: y_0" in fitted.message
