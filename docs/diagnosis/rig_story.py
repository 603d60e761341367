"""The thesis' rig story, reproduced on the virtual test bed (issue 8, "Proven on data whose effect
is withheld", last point). An example script, not a test (it takes minutes: three virtual runs and
a diagnosis with up to three refit rounds).

    .venv/bin/python docs/diagnosis/rig_story.py [--duration 40] [--out docs/diagnosis]

The rig has only two imperfections on (plus sensor noise): the aluminium bar between the force
sensor and the pantograph (``bar_mass`` 1.5 kg, thesis chapter 3: ``F_sensor = F_c - m_bar
a_bar``) and Coulomb friction in the lower-arm hinge (``hinge_friction_torque`` 20 N m). The
nominal is the linearised physical model (Table 4.1 free), fitted on an APRBS training run; the
diagnosis is judged on a withheld run (another APRBS realisation) and the story is checked on a
third, slow ramp run (the thesis' validation kind, Fig. 4.3):

1. *where*: the force residual's share above 2 Hz, and its RMS during the linear motor's strongest
   accelerations (top 10 % of ``|eta''|``) against the rest (the bar's inertia), and during slow
   motion (``1 < |eta'| < 10`` mm/s, the ramps' 5 mm/s: friction);
2. *which*: the diagnosis' accepted effects, in order;
3. *how far*: each effect's share of the validation gap removed, and the ramp run's force fit
   with the nominal and with the final model.

Writes ``rig_story.json`` and ``rig_story.md`` into ``--out``.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def record(folder: Path, profile_name: str, seed: int, duration: float, cutoff: float | None):
    """A virtual run with the bar and the hinge friction on; the data the diagnosis sees."""
    from build_fmu.project import project_fmu
    from identification.diagnosis_benchmark import blind_data
    from rig.dataset import read_dataset
    from rig.imperfections import RigImperfections
    from rig.profiles import load_profile
    from rig.virtual import run_virtual_profile

    base = load_profile(ROOT / "rig" / "profiles" / f"{profile_name}.json")
    profile = dataclasses.replace(base, duration=duration, seed=base.seed + seed)
    if cutoff is not None:
        profile = dataclasses.replace(profile, conditioning=dataclasses.replace(
            profile.conditioning, filter_cutoff=cutoff))
    imperfections = dataclasses.replace(RigImperfections.none(), bar_mass=1.5,
                                        hinge_friction_torque=20.0, force_noise=1.0,
                                        laser_noise=1.5e-3)
    run_virtual_profile(profile, fmu_path=project_fmu("Pantograph"), folder=folder,
                        imperfections=imperfections, seed=seed)
    return blind_data(read_dataset(folder))


def locate(data, residual: np.ndarray) -> dict[str, float]:
    """Where the force residual lies: high band, strong acceleration, slow motion."""
    from scipy import signal as sps

    from identification.rigid_body import motion

    dt = data.sample_period
    velocity, acceleration = motion(data.input("eta"), dt, 0.4)[:2]
    r = residual - np.mean(residual)
    high = sps.sosfiltfilt(sps.butter(4, 2.0, "highpass", fs=1 / dt, output="sos"), r)
    strong = np.abs(acceleration) >= np.quantile(np.abs(acceleration), 0.9)
    slow = (np.abs(velocity) > 1e-3) & (np.abs(velocity) < 0.01)  # ramps: 5 mm/s
    rms = lambda x: float(np.sqrt(np.mean(x ** 2))) if len(x) else float("nan")
    return {"share_above_2_hz": float(np.sum(high ** 2) / np.sum(r ** 2)),
            "rms_strong_acceleration_N": rms(r[strong]), "rms_other_N": rms(r[~strong]),
            "high_band_rms_strong_acceleration_N": rms(high[strong]),
            "high_band_rms_other_N": rms(high[~strong]),
            "rms_slow_motion_N": rms(r[slow]), "rms_not_slow_N": rms(r[~slow])}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=40.0)
    parser.add_argument("--out", default=str(ROOT / "docs" / "diagnosis"))
    args = parser.parse_args()
    from identification.base import fit_percent
    from identification.diagnosis import diagnose

    with tempfile.TemporaryDirectory() as root:
        train = record(Path(root) / "train", "aprbs_training", 41, args.duration, None)
        validation = record(Path(root) / "validate", "aprbs_training", 42, args.duration, None)
        ramps = record(Path(root) / "ramps", "ramps_validation", 43, 60.0, None)
    result = diagnose(train, validation, structure="physical-linear", progress=print)
    j = validation.output_names.index("F_c")
    before = validation.outputs[:, j] - result.series["before"][:, j]
    after = validation.outputs[:, j] - result.series["after"][:, j]
    from identification.diagnosis import _Model, _simulate  # the final model on the ramp run

    nominal = result.nominal_parameters
    structure_nominal = _nominal_structure(train)
    ramp_before = _simulate(_Model(structure_nominal, dict(nominal), ()), ramps)
    steps = [{"effect": s.effect, "fit_before": dict(s.fit_before), "fit_after": dict(s.fit_after),
              "energy_removed": dict(s.energy_removed), "parameters": dict(s.parameters),
              "std": dict(s.std)} for s in result.steps]
    report = {
        "verdict": result.verdict, "effects": list(result.effects),
        "validation_fit_before": dict(result.fit_before),
        "validation_fit_after": dict(result.fit_after), "steps": steps,
        "where_validation_before": locate(validation, before),
        "where_validation_after": locate(validation, after),
        "where_text": result.where.get("text", ""),
        "ramps_fit_nominal": {o: float(fit_percent(ramps.outputs[:, k], ramp_before[:, k]))
                              for k, o in enumerate(ramps.output_names)},
        "where_ramps_nominal": locate(ramps, ramps.outputs[:, j] - ramp_before[:, j]),
        "truth": {"bar_mass_kg": 1.5, "hinge_friction_torque_Nm": 20.0}}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "rig_story.json").write_text(json.dumps(report, indent=2, default=float))
    (out / "rig_story.md").write_text(_markdown(report))
    print(json.dumps(report, indent=2, default=float))
    return 0


def _nominal_structure(train):
    from identification.diagnosis_support import build_structure

    return build_structure("physical-linear", train, {})[0]


def _markdown(report: dict) -> str:
    w, wa = report["where_validation_before"], report["where_validation_after"]
    lines = ["# The thesis' rig story on the virtual test bed", "",
             "`.venv/bin/python docs/diagnosis/rig_story.py`: bar 1.5 kg + hinge friction 20 N m "
             "(hidden), nominal `physical-linear`, APRBS training, withheld APRBS validation, "
             "and a slow ramp run.", "",
             f"Verdict: **{report['verdict']}** ({', '.join(report['effects']) or '-'}).", "",
             "| step | effect | F_c fit before -> after | y_cb fit before -> after | "
             "F_c energy removed |", "|---|---|---|---|---|"]
    for i, s in enumerate(report["steps"], 1):
        lines.append(f"| {i} | {s['effect']} | {s['fit_before']['F_c']:.1f} -> "
                     f"{s['fit_after']['F_c']:.1f} % | {s['fit_before']['y_cb']:.1f} -> "
                     f"{s['fit_after']['y_cb']:.1f} % | {100 * s['energy_removed']['F_c']:.0f} % |")
    lines += ["", "Where the force residual lies (validation; nominal -> final model):", "",
              "| measure | nominal | final |", "|---|---|---|"]
    lines += [f"| {k} | {w[k]:.3g} | {wa[k]:.3g} |" for k in w]
    lines += ["", f"Ramp run, nominal force fit {report['ramps_fit_nominal']['F_c']:.1f} %; "
              f"force residual RMS in slow motion {report['where_ramps_nominal']['rms_slow_motion_N']:.2f}"
              f" N against {report['where_ramps_nominal']['rms_not_slow_N']:.2f} N elsewhere.", "",
              f"Diagnosis' own summary of where: {report['where_text']}", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
