"""Thesis section 4.8 side by side: the structures on the virtual test bed, one rig effect at a time.

Usage (from the checkout, the venv's python)::

    python docs/identification/section_4_8.py runs  OUT          # record the runs (minutes each)
    python docs/identification/section_4_8.py compare OUT LABEL  # fit one pair (one process each)
    python docs/identification/section_4_8.py write OUT          # section_4_8.md from OUT/*.json

Each pair is an APRBS training run (``aprbs_training.json``, 180 s) and a long-stroke ramp
validation run (``ramps_long_stroke.json``: the motor ramps over 0.2 m at 0.02 m/s, three
cycles in the first 60 s, thesis 4.2 / Fig. 4.3, the linear motor's travel being ~0.3 m,
thesis ch. 3), recorded on the virtual test bed with one set of rig imperfections (:data:`PAIRS`).
The fast structures are compared (``panto compare``'s library function); the friction
oscillators and the FMU-in-the-loop model take minutes each and are left out (their default-rig
figures are in comparison_full.md).
"""
from __future__ import annotations

import json
import sys
from dataclasses import replace
from importlib.resources import files
from pathlib import Path

from panto.rig.imperfections import RigImperfections
from panto.rig.profiles import load_profile

HERE = Path(__file__).resolve().parent
STRUCTURES = ("physical-linear", "blackbox-6", "blackbox-4", "three-mass", "two-mass")
#: The thesis' table (fit %, training APRBS / validation ramps), by our structure names.
THESIS = {"physical-linear": (44.7, 84.0), "blackbox-6": (35.9, 69.0), "blackbox-4": (45.8, 63.1),
          "three-mass-friction": (13.0, 83.7), "three-mass": (15.1, 76.8),
          "two-mass-friction": (11.4, 21.1), "two-mass": (10.6, -76.0)}
#: Rig imperfections per pair: the rig as the thesis describes it, the ideal rig, one effect.
PAIRS = {
    "default": RigImperfections(),
    "ideal": RigImperfections.none(),
    "friction": RigImperfections().with_only("hinge_friction_torque"),
    "sensor-noise": RigImperfections().with_only("force_noise", "laser_noise", "force_quantum",
                                                 "laser_quantum", "pressure_noise"),
    "bar-and-contact": RigImperfections().with_only("bar_mass", "unilateral_contact"),
    "robot-10x": replace(RigImperfections(), robot_compliance=1e-5, robot_damping_ratio=0.02),
    "default-short-ramps": RigImperfections(),
}
#: Pairs validated on the unchanged ``ramps_validation.json`` (5 cm motor ramps) instead.
SHORT_RAMPS = ("default-short-ramps",)


def long_stroke_ramps():
    """The embedded profile ``ramps_long_stroke.json``: motor ramps over 0.2 m at 0.02 m/s."""
    return load_profile(files("panto.rig") / "profiles" / "ramps_long_stroke.json")


def record_runs(out: Path) -> None:
    """Record every pair's training and validation run into ``out/runs/LABEL-{train,val}``."""
    from panto.build_fmu.project import project_fmu
    from panto.rig.virtual import run_virtual_profile

    fmu = project_fmu("Pantograph")
    training = load_profile(files("panto.rig") / "profiles" / "aprbs_training.json")
    for label, imperfections in PAIRS.items():
        validation = (load_profile(files("panto.rig") / "profiles" / "ramps_validation.json")
                      if label in SHORT_RAMPS else long_stroke_ramps())
        for kind, profile, seed in (("train", training, 1), ("val", validation, 2)):
            folder = out / "runs" / f"{label}-{kind}"
            if not folder.exists():
                run_virtual_profile(profile, fmu_path=fmu, folder=folder, seed=seed,
                                    imperfections=imperfections)


def compare_pair(out: Path, label: str) -> None:
    """Fit :data:`STRUCTURES` on one pair; write ``out/LABEL.json``."""
    from panto.identification.data.datasets import pantograph_data
    from panto.identification.estimation.comparison import compare_structures
    from panto.identification.structures.registry import comparison_identifiers

    train = pantograph_data(out / "runs" / f"{label}-train", rate=50.0)
    validation = pantograph_data(out / "runs" / f"{label}-val", rate=50.0)
    table = compare_structures(train, validation, structures=comparison_identifiers(STRUCTURES))
    rows = {r.structure: {"training": dict(r.fit_training), "validation": dict(r.fit_validation),
                          "n_free": r.n_free, "success": r.success} for r in table.rows}
    (out / f"{label}.json").write_text(json.dumps(rows, indent=1))


def write_page(out: Path, target: Path = HERE / "section_4_8.md") -> None:
    """The page: the thesis' table beside ours (default rig, ideal rig) and the effect sweep."""
    results = {label: json.loads((out / f"{label}.json").read_text())
               for label in PAIRS if (out / f"{label}.json").exists()}
    lines = [HEAD, "",
             "| structure | thesis APRBS / ramps | default rig F_c: APRBS / ramps | ideal rig F_c: "
             "APRBS / ramps | why |", "|---|---|---|---|---|"]
    for name, (train, val) in THESIS.items():
        cells = []
        for label in ("default", "ideal"):
            row = results.get(label, {}).get(name)
            cells.append(f"{row['training']['F_c']:.1f} / {row['validation']['F_c']:.1f}"
                         if row else "not run")
        lines.append(f"| {name} | {train:g} / {val:g} | {cells[0]} | {cells[1]} | {WHY[name]} |")
    lines += ["", "One rig effect at a time (both runs of the pair carry only that effect; "
              "fit of F_c / y_cb on the long-stroke ramps [%]; the last row on the 5 cm ramps):", "",
              "| rig | " + " | ".join(STRUCTURES) + " |", "|---" * (len(STRUCTURES) + 1) + "|"]
    for label, rows in results.items():
        lines.append(f"| {label} | " + " | ".join(
            f"{rows[s]['validation']['F_c']:.1f} / {rows[s]['validation']['y_cb']:.1f}"
            for s in STRUCTURES) + " |")
    lines += ["", TAIL, ""]
    target.write_text("\n".join(lines))


HEAD = """# Thesis section 4.8 on the virtual test bed: the comparison side by side

The thesis' table (section 4.8) against the same structures fitted here on the virtual test bed:
trained on the 180 s APRBS run, validated (free run) on long-stroke ramps (the motor ramps over
0.2 m at 0.02 m/s, three cycles in the first 60 s, pressure ramps as in `ramps_validation.json`;
the thesis: "during the first 60 s the linear motor is moving", travel ~0.3 m). Fits are of the
force F_c (the thesis' table gives one number per run). Identification at 50 Hz as in the thesis.

Reproduce (the runs take about 3-5 minutes each on this 2-core machine, a pair's fits 1-7 min):

```bash
python docs/identification/section_4_8.py runs out/s48
for label in default ideal friction sensor-noise bar-and-contact robot-10x; do
    python docs/identification/section_4_8.py compare out/s48 $label
done
python docs/identification/section_4_8.py write out/s48
```

The fast check of the finding that holds is `tests/test_section_4_8.py`."""

TAIL = """## What this shows

- **The rig effects mask what the ideal rig shows.** On the nominal pantograph measured perfectly
  (`ideal`), the oscillators validate 13-16 points below the physical model and the black boxes
  on the force (83.0-85.8 against 98.5-99.4 %): their structure, not their order (the 4-state
  black box reaches 98.5 %), limits them. On the default rig the gap is 5-6 points.
- **What closes the gap, one effect at a time:** the hinge friction (physical model 99.4 -> 91.4 %,
  oscillators unchanged) and the bar's inertia with contact loss (99.4 -> 88.8 %) cost the better
  structures most; sensor noise and a ten times softer robot mode change almost nothing.
- **The long stroke is not the missing mechanism:** on the default rig, 0.2 m ramps cost every
  structure about 4 points against the 5 cm ramps (last row) and leave the gap as it is.
  (comparison_full.md's 88.8-92.2 % for every structure was recorded by an earlier code version;
  the same runs re-fitted today give the last row, with the same 5-6 point gap.)
- **The two-mass oscillator does not fail:** it stays within 3 points of the three-mass on every
  rig tried (sometimes above it). The thesis' -76 % (21.1 % with friction) and its 'three-mass
  very good' are not reproduced by any emulated effect. The likeliest causes lie outside what
  the emulation carries: the thesis' training force was dominated by the rig's spurious
  oscillations (its APRBS fits of 10-46 % against ours of ~60 % on the default rig), which leave a
  low-order structure fitted by a genetic algorithm free to settle on a wrong static gain, and
  its own remark that the 6-state black box stopped in a local optimum shows its fits did not
  always reach their optimum. Ours start from the data's best linear approximation.
- **The thesis' training order is not reproduced either:** the oscillators' APRBS fits are within
  two points of the physical model's here; the emulated bar and robot add far less spurious
  force than the thesis' rig did."""

#: Per row: why ours agrees with the thesis or not.
WHY = {
    "physical-linear": "agrees: best on the ramps with the black boxes (both rigs); our training fit is "
                       "higher because the emulated bar/robot add less spurious force than the real rig",
    "blackbox-6": "agrees with the physical model on validation as in the thesis; the thesis' "
                  "6-state training fit below the 4-state one was a local optimum (its words), "
                  "ours starts from a subspace estimate",
    "blackbox-4": "the thesis' 63.1 % on the ramps is not reproduced: our 4-state black box "
                  "matches the 6-state one (4 states suffice for this plant's linear response)",
    "three-mass-friction": "not run here (minutes per fit); 90.5 % on the default short-stroke "
                           "ramps in comparison_full.md",
    "three-mass": "below the physical model (13.6 points on the ideal rig, 5 on the default); "
                  "not 'very good' relative to the two-mass",
    "two-mass-friction": "not run here; 92.2 % on the default short-stroke ramps "
                         "(comparison_full.md): the thesis' 21.1 % is not reproduced",
    "two-mass": "does NOT fail: within a few points of the three-mass on every rig tried; "
                "the thesis' -76 % is not reproduced by any emulated effect",
}


if __name__ == "__main__":
    command, folder = sys.argv[1], Path(sys.argv[2])
    folder.mkdir(parents=True, exist_ok=True)
    {"runs": lambda: record_runs(folder), "compare": lambda: compare_pair(folder, sys.argv[3]),
     "write": lambda: write_page(folder)}[command]()
