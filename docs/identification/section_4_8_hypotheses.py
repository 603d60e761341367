"""Thesis section 4.8: three hypotheses for the two-mass oscillator's failure, measured.

Usage (from the checkout, the venv's python; RUNS is the ``runs`` folder that
``section_4_8.py runs OUT`` records, e.g. ``OUT/runs``)::

    cd docs/identification
    python section_4_8_hypotheses.py static RUNS LABEL                     # hypothesis 1
    python section_4_8_hypotheses.py sweep RUNS LABEL                      # 1, k1 held
    python section_4_8_hypotheses.py ga RUNS LABEL MASSES SEED OUT.json [POPULATION GENERATIONS]

Hypothesis 1 (static stiffness over the stroke): the static gains ``dF_c/deta``, ``dF_c/dp``,
``dy_cb/deta``, ``dy_cb/dp`` of the fitted oscillators (Levenberg-Marquardt from the static start,
the comparison's path) against the pantograph's own (its linearisation about the static
equilibrium, :func:`panto.identification.structures.linearisation.linearise`, at heights over the
long stroke). The DC gain of a linear model ``(A, B, C, D)`` is ``D - C A^-1 B``.

Hypothesis 2 (``ga``, the thesis' optimiser): NSGA-II on the two objectives (fit of ``y_cb`` and of
``F_c``, thesis 4.1.3) with the thesis' free parameters (masses, springs, dampers, ``k_E`` and the
pressure gain: 8 for the two-mass, 11 for the three-mass, thesis table 4.8; plus the two levels
``F_0`` and ``y_cb_offset`` that the thesis removed by working about the measured equilibrium),
random initial population (no subspace or static start), several seeds. Every member of the final
Pareto front is validated on the ramps, so the spread a user's pick (thesis: "the user has to
choose") can produce is measured.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

#: Pressure [bar] and heights [m] at which the pantograph's static gains are evaluated.
PRESSURE = 4.4
HEIGHTS = (1.90, 1.95, 2.00, 2.05, 2.10)
#: Base-spring stiffnesses [N/m] the slope sweep holds (hypothesis 1).
SWEEP_K1 = (0.1, 100.0, 300.0, 1000.0, 3000.0)
#: NSGA-II settings of hypothesis 2 (the thesis used 1000 individuals; see the page).
POPULATION, GENERATIONS = 150, 50
#: GA bounds of the levels (the structure's +-1e5 N / +-1 m would leave the search to the levels).
LEVEL_BOUNDS = {"F_0": (-3000.0, 3000.0), "y_cb_offset": (-0.5, 0.5)}


def dc_gain(a, b, c, d) -> np.ndarray:
    """Static gain ``D - C A^-1 B`` of a stable continuous linear model."""
    return np.asarray(d) - np.asarray(c) @ np.linalg.solve(np.asarray(a), np.asarray(b))


def pantograph_gains(heights=HEIGHTS, pressure: float = PRESSURE) -> dict[float, np.ndarray]:
    """The nominal pantograph's static gains per height: rows (F_c, y_cb), columns (eta, p)."""
    from panto.identification.structures.physical import PhysicalLinear

    structure = PhysicalLinear(outputs=("F_c", "y_cb"))
    out = {}
    for eta in heights:
        a, b, c, d, _, _ = structure.linear_model({}, (eta, pressure))
        out[eta] = dc_gain(a, b, c[[2, 0]], d[[2, 0]])
    return out


def pantograph_force(heights=HEIGHTS, pressure: float = PRESSURE) -> dict[float, float]:
    """The nominal pantograph's static contact force [N] per height (its static characteristic)."""
    from panto.identification.structures.physical import PhysicalLinear

    structure = PhysicalLinear(outputs=("F_c", "y_cb"))
    return {eta: float(structure.linear_model({}, (eta, pressure))[5][2]) for eta in heights}


def oscillator_gains(structure, parameters) -> np.ndarray:
    """An oscillator's static gains: rows (F_c, y_cb), columns (eta, p)."""
    a, b, c, d = structure.matrices(parameters)
    return dc_gain(a, b[:, :2], c[[2, 0]], d[[2, 0]][:, :2])


def load_pair(runs: Path, label: str):
    """Training (APRBS) and validation (ramps) identification data of one recorded pair, 50 Hz."""
    from panto.identification.data.datasets import pantograph_data

    return (pantograph_data(runs / f"{label}-train", rate=50.0),
            pantograph_data(runs / f"{label}-val", rate=50.0))


def validation_fit(structure, parameters, validation) -> dict[str, float]:
    """Free-run fit [%] of each output on the validation run."""
    from panto.identification.estimation.base import fit_percent

    simulated = structure.simulate(parameters, validation.select_outputs(structure.output_names))
    return {name: float(fit_percent(validation.output(name), simulated[:, j]))
            for j, name in enumerate(structure.output_names)}


def hypothesis_static(runs: Path, label: str) -> dict:
    """Hypothesis 1: fitted oscillators' static gains against the pantograph's, with their fits."""
    from panto.identification.structures.oscillators import OscillatorStructure, identify_oscillator

    train, validation = load_pair(runs, label)
    out = {"pantograph": {f"{h:.2f}": g.tolist() for h, g in pantograph_gains().items()},
           "pantograph_force": {f"{h:.2f}": f for h, f in pantograph_force().items()},
           "fits": {}}
    for masses in (2, 3):
        result = identify_oscillator(train, masses=masses, friction=False)
        structure = OscillatorStructure(masses, outputs=train.output_names)
        out["fits"][structure.name] = {
            "parameters": dict(result.parameters), "training": dict(result.fit),
            "validation": validation_fit(structure, result.parameters, validation),
            "gains": oscillator_gains(structure, result.parameters).tolist()}
    return out


def hypothesis_sweep(runs: Path, label: str, values=SWEEP_K1) -> dict:
    """Hypothesis 1, the cost of a wrong slope: ``k1`` held at each value, the rest refitted by LM;
    the training and validation fits and ``dF_c/deta`` of each (two- and three-mass)."""
    from panto.identification.structures.oscillators import OscillatorStructure, identify_oscillator

    train, validation = load_pair(runs, label)
    out = {}
    for masses in (2, 3):
        structure = OscillatorStructure(masses, outputs=train.output_names)
        free = tuple(n for n in structure.default_free() if n != "k1")
        rows = []
        for k1 in values:
            result = identify_oscillator(train, masses=masses, friction=False, free=free,
                                         fixed={"k1": float(k1)})
            rows.append({"k1": float(k1), "training": dict(result.fit),
                         "validation": validation_fit(structure, result.parameters, validation),
                         "gains": oscillator_gains(structure, result.parameters).tolist()})
        out[structure.name] = rows
    return out


def hypothesis_ga(runs: Path, label: str, masses: int, seed: int, population: int = POPULATION,
                  generations: int = GENERATIONS) -> dict:
    """Hypothesis 2: the thesis' GA; every front member's training and validation fits, gains."""
    from panto.identification.estimation.genetic import fit_pareto
    from panto.identification.structures.oscillators import OscillatorStructure

    train, validation = load_pair(runs, label)
    structure = OscillatorStructure(masses, outputs=("y_cb", "F_c"))
    free = tuple(n for n in structure.parameter_names if n not in ("y_0",))
    bounds = {**{n: structure.bounds()[n] for n in free}, **LEVEL_BOUNDS}
    start = time.perf_counter()
    pareto = fit_pareto(structure, train.select_outputs(("y_cb", "F_c")), free=free,
                        bounds=bounds, population=population, generations=generations,
                        seed=seed, initial={"y_0": float(train.input("eta")[0])})
    front = []
    for parameters, fits in zip(pareto.front, pareto.objectives):
        front.append({"training": dict(zip(pareto.objective_names, fits.tolist())),
                      "validation": validation_fit(structure, parameters, validation),
                      "gains": oscillator_gains(structure, parameters).tolist(),
                      "parameters": dict(parameters)})
    return {"structure": structure.name, "seed": seed, "free": list(free),
            "population": population, "generations": generations,
            "seconds": time.perf_counter() - start, "front": front}


if __name__ == "__main__":
    command, folder, pair = sys.argv[1], Path(sys.argv[2]), sys.argv[3]
    if command == "static":
        print(json.dumps(hypothesis_static(folder, pair), indent=1))
    elif command == "sweep":
        print(json.dumps(hypothesis_sweep(folder, pair), indent=1))
    else:
        sizes = [int(a) for a in sys.argv[7:9]]
        result = hypothesis_ga(folder, pair, int(sys.argv[4]), int(sys.argv[5]), *sizes)
        Path(sys.argv[6]).write_text(json.dumps(result, indent=1))
