"""The diagnosis on the virtual test bed: a rig whose only imperfection is joint friction in the
pantograph's lower-arm hinge (plus sensor noise); the nominal is the linearised physical model
(Table 4.1 free). The friction must be named first and close part of the force gap on a withheld
run (a different APRBS realisation)."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from panto.identification.data.datasets import pantograph_data
from panto.identification.diagnosis.pipeline import diagnose


def _run(folder: Path, seed: int) -> Path:
    from panto.build_fmu.project import project_fmu
    from panto.rig.imperfections import RigImperfections
    from panto.rig.profiles import load_profile
    from panto.rig.virtual import run_virtual_profile

    base = load_profile(Path(__file__).parents[1] / "rig" / "profiles" / "aprbs_training.json")
    profile = dataclasses.replace(base, duration=30.0, seed=base.seed + seed, conditioning=
                                  dataclasses.replace(base.conditioning, filter_cutoff=1.0))
    imperfections = dataclasses.replace(RigImperfections.none(), force_noise=1.0,
                                        laser_noise=1.5e-3, hinge_friction_torque=20.0)
    run_virtual_profile(profile, fmu_path=project_fmu("Pantograph"), folder=folder,
                        imperfections=imperfections, seed=seed)
    return folder


@pytest.fixture(scope="module")
def friction_runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("friction")
    return _run(root / "train", 11), _run(root / "validate", 12)


def test_hinge_friction_is_named_on_the_virtual_test_bed(friction_runs):
    train, validation = (pantograph_data(run).segment(1.0, 1e9) for run in friction_runs)
    lines = []
    result = diagnose(train, validation, structure="physical-linear", progress=lines.append)
    assert result.verdict == "effect" and result.effects[0] == "coulomb_friction", lines
    step = result.steps[0]
    assert step.fit_after["F_c"] > step.fit_before["F_c"] + 3.0  # the force gap shrinks
    assert step.energy_removed["F_c"] > 0.15
    # the friction's magnitude (a joint that sticks also has its presliding width)
    (name,) = [n for n in step.parameters if n.startswith("coulomb_friction")
               and not n.endswith(":presliding")]
    assert step.parameters[name] != 0.0 and abs(step.parameters[name]) > 3 * step.std[name]
