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
    lines += ["", TAIL, "", HYPOTHESES, ""]
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
- **The two-mass oscillator does not fail when fitted to its optimum:** from the static start
  (Levenberg-Marquardt) it stays within 3 points of the three-mass on every rig tried
  (sometimes above it). It does fail, and the three-mass holds, when its base spring k1 is left
  stiff, as a genetic algorithm started from a random population leaves it: see "Hypotheses
  tried, session 27" below (mechanism reproduced; what the thesis' own fit did is not known).
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
                  "holds (67.7-82.5 %) where the two-mass fails: with a stiff base spring it "
                  "routes the compliance through k2 (session 27 below)",
    "two-mass-friction": "not run here; 92.2 % on the default short-stroke ramps "
                         "(comparison_full.md): the thesis' 21.1 % is not reproduced",
    "two-mass": "fitted to its optimum it does not fail (no emulated rig effect makes it); with "
                "its base spring k1 held at 1000 N/m it does: -41.7 % here, -76.3 % on the "
                "nominal FMU (session 27 below: its static slope is -k1)",
}

#: The session-27 section of the page (hypotheses for the two-mass oscillator's failure).
HYPOTHESES = """## Hypotheses tried, session 27

Helper: `docs/identification/section_4_8_hypotheses.py` (run from `docs/identification`; RUNS is
the `runs` folder of `section_4_8.py runs OUT`). Pair `default` unless stated; fits of F_c,
training APRBS / validation long-stroke ramps [%].

**Hypothesis 1, the static force-vs-height slope: reproduces the failure, given a stiff base
spring.** (`python section_4_8_hypotheses.py static RUNS default`, `... sweep RUNS default`,
`... sweep RUNS ideal`; 1-2 min each.)

- The pantograph's own static slope (nominal model linearised at its equilibrium, 4.4 bar) is
  dF_c/d eta = +36.4, +36.7, +37.0, +37.2, +37.3 N/m at eta = 1.90 ... 2.10 m (static force
  116.4 -> 123.7 N): positive and nearly constant, so the stroke's nonlinearity is negligible
  (7 N over 0.2 m). What matters is the model's slope.
- An oscillator's slope is minus the series stiffness of all its springs (k1, k2, [k3], k_E),
  always negative (checked analytically in `tests/test_section_4_8.py`); the best a fit can do is
  make the chain soft. Both fitted oscillators put k1 at its lower bound 0.1 N/m (slope -0.1 N/m,
  dF_c/dp 96.2 and 97.9 N/bar against the pantograph's 97.2).
- Held at a stiffer k1 (the rest refitted by LM), the two-mass oscillator has no other spring
  below the cross bar to make the chain soft, so its slope is about -k1; the three-mass
  oscillator makes k2 soft instead and keeps a small slope (from k1 = 300 N/m on; at 100 N/m its
  LM stayed in the two-mass-like optimum):

| k1 held [N/m] | two-mass default | slope | three-mass default | slope | two-mass ideal | three-mass ideal |
|---|---|---|---|---|---|---|
| 0.1 (free) | 58.8 / 82.2 | -0.1 | 61.1 / 81.6 | -0.1 | 96.9 / 83.0 | 96.9 / 85.7 |
| 100 | 58.5 / 70.8 | -98.5 | 60.9 / 72.4 | -82.5 | 95.2 / 75.0 | 95.2 / 74.9 |
| 300 | 57.1 / 44.6 | -287.5 | 60.9 / 79.3 | -27.9 | 90.3 / 49.7 | 96.9 / 82.9 |
| 1000 | 48.4 / **-41.7** | -878.3 | 60.6 / **73.3** | -78.7 | 73.3 / -39.8 | 96.8 / 82.5 |
| 3000 | 24.4 / -177.9 | -1799.5 | 59.9 / 67.7 | -121.1 | 33.7 / -242.1 | 96.3 / 80.8 |

- The APRBS (motor std 2 cm) sees little of the slope, the long ramps (0.2 m) all of it: on the
  default rig k1 = 1000 N/m costs the two-mass 10.4 points of training fit and 124 points on
  the ramps; on the ideal rig 23.6 and 123. The rig's spurious force (default rig) cuts what
  the training fit can tell about the slope to less than half; the thesis' rig, with training
  fits of 10-15 %, told even less.
- On the nominal Pantograph FMU (20 s runs, the test's data): two-mass free 97.0 / 93.1, k1 held
  at 1000 N/m 67.4 / **-76.3**; three-mass free 97.1 / 92.9, held 96.8 / **89.9** (slopes -900.8
  and -15.1 N/m). This is the thesis' pattern (two-mass fails completely, three-mass holds).
  `tests/test_section_4_8.py::test_a_stiff_base_spring_pins_the_two_mass_slope_but_not_the_three_mass_one`
  holds it (slopes either side of -k1/2, the two-mass below the three-mass on the ramps, the
  two-mass' loss larger on the ramps than on the APRBS).

**Hypothesis 2, the thesis' optimiser: it leaves k1 stiff, and then the two-mass fails; not
every run does.** (`python section_4_8_hypotheses.py ga RUNS default MASSES SEED OUT.json
[POPULATION GENERATIONS]`: NSGA-II (pymoo), objectives 100 - fit of y_cb and of F_c as in
thesis 4.1.3, random initial population within the structure's bounds, free: masses, springs,
dampers, k_E and the pressure gain (the thesis' 8 / 11 parameters) plus the levels F_0 (+-3000 N)
and y_cb_offset (+-0.5 m); every member of the final Pareto front validated on the ramps.)

| run | two-mass: best training F_c | knee pick F_c train / ramps, slope | front on the ramps | three-mass: best training F_c | knee pick train / ramps, slope | front on the ramps |
|---|---|---|---|---|---|---|
| 150 x 50, seed 1 | 28.5 | 4.9 / -116.5, -1246 N/m | -524 .. -15 | 37.7 | 29.4 / 1.6, -339 N/m | -183 .. 23 |
| 150 x 50, seed 2 | 27.0 | 17.6 / -44.1, -660 N/m | -2756 .. 20 | 56.3 | 56.0 / 66.0, -0.1 N/m | -42 .. 66 |
| 150 x 50, seed 3 | 26.8 | -22.1 / -310.0, -2775 N/m | -11877 .. 6 | 51.4 | 31.1 / -31.7, -677 N/m | -60 .. 38 |
| 1000 x 30 (thesis' population), seed 7 | 41.6 | 39.0 / 57.0, -53 N/m | -808 .. 59 | 36.7 | 33.9 / 27.3, -5 N/m | 18 .. 38 |

- Seconds per run: 56-91 (two-mass), 71-132 (three-mass) at 150 x 50; 279 and 251 at 1000 x 30.
- Over the three 150 x 50 fronts, 105 of 122 two-mass members have a slope steeper than
  -500 N/m (median ramp fit -191 %); 20 of 34 three-mass members keep it within 100 N/m (median
  56.6 %). In every member of the three-mass front of the 1000 x 30 run k1 is stiff (809 N/m - 26 kN/m) and
  k2 soft (3.5-134 N/m): the GA finds the three-mass' escape, not the two-mass' one (k1 itself
  small).
- The GA's training fits (27-56 % on F_c) are far below LM's (58.8 / 61.1 %) and in the range
  of the thesis' 10.6 / 15.1 %; LM started from the GA's knee picks ends where LM from the static
  start does (two-mass seeds 1 and 3: k1 -> 0.1 N/m, 58.8 / 83.4 %; three-mass seed 3: 61.0 /
  85.1 %). The failure is the unfinished search's, not the structure's optimum.
- Not reproduced as a number: the two-mass knee pick ranges from -310 to +57 % with the seed
  and the population, the three-mass from -32 to 66 %; the thesis' -76 / 76.8 % lies inside
  these spreads, and the thesis does not state its bounds, generations or which Pareto member
  it chose, so which of these runs it resembles cannot be decided.

**Hypothesis 3, the thesis' data: not tested, nothing to change.** The thesis gives no APRBS
levels or hold times and no ramp heights or gradients; the facts it does give (the linear
motor's ~0.3 m travel, at most 5 mm per sample, the motor moving in the first 60 s of the ramps,
500 Hz resampled to 50 Hz, 20 Hz low-pass) are what the runs already use. Note its text
disagrees with itself on which run trained the oscillators (4.6: "the step sequence from Figure
4.3"; the table's caption: training "the ARBS signal from Figure 4.3", validation "Figure 4.2";
4.2 and 4.5: Figure 4.2 is the APRBS, 4.3 the ramps); the runs here follow 4.2 and 4.5.

**Conclusion.** The two-mass oscillator's failure on the ramps while the three-mass holds is
reproduced by one mechanism, with numbers: the two-mass' static force slope is minus its base
spring's stiffness whenever that spring is not soft, the APRBS's short stroke barely penalises
it, the long ramps multiply it; the three-mass can keep a soft chain with a stiff base spring.
A genetic search from a random population (the thesis' optimiser) ends with a stiff two-mass
base spring in most runs here (the knee picks of all three 150 x 50 runs: slopes -660 to
-2775 N/m; 105 of 122 front members steeper than -500 N/m); the one run at the thesis'
population size did not (knee -53 N/m, 57.0 % on the ramps). The rig emulation needs no new effect
for it; a fit carried to its optimum (LM from the static start, as `panto identify` does) does
not show it."""


if __name__ == "__main__":
    command, folder = sys.argv[1], Path(sys.argv[2])
    folder.mkdir(parents=True, exist_ok=True)
    {"runs": lambda: record_runs(folder), "compare": lambda: compare_pair(folder, sys.argv[3]),
     "write": lambda: write_page(folder)}[command]()
