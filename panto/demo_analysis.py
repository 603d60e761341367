"""Steps 3-6 of the main job: identification, diagnosis, design of experiments, co-simulation.

Same contract as :mod:`panto.demo_steps`: ``step(state, progress) -> dict``.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

Progress = Callable[[str], None]

#: Static contact force [N] the co-simulated pantograph is set to by its bellow pressure: the
#: EN 50318:2002 reference pantograph's uplift force (120 N), so its mean force can be set
#: beside the acceptance range (110-120 N at 300 km/h).
TARGET_STATIC_FORCE = 120.0


def identify_models(state: dict[str, Any], progress: Progress) -> dict:
    """Step 3: the comparison table, the physical model's parameter file, Pareto front and
    eigenvalue sensitivity."""
    from panto.identification.estimation.comparison import compare_structures
    from panto.identification.estimation.plots import plot_comparison, plot_validation
    from panto.identification.data.datasets import pantograph_data
    from panto.identification.structures.physical import PhysicalLinear
    from panto.identification.structures.registry import comparison_identifiers, parameter_set
    from panto.identification.estimation.reporting import parameter_records, write_identification

    out, settings = state["out"], state["settings"]
    train = pantograph_data(state["runs"]["training"], rate=50.0)
    validation = pantograph_data(state["runs"]["validation"], rate=50.0)
    state["data"] = (train, validation)
    limit = {"max_evaluations": settings.max_evaluations} if settings.max_evaluations else {}
    identifiers = comparison_identifiers(settings.structures)
    # what the run cannot pin is fixed at its prior rather than run to a bound
    physical_options = {**limit, "fix_unidentifiable": True}
    table = compare_structures(train, validation, structures=identifiers, progress=progress,
                               options={"physical-linear": physical_options} if any(
                                   i.name == "physical-linear" for i in identifiers) else None)
    folder = out / "comparison"
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "comparison.md").write_text(table.to_markdown() + "\n")
    table.to_csv(folder / "comparison.csv")
    table.write_json(folder / "comparison.json")
    plot_comparison(table, folder / "comparison.png")
    plot_validation(table, validation, folder)
    row = table.row("physical-linear")
    if row.result is None:
        raise RuntimeError(f"physical-linear was not identified: {row.message}")
    result = row.result
    structure = PhysicalLinear(outputs=validation.output_names)
    nominal = structure.nominal()
    paths = write_identification(result, out / "identification", data=train,
                                 validation=validation, nominal=nominal,
                                 parameter_set=parameter_set(result.structure))
    state["identified"] = dict(result.parameters)
    state["parameter_file"] = paths["parameters"]
    nominal_fit = _fits(validation, structure.simulate(nominal, validation))
    summary = {
        "comparison": table.to_dict(), "comparison_markdown": table.to_markdown(),
        "physical": {"parameters": dict(result.parameters), "std": dict(result.std),
                     "fit_training": dict(result.fit), "fit_validation": dict(row.fit_validation),
                     "nominal_fit_validation": nominal_fit,
                     "parameter_file": str(paths["parameters"].relative_to(out)),
                     "not_identifiable": (result.details.get("identifiability") or {})
                     .get("not_identifiable") or {},
                     "estimates": parameter_records(result),
                     "fixed_at_prior": dict(result.details.get("fixed_at_prior", {})),
                     "verdict_rule": (result.details.get("identifiability") or {}).get("rule")},
        "plots": {"fit": "identification/fit.png", "comparison": "comparison/comparison.png"}}
    progress("physical-linear on validation: " + ", ".join(
        f"{o} {row.fit_validation[o]:.1f} % (nominal {nominal_fit[o]:.1f} %)"
        for o in validation.output_names))
    summary["pareto"] = _pareto(structure, train, out, settings, progress)
    summary["sensitivity"] = _sensitivity(result, out, progress)
    return summary


def _fits(data: Any, simulated: np.ndarray) -> dict[str, float]:
    from panto.identification.estimation.base import fit_percent

    values = np.atleast_1d(fit_percent(data.outputs, simulated))
    return {name: float(v) for name, v in zip(data.output_names, values)}


def _pareto(structure: Any, train: Any, out: Any, settings: Any, progress: Progress) -> dict:
    """NSGA-II front of the two fits (thesis Fig. 4.7), its knee polished by LM."""
    from panto.identification.estimation.genetic import fit_pareto
    from panto.identification.estimation.plots import plot_pareto

    if settings.pareto_population <= 0:
        return {"skipped": "population 0"}
    pareto = fit_pareto(structure, train, free=structure.default_free(),
                        population=settings.pareto_population,
                        generations=settings.pareto_generations, seed=1)
    picked = pareto.pick(rule="knee")
    limit = {"max_evaluations": settings.max_evaluations} if settings.max_evaluations else {}
    polished = pareto.polish(picked, train, **limit)
    plot_pareto(pareto, out / "identification" / "pareto.png", picked=picked, polished=polished)
    progress(f"Pareto front: {len(pareto.front)} solutions after {pareto.n_evaluations} "
             f"evaluations; knee {_text(picked.fit)} -> polished {_text(polished.fit)}")
    return {"front_size": len(pareto.front), "evaluations": pareto.n_evaluations,
            "knee_fit": dict(picked.fit), "polished_fit": dict(polished.fit),
            "objectives": np.asarray(pareto.objectives).tolist(),
            "objective_names": list(picked.fit),
            "plot": "identification/pareto.png"}


def _text(fits: dict) -> str:
    return ", ".join(f"{k} {v:.1f} %" for k, v in fits.items())


def _sensitivity(result: Any, out: Any, progress: Progress) -> dict:
    """Eigenvalues of the identified model with each Table 4.1 parameter scaled (Fig. 4.9)."""
    from panto.identification.structures.plots import plot_eigenvalue_sensitivity
    from panto.identification.structures.sensitivity import eigenvalue_sensitivity

    sensitivity = eigenvalue_sensitivity(result)
    plot_eigenvalue_sensitivity(sensitivity, out / "identification" / "eigenvalues.png")
    sensitivity.write_json(out / "identification" / "eigenvalues.json")
    progress("modes " + ", ".join(f"{f:.2f}" for f in sensitivity.natural_frequencies_hz)
             + f" Hz; most influential {', '.join(sensitivity.ranking[:4])}")
    return {"natural_frequencies_hz": sensitivity.natural_frequencies_hz.tolist(),
            "ranking": sensitivity.ranking, "plot": "identification/eigenvalues.png"}


def diagnose_gap(state: dict[str, Any], progress: Progress) -> dict:
    """Step 4: where the physical model misses on the withheld run, and how far the found
    effects close the gap."""
    from panto.identification.diagnosis.pipeline import DiagnosisOptions, diagnose
    from panto.identification.diagnosis.report import write_report

    out, settings = state["out"], state["settings"]
    train, validation = state["data"]
    limit = {"max_evaluations": settings.max_evaluations} if settings.max_evaluations else {}
    if settings.diagnosis_light:
        from panto.identification.estimation.global_fit import (FrequencyFitOptions,
                                                                  GlobalFitOptions)

        limit.update(discovery=False, challenge=False, global_fit=GlobalFitOptions(
            data_starts=1, perturbations=0, polish_evaluations=settings.max_evaluations or 300,
            frequency=FrequencyFitOptions(screening=32, starts=2, max_evaluations=500)))
    options = DiagnosisOptions(max_effects=settings.diagnosis_max_effects, **limit)
    result = diagnose(train, validation, structure="physical-linear", options=options,
                      progress=progress)
    paths = write_report(result, out / "diagnosis", units=train.units)
    closed = result.gap_closed()
    progress(f"verdict {result.verdict} ({', '.join(result.effects) or 'no effect'}); "
             "validation fit " + ", ".join(
        f"{o} {result.fit_before[o]:.1f} -> {result.fit_after[o]:.1f} %"
        for o in result.output_names))
    steps = [{"effect": s.effect, "parameters": dict(s.parameters),
              "std": {k: _finite(v) for k, v in s.std.items()}, "fit_after": dict(s.fit_after),
              "energy_removed": {k: _finite(v) for k, v in s.energy_removed.items()},
              "hinge_torque_Nm": _hinge_torque(s, result.final_parameters)}
             for s in result.steps]
    return {"verdict": result.verdict, "effects": list(result.effects), "steps": steps,
            "rig_truth": rig_truth(validation.metadata.get("dataset", {}).get("truth"),
                                   result.effects),
            "fit_before": dict(result.fit_before), "fit_after": dict(result.fit_after),
            "gap_closed": {k: _finite(v) for k, v in closed.items()},
            "summary": result.summary, "report": str(paths["html"].relative_to(out)),
            "plot": "diagnosis/validation.png"}


def _hinge_torque(step: Any, parameters: Any) -> list[float | None] | None:
    """A friction found as an equivalent bellow pressure ``c`` [bar] in physical-linear, as the
    hinge torque it stands for, ``k_p |c|`` [N m] (the bellow torque is ``k_p p`` on the lower
    arm, reference pantograph_model.md), with its standard deviation; None for other effects."""
    c = step.parameters.get("coulomb_friction:p")
    if c is None or "k_p" not in parameters:
        return None
    k_p = float(parameters["k_p"])
    return [abs(float(c)) * k_p, _finite(float(step.std.get("coulomb_friction:p", math.nan)) * k_p)]


def rig_truth(truth: Any, named: Any) -> list[dict]:
    """What the virtual rig hid (a run's truth record, ``RunMetadata.truth``, which the
    diagnosis never reads) beside what the diagnosis `named`: one row per imperfection that was
    on, with the library effect that stands for it (None: no library effect does; it is absorbed
    by the nominal's parameters or left in the gap). Empty without a truth record (a real rig)."""
    from panto.identification.diagnosis.benchmark import IMPERFECTIONS_OF

    hidden = (truth or {}).get("imperfections") or {}
    effect_of = {name: effect for effect, names in IMPERFECTIONS_OF.items() for name in names}
    extra = ("bellow_angle_coefficient",)  # a model parameter (kappa_p), not a library effect
    rows = []
    for name in (*effect_of, *extra):
        value = hidden.get(name)
        if value:
            effect = effect_of.get(name)
            rows.append({"imperfection": name, "value": value, "effect": effect,
                         "named": bool(effect and effect in named)})
    return rows


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def design_next_run(state: dict[str, Any], progress: Progress) -> dict:
    """Step 5: the D-optimal rig run for the physical model's parameters (thesis 5.5), as a
    rig profile, with the predicted covariance against the APRBS of equal length."""
    from panto.identification.design.constraints import RigInputConstraints
    from panto.identification.design.pantograph import DesignOptions, design_pantograph_experiment
    from panto.identification.design.profiles import write_design_report
    from panto.identification.design.pantograph_sensitivity import LinearisedPantograph

    out, settings = state["out"], state["settings"]
    constraints = RigInputConstraints.from_rig()
    names = set(LinearisedPantograph.structure_for("physical-linear").parameter_names)
    identified = state.get("identified")
    values = {k: v for k, v in (identified or {}).items() if k in names}
    model = LinearisedPantograph(
        "physical-linear", values, None, operating_point=constraints.operating_point(),
        sample_period=constraints.sample_period,
        length=round(settings.doe_duration / constraints.sample_period),
        pressure_lag=constraints.pressure_lag)
    design = design_pantograph_experiment(
        model, constraints, options=DesignOptions(population=settings.doe_population,
                                                  generations=settings.doe_generations, seed=0))
    paths = write_design_report(design, out / "doe")
    summary = design.summary()
    ratios = [row["ratio_conventional_to_designed"] for row in summary["table"]]
    progress(f"{len(ratios)} parameters, {settings.doe_duration:g} s: std APRBS / designed "
             f"median {np.median(ratios):.2f}, det ratio per parameter "
             f"{summary['det_ratio_per_parameter']:.2f}")
    return {"parameters_from": "identified" if values else "nominal (identification failed)",
            "duration_s": settings.doe_duration, "criterion": design.criterion,
            "det_ratio_per_parameter": summary["det_ratio_per_parameter"],
            "median_std_ratio": float(np.median(ratios)), "table": summary["table"],
            "units": dict(LinearisedPantograph.structure_for("physical-linear").units()),
            "min_contact_force_N": summary["min_contact_force_N"],
            "files": {k: str(p.relative_to(out)) for k, p in paths.items()},
            "plots": [str(p.relative_to(out)) for p in paths.values()
                      if str(p).endswith(".png")]}


def cosimulate_identified(state: dict[str, Any], progress: Progress) -> dict:
    """Step 6: the identified pantograph on the EN 50318 line; statistics against the targets."""
    from panto.catenary_cosim.master import cosimulate
    from panto.catenary_cosim.pantographs import pantograph_setup
    from panto.catenary_cosim.validation import ACCEPTANCE, LABELS

    out, settings = state["out"], state["settings"]
    parameters = _pantograph_parameters(state.get("identified"))
    pressure = pressure_for_static_force(parameters, TARGET_STATIC_FORCE)
    setup = pantograph_setup("physical", pressure_bar=pressure).with_fmu(
        state["fmus"] / "Pantograph.fmu").with_parameters(**parameters)
    options = {k: v for k, v in (("element_length", settings.cosim_element_length),
                                 ("time_step", settings.cosim_time_step)) if v}
    result = cosimulate("en50318-2002", setup, speed_kmh=settings.cosim_speed, **options)
    statistics = result.statistics().to_dict()
    stem = f"en50318-2002_{settings.cosim_speed:g}kmh"
    plots = result.save_plots(out / "cosim", stem=stem)
    result.to_csv(out / "cosim" / f"{stem}.csv", every=10)
    targets = ACCEPTANCE.get(int(settings.cosim_speed), {})
    reference = {}
    if settings.cosim_reference:  # the line model checked with the standard's own pantograph
        standard = pantograph_setup("en50318-2002").with_fmu(state["fmus"] / "TwoMass.fmu")
        reference = cosimulate("en50318-2002", standard, speed_kmh=settings.cosim_speed,
                               **options).statistics().to_dict()
    rows = [{"statistic": key, "label": LABELS[key], "value": _finite(value),
             "reference_pantograph": _finite(reference[key]) if key in reference else None,
             "target": list(targets[key]) if key in targets else None,
             "inside": bool(key in targets and math.isfinite(value)
                            and targets[key][0] - 1e-9 <= value <= targets[key][1] + 1e-9)}
            for key, value in statistics.items()]
    line = (f"{result.message}; mean {statistics['mean']:.1f} N, std {statistics['std']:.1f} N, "
            f"{sum(r['inside'] for r in rows)}/{len(rows)} statistics inside the EN 50318 "
            f"ranges (bellow {pressure:.2f} bar)")
    progress(("reference pantograph: mean {mean:.1f} N, std {std:.1f} N; ".format(**reference)
              if reference else "") + line)
    return {"speed_kmh": settings.cosim_speed, "line": "en50318-2002",
            "parameters_from": "identified" if state.get("identified") else "nominal "
            "(identification failed)", "pressure_bar": pressure,
            "static_force_N": TARGET_STATIC_FORCE, "statistics": rows,
            "inside": sum(r["inside"] for r in rows), "message": result.message,
            "reference_inside": sum(bool(r["target"]) and r["reference_pantograph"] is not None
                                    and r["target"][0] - 1e-9 <= r["reference_pantograph"]
                                    <= r["target"][1] + 1e-9 for r in rows) if reference
            else None,
            "wall_s": result.timing.get("total"),
            "plots": [str(p.relative_to(out)) for p in plots]}


def _pantograph_parameters(identified: dict | None) -> dict[str, float]:
    """The identified values the Pantograph FMU has as parameters (checked by its specs)."""
    from panto.fmu_src.models import default_parameters

    defaults = default_parameters("Pantograph")
    values = {k: float(v) for k, v in (identified or {}).items() if k in defaults.names}
    defaults.with_values(values)  # a clear error for an inadmissible value
    return values


def pressure_for_static_force(parameters: dict[str, float], force: float, *,
                              eta: float = 2.0) -> float:
    """Bellow pressure [bar] at which the pantograph presses with `force` [N] at height `eta`.

    Solves :math:`F_c(\\eta, p) = F` for p with the static equilibrium of the physical model
    (:func:`panto.identification.structures.linearisation.linearise` gives the equilibrium outputs
    :math:`y_0 = (y_{cb}, \\xi, F_c)`; compiled once per process, unlike a new
    :class:`panto.fmu_src.models.Model`); the force grows monotonically with the pressure.
    """
    from scipy.optimize import brentq

    from panto.identification.structures.linearisation import linearise
    from panto.identification.structures.physical import PhysicalLinear

    structure = PhysicalLinear()
    vector = structure.parameter_vector({k: v for k, v in parameters.items()
                                         if k in structure.parameter_names})

    def excess(p: float) -> float:
        return float(linearise(vector, (eta, p))[5][2]) - force

    low, high = 3.5, 9.5
    if excess(low) > 0 or excess(high) < 0:
        raise ValueError(f"no bellow pressure in [{low}, {high}] bar gives {force} N at eta = "
                         f"{eta} m with these parameters")
    return float(brentq(excess, low, high, xtol=1e-4))
