"""A designed experiment that pays off: the closed loop of thesis section 5.5 on one plant.

:func:`closed_loop_experiment` runs the loop the thesis sketches and checks its promise:

1. **Run 1**: the APRBS training profile as the rig plays it
   (:func:`panto.identification.design.constraints.conventional_inputs`), ``duration`` seconds.
2. **Identify** the free parameters from run 1
   (:func:`panto.identification.estimation.least_squares.fit_least_squares`): estimates, their
   standard deviations and identifiability verdicts (:mod:`panto.identification.estimation.uncertainty`).
3. **Design run 2** at the run-1 estimate with what ``panto doe`` runs
   (:func:`panto.identification.design.pantograph.design_pantograph_experiment`), the noise
   variance per output taken from run 1's residuals. The design is computed, and the joint fit
   started, at the whole run-1 estimate, not-identifiable parameters included: the data fix
   their combinations (the masses' weight through the rest force), and putting some of them
   back at the prior breaks those (tried: the design model's rest contact force fell from 81 N
   to 13 N, below the design's 20 N contact limit).
4. **Predict**: the design holds the Fisher information :math:`M_2` of the designed input and
   :math:`M_1` of the APRBS run of equal length, both at the run-1 estimate (eq. 5.6). Two
   independent runs add their information, so the Cramer-Rao bound after runs 1 + 2 is
   :math:`(M_1 + M_2)^{-1}` (eq. 5.1). The product's fit reaches it with one output; with
   several it weights each by its spread, not its noise, and is not efficient, so the
   prediction for *that* estimator (:func:`predicted_least_squares_std`, the same
   sensitivities) is the one compared with what the fit reports; both are in the result.
5. **Run 2** (the design) on the same plant, and **re-identify from both runs** jointly: one
   least-squares problem whose residual is that of both records, each simulated from its own
   rest start (:class:`~panto.identification.design.closed_loop_runs.JointExperiments`).
6. **Compare** per parameter (:class:`ParameterOutcome`): std after run 1 (predicted,
   achieved), after runs 1 + 2 (predicted, achieved, Cramer-Rao bound), verdicts before and
   after, the truth. The predictions assume white noise of the run-1 residual variance; the
   fit's covariance allows coloured residuals (model error), so on a plant the structure does
   not represent exactly the achieved std exceed the predicted ones by about the same factor
   after run 1 and after runs 1 + 2, and the *shrink factor* (std after run 1 over std after
   runs 1 + 2) is the prediction that carries over.

``next_run="repeat"`` replaces the design by a second APRBS run (other noise): the control that
shows what the design adds (its predicted and achieved shrinkage is about :math:`\\sqrt 2`).

The plant is anything that turns an input into identification data (:data:`Runner`):
:class:`~panto.identification.design.closed_loop_runs.VirtualTestBedRunner` plays it on the
virtual test bed (:mod:`panto.rig.virtual`); the joint fit's records are joined by
:mod:`panto.identification.design.closed_loop_runs`.
"""
from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from panto.identification.design.closed_loop_runs import (JointExperiments, VirtualTestBedRunner,
                                                          join_records)
from panto.identification.design.constraints import RigInputConstraints, conventional_inputs
from panto.identification.design.fisher import cramer_rao_covariance
from panto.identification.design.pantograph import (DesignOptions, PantographDesign,
                                                    design_pantograph_experiment, model_inputs)
from panto.identification.design.pantograph_sensitivity import LinearisedPantograph
from panto.identification.estimation.base import (IdentificationData, IdentificationResult,
                                                  ModelStructure)
from panto.identification.estimation.least_squares import fit_least_squares, structure_units

#: ``runner(name, motor, demand, constraints)``: play motor positions [m] about mid-stroke and
#: pressure demands [bar] at ``constraints.sample_period`` on the plant and return its
#: identification data (inputs eta, p; the fitted outputs).
Runner = Callable[[str, np.ndarray, np.ndarray, RigInputConstraints], IdentificationData]
Progress = Callable[[str], None]
NEXT_RUNS = ("designed", "repeat")


# --- the loop -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ClosedLoopOptions:
    """What :func:`closed_loop_experiment` designs and fits.

    Parameters
    ----------
    structure : {"physical-linear", "two-mass", "three-mass"}
    free : tuple of str, optional
        Parameters identified and designed for (default: the structure's ``default_free()``;
        for ``two-mass`` without ``y_0``, without ``y_cb_offset`` unless ``y_cb`` is fitted).
    duration : float
        Length of each run [s].
    criterion : {"D", "A", "E"}
    design : DesignOptions
        The design's genetic algorithm.
    next_run : {"designed", "repeat"}
        Run 2: the design, or the APRBS again (the control).
    max_evaluations : int
        Model evaluations per least-squares fit.
    identifiability_threshold : float
        Relative standard deviation above which a parameter is not identifiable.
    outputs : tuple of str
        The outputs fitted and designed for (of what the runner returns). With one output the
        product's fit is efficient (its std reaches the Cramer-Rao bound); with several it
        weights them by their spread, not their noise (:func:`predicted_least_squares_std`).
    """

    structure: str = "physical-linear"
    free: tuple[str, ...] | None = None
    duration: float = 30.0
    criterion: str = "D"
    design: DesignOptions = DesignOptions(population=40, generations=150)
    next_run: str = "designed"
    max_evaluations: int = 4000
    identifiability_threshold: float = 0.5
    outputs: tuple[str, ...] = ("F_c", "y_cb")

    def __post_init__(self) -> None:
        if self.next_run not in NEXT_RUNS:
            raise ValueError(f"ClosedLoopOptions.next_run = {self.next_run!r}: choose from "
                             f"{NEXT_RUNS}")
        if not self.duration > 0:
            raise ValueError(f"ClosedLoopOptions.duration = {self.duration!r}: must be > 0 s")


@dataclass(frozen=True)
class ParameterOutcome:
    """One parameter through the loop (standard deviations in `unit`; NaN where not defined,
    e.g. at a bound).

    Parameters
    ----------
    name, unit : str
    truth : float
        The plant's value (NaN if unknown).
    prior : float
        Where the fits started.
    estimate_first, std_first, verdict_first : float, float, str
        From run 1 alone (achieved).
    predicted_std_first, predicted_std_joint : float
        Predicted std of the product's least-squares fit after run 1 and after runs 1 + 2
        (:func:`predicted_least_squares_std`: the design's sensitivities at the run-1 estimate,
        the fit's weighting of the outputs).
    bound_std_first, bound_std_joint : float
        Cramer-Rao bounds :math:`\\sqrt{(M_1^{-1})_{ii}}` and :math:`\\sqrt{((M_1 + M_2)^{-1})_{ii}}`
        from the design's Fisher information: what a fit weighting each output by its noise
        would reach.
    estimate_joint, std_joint, verdict_joint : float, float, str
        From runs 1 + 2 jointly (achieved).
    """

    name: str
    unit: str
    truth: float
    prior: float
    estimate_first: float
    std_first: float
    verdict_first: str
    predicted_std_first: float
    predicted_std_joint: float
    bound_std_first: float
    bound_std_joint: float
    estimate_joint: float
    std_joint: float
    verdict_joint: str

    @property
    def predicted_shrink(self) -> float:
        """Predicted std after run 1 over predicted std after runs 1 + 2."""
        return self.predicted_std_first / self.predicted_std_joint

    @property
    def achieved_shrink(self) -> float:
        """Achieved std after run 1 over achieved std after runs 1 + 2."""
        return self.std_first / self.std_joint

    @property
    def achieved_to_predicted(self) -> float:
        """Achieved over predicted std after runs 1 + 2 (1: the prediction held)."""
        return self.std_joint / self.predicted_std_joint

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (NaN as None)."""
        values = {k: getattr(self, k) for k in self.__dataclass_fields__} | {
            "predicted_shrink": self.predicted_shrink, "achieved_shrink": self.achieved_shrink,
            "achieved_to_predicted": self.achieved_to_predicted}
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                for k, v in values.items()}


@dataclass(frozen=True)
class ClosedLoopResult:
    """The loop's outcome: per parameter (:class:`ParameterOutcome`), the fits and the design.

    ``first`` and ``joint`` are the least-squares results (run 1; runs 1 + 2), ``design`` the
    design computed at the run-1 estimate (for ``next_run="repeat"`` it still holds :math:`M_1`
    as ``conventional_fisher``), ``noise_std`` the run-1 residual std per output the design used.
    """

    structure: str
    free: tuple[str, ...]
    duration: float
    next_run: str
    parameters: tuple[ParameterOutcome, ...]
    noise_std: dict[str, float]
    first: IdentificationResult
    joint: IdentificationResult
    design: PantographDesign

    def outcome(self, name: str) -> ParameterOutcome:
        """The outcome of parameter `name`."""
        return next(p for p in self.parameters if p.name == name)

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary (options, fits, per-parameter table, design summary)."""
        return {"structure": self.structure, "free": list(self.free), "duration_s": self.duration,
                "next_run": self.next_run, "noise_std": self.noise_std,
                "fit_percent": {"run 1": dict(self.first.fit), "runs 1+2": dict(self.joint.fit)},
                "messages": {"run 1": self.first.message, "runs 1+2": self.joint.message},
                "parameters": [p.to_dict() for p in self.parameters],
                "design": self.design.summary()}

    def markdown(self) -> str:
        """The per-parameter table (units of the parameter): truth, run-1 estimate, std after run
        1 (predicted, achieved), std after runs 1 + 2 (predicted, achieved, Cramer-Rao bound),
        the joint estimate, verdicts before and after."""
        lines = [f"{self.structure}, {self.duration:g} s per run, run 2: {self.next_run}", "",
                 "| parameter | unit | truth | estimate run 1 | std run 1 predicted | "
                 "std run 1 achieved | std 1+2 predicted | std 1+2 achieved | achieved / "
                 "predicted | CR bound 1+2 | estimate 1+2 | verdict run 1 | verdict 1+2 |",
                 "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for p in self.parameters:
            lines.append(f"| {p.name} | {p.unit} | {p.truth:.5g} | {p.estimate_first:.5g} | "
                         f"{p.predicted_std_first:.3g} | {p.std_first:.3g} | "
                         f"{p.predicted_std_joint:.3g} | {p.std_joint:.3g} | "
                         f"{p.achieved_to_predicted:.2f} | {p.bound_std_joint:.3g} | "
                         f"{p.estimate_joint:.5g} | {p.verdict_first} | {p.verdict_joint} |")
        fit = ", ".join(f"{k} {v:.2f} %" for k, v in self.first.fit.items())
        joint = ", ".join(f"{k} {v:.2f} %" for k, v in self.joint.fit.items())
        lines += ["", f"Fit run 1: {fit}; runs 1+2: {joint}. Noise std (run-1 residual): "
                  + ", ".join(f"{k} {v:.3g}" for k, v in self.noise_std.items()) + "."]
        return "\n".join(lines) + "\n"


def write_closed_loop_report(result: ClosedLoopResult, folder: str | Path) -> dict[str, Path]:
    """``closed_loop.json`` (:meth:`ClosedLoopResult.summary`), ``closed_loop.md``
    (:meth:`ClosedLoopResult.markdown`) and ``closed_loop.png``
    (:func:`panto.identification.design.closed_loop_plots.plot_closed_loop`) into `folder`."""
    from panto.identification.design.closed_loop_plots import plot_closed_loop

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = {"summary": folder / "closed_loop.json", "table": folder / "closed_loop.md"}
    paths["summary"].write_text(json.dumps(result.summary(), indent=2, default=_plain) + "\n",
                                encoding="utf-8")
    paths["table"].write_text(result.markdown(), encoding="utf-8")
    paths["plot"] = plot_closed_loop(result, folder / "closed_loop.png")
    return paths


def _plain(value: Any) -> Any:
    """JSON for NumPy values (NaN and inf as None)."""
    if isinstance(value, np.ndarray):
        return [_plain(v) for v in value.tolist()]
    value = float(value)
    return value if math.isfinite(value) else None


def closed_loop_experiment(run: Runner, *, options: ClosedLoopOptions = ClosedLoopOptions(),
                           constraints: RigInputConstraints | None = None,
                           initial: Mapping[str, float] | None = None,
                           truth: Mapping[str, float] | None = None,
                           progress: Progress | None = None) -> ClosedLoopResult:
    """Identify from an APRBS run, design run 2 there, run it, re-identify from both (module notes).

    Parameters
    ----------
    run : Runner
        The plant (e.g. :class:`VirtualTestBedRunner`).
    options : ClosedLoopOptions
    constraints : RigInputConstraints, optional
        The rig's limits (default :meth:`RigInputConstraints.from_rig`).
    initial : mapping, optional
        Prior values where the run-1 fit starts (default: the structure's nominal values).
    truth : mapping, optional
        The plant's values, for the report only.
    progress : callable, optional

    Returns
    -------
    ClosedLoopResult
    """
    say = progress or (lambda line: None)
    constraints = constraints or RigInputConstraints.from_rig()
    structure = LinearisedPantograph.structure_for(options.structure)
    free = _free(options, structure)
    prior = structure.nominal() | {k: float(v) for k, v in (initial or {}).items()}
    n = int(round(options.duration / constraints.sample_period))
    say(f"closed loop: run 1 (APRBS, {options.duration:g} s)")
    first_data = run("run1_aprbs", *conventional_inputs(n, constraints),
                     constraints).select_outputs(options.outputs)
    say(f"closed loop: identifying {list(free)} from run 1")
    first = _fit(structure, first_data, free, prior, options)
    point = _design_point(first, prior)
    noise_std = {o: float(first.details["residual_std"][o]) for o in first_data.output_names}
    say(f"closed loop: designing run 2 at the run-1 estimate (noise std {noise_std})")
    model, design = _design(options, constraints, point, free, noise_std, len(first_data), say)
    first_inputs = (design.conventional_motor_position, design.conventional_pressure_demand)
    second_inputs = ((design.motor_position, design.pressure_demand)
                     if options.next_run == "designed" else first_inputs)
    say(f"closed loop: run 2 ({options.next_run})")
    second_data = run(f"run2_{options.next_run}", *second_inputs,
                      constraints).select_outputs(options.outputs)
    joined, lengths = join_records([first_data, second_data])
    say("closed loop: identifying from runs 1 + 2")
    joint = _fit(JointExperiments(structure, lengths), joined, free, point, options)
    second_fisher = design.fisher if options.next_run == "designed" else design.conventional_fisher
    variance = [noise_std[o] ** 2 for o in model.output_names]
    predicted = [predicted_least_squares_std(model, runs, constraints, variance)
                 for runs in ([first_inputs], [first_inputs, second_inputs])]
    bound = [_bound_std(design.conventional_fisher),
             _bound_std(design.conventional_fisher + second_fisher)]
    units = structure_units(structure)
    truth = dict(truth or {})
    outcomes = tuple(ParameterOutcome(
        name, units.get(name, "-"), float(truth.get(name, math.nan)), float(prior[name]),
        *_estimate(first, name), float(predicted[0][i]), float(predicted[1][i]),
        float(bound[0][i]), float(bound[1][i]), *_estimate(joint, name))
        for i, name in enumerate(free))
    return ClosedLoopResult(options.structure, free, float(options.duration), options.next_run,
                            outcomes, noise_std, first, joint, design)


def _free(options: ClosedLoopOptions, structure: Any) -> tuple[str, ...]:
    if options.free is not None:
        return tuple(options.free)
    unused = {"y_0"} if options.structure == "two-mass" else set()
    if "y_cb" not in options.outputs:
        unused.add("y_cb_offset")  # moves only y_cb
    return tuple(n for n in structure.default_free() if n not in unused)


def _fit(structure: ModelStructure, data: IdentificationData, free: Sequence[str],
         start: Mapping[str, float], options: ClosedLoopOptions) -> IdentificationResult:
    return fit_least_squares(structure, data, free=free, initial=dict(start),
                             max_evaluations=options.max_evaluations,
                             identifiability_threshold=options.identifiability_threshold)


def _design_point(first: IdentificationResult, prior: Mapping[str, float]) -> dict[str, float]:
    """The run-1 estimate (every structure parameter; the prior where the fit has none).

    Not-identifiable parameters keep their estimates too: the data pin down their combinations
    (e.g. the masses' total weight through the static force), and putting some of them back at
    the prior would break what the data did determine (the rest force of the design model).
    """
    return {k: float(v) for k, v in prior.items()} | {
        k: float(v) for k, v in first.parameters.items() if k in prior}


def _design(options: ClosedLoopOptions, constraints: RigInputConstraints,
            point: Mapping[str, float], free: Sequence[str], noise_std: Mapping[str, float],
            length: int, say: Progress) -> tuple[LinearisedPantograph, PantographDesign]:
    """The design model at `point` and `design_pantograph_experiment` on it for `length` samples
    (run 2 = run 1's length), compared with the APRBS of that length (run 1)."""
    probe = LinearisedPantograph.structure_for(options.structure)
    parameters = {k: v for k, v in point.items() if k in probe.parameter_names}
    outputs = tuple(noise_std)
    model = LinearisedPantograph(options.structure, parameters, free, outputs=outputs,
                                 operating_point=constraints.operating_point(),
                                 sample_period=constraints.sample_period, length=length,
                                 pressure_lag=constraints.pressure_lag)
    variance = [noise_std[o] ** 2 for o in outputs]
    conventional = tuple(x[:length] for x in conventional_inputs(length, constraints))
    return model, design_pantograph_experiment(model, constraints, criterion=options.criterion,
                                               noise_variance=variance, options=options.design,
                                               conventional=conventional, progress=say)


def predicted_least_squares_std(model: LinearisedPantograph,
                                runs: Sequence[tuple[np.ndarray, np.ndarray]],
                                constraints: RigInputConstraints,
                                noise_variance: Sequence[float]) -> np.ndarray:
    """Predicted std of the free parameters as :func:`fit_least_squares` estimates them from
    `runs` (motor positions [m], pressure demands [bar]) with white noise of `noise_variance`.

    The fit minimises :math:`\\sum_j \\lVert e_j \\rVert^2 / s_j^2`, each output ``j`` normalised
    by its spread :math:`s_j` over all records (not by its noise). Linearised about the design
    point, with :math:`\\Psi_j` the sensitivity of output ``j`` (the design model's, all runs
    stacked), its covariance is the sandwich :math:`A^{-1} B A^{-1}`,
    :math:`A = \\sum_j \\Psi_j^T \\Psi_j / s_j^2`,
    :math:`B = \\sum_j \\sigma_j^2 \\Psi_j^T \\Psi_j / s_j^4`, the spreads predicted as
    :math:`s_j^2 = \\sum_k (\\hat y_{kj} - \\bar y_j)^2 + N \\sigma_j^2`. With one output (or
    :math:`\\sigma_j \\propto s_j`) it is the Cramer-Rao bound :math:`(\\sum_j \\Psi_j^T
    \\Psi_j / \\sigma_j^2)^{-1}`; otherwise larger. Units: those of the parameters.
    """
    outputs, sensitivities = zip(*(model.sensitivities(None, model_inputs(m, d, constraints))
                                   for m, d in runs))
    y, psi = np.concatenate(outputs), np.concatenate(sensitivities)   # (N, o), (N, o, p)
    variance = np.asarray(noise_variance, float)
    spread = np.sum((y - y.mean(axis=0)) ** 2, axis=0) + len(y) * variance
    a = np.einsum("koi,koj,o->ij", psi, psi, 1.0 / spread)
    b = np.einsum("koi,koj,o->ij", psi, psi, variance / spread ** 2)
    try:
        inverse = np.linalg.inv(a)
    except np.linalg.LinAlgError:
        return np.full(len(a), math.inf)
    return np.sqrt(np.abs(np.diag(inverse @ b @ inverse)))


def _bound_std(fisher: np.ndarray) -> np.ndarray:
    try:
        return np.sqrt(np.abs(np.diag(cramer_rao_covariance(fisher))))
    except np.linalg.LinAlgError:
        return np.full(len(fisher), math.inf)


def _estimate(result: IdentificationResult, name: str) -> tuple[float, float, str]:
    estimate = result.estimates.get(name)
    if estimate is None:
        return math.nan, math.nan, "not fitted"
    return float(estimate.value), float(estimate.std), estimate.verdict


__all__ = ["closed_loop_experiment", "write_closed_loop_report", "predicted_least_squares_std", "ClosedLoopOptions", "ClosedLoopResult", "ParameterOutcome",
           "VirtualTestBedRunner", "JointExperiments", "join_records", "Runner"]
