"""The pantograph design proven on the virtual test bed, and `panto doe` as a user runs it
(issue 7)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from panto.identification.design.constraints import RigInputConstraints
from panto.identification.design.pantograph import DesignOptions, design_pantograph_experiment
from panto.identification.design.pantograph_sensitivity import LinearisedPantograph, PressureLag

CONSTRAINTS = RigInputConstraints(pressure_lag=PressureLag(0.22, 0.02))


def test_designed_run_gives_smaller_reported_covariance_than_aprbs(project_fmus, tmp_path):
    """20 s each on the virtual test bed (sensor noise only), four free parameters of the
    linearised physical model: the least-squares covariance reported from the designed run is
    smaller (determinant) than from the APRBS run of equal length."""
    from panto.identification.design.profiles import VirtualRigOptions, compare_on_virtual_rig

    free = ("m_c", "k_c", "k_p", "c1")
    model = LinearisedPantograph("physical-linear", free=free, length=1000,
                                 pressure_lag=CONSTRAINTS.pressure_lag)
    design = design_pantograph_experiment(model, CONSTRAINTS,
                                          options=DesignOptions(population=24, generations=30))
    comparison = compare_on_virtual_rig(design, tmp_path, options=VirtualRigOptions(
        fmu_path=project_fmus["Pantograph.fmu"].path, seed=3))
    assert comparison.det_ratio_per_parameter > 1.0
    for run in (comparison.designed, comparison.conventional):
        assert all(np.isfinite(list(run.std.values())))
        assert min(run.fit.values()) > 90.0
    assert json.dumps(comparison.summary(), default=float)


def _run_cli(arguments):
    from panto.cli import main

    return main(["doe", *arguments])


def test_cli_three_mass(tmp_path):
    out = tmp_path / "three"
    assert _run_cli(["--model", "three-mass", "--duration", "6", "--population", "6",
                     "--generations", "2", "--out", str(out)]) == 0
    summary = json.loads((out / "doe_summary.json").read_text())
    assert summary["structure"] == "three-mass" and "m3" in summary["free"]
    assert max(summary["violations"].values()) <= 0.0


def test_cli_uses_the_parameter_file(tmp_path):
    """A parameter file as `panto identify --out` writes it (the Pantograph parameter set):
    the design is computed at its values."""
    from panto.fmu_src.models import default_parameters

    path = tmp_path / "parameters.json"
    default_parameters("Pantograph").with_values({"k_c": 25000.0, "m_c": 7.0}).save(path)
    out = tmp_path / "designed"
    assert _run_cli(["--model", "physical-linear", "--parameters", str(path), "--free", "m_c",
                     "k_c", "k_p", "--duration", "6", "--population", "6", "--generations", "2",
                     "--out", str(out)]) == 0
    rows = (out / "predicted_covariance.csv").read_text().splitlines()
    values = {r.split(",")[0]: float(r.split(",")[1]) for r in rows[1:]}
    assert values["k_c"] == pytest.approx(25000.0) and values["m_c"] == pytest.approx(7.0)


def test_cli_rejects_a_bad_parameter_file(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text('{"parameters": {"k_c": {"value": "stiff"}}}')
    with pytest.raises(SystemExit, match="k_c"):
        _run_cli(["--parameters", str(path), "--out", str(tmp_path / "o")])
