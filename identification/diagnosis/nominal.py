"""The diagnosis' nominal: its output-error fit on the training run and its adequacy (steps 0-1
of :func:`~panto.identification.diagnosis.pipeline.diagnose`).

:func:`fit_nominal` fits it as the diagnosis does (one least-squares run, or globally);
:func:`adequate_nominal` checks it against a black box of its order and refits it globally when a
single start did not converge (:attr:`~panto.identification.diagnosis.pipeline.DiagnosisOptions.
adequacy`); :func:`black_box_validation` is that black box's fit on the validation run, the level a
nonlinear effect must beat.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from panto.identification.estimation.base import (IdentificationData, IdentificationError,
                                                  ModelStructure, fit_percent)
from panto.identification.estimation.global_fit import GlobalFitOptions, fit_from_start
from panto.identification.structures.adequacy import check_adequacy

Progress = Callable[[str], None]


def simulate(model: Any, data: IdentificationData) -> np.ndarray:
    """`model`'s free run on `data` (anything with ``structure`` and ``parameters``), its
    columns in the data's output order."""
    y = np.asarray(model.structure.simulate(model.parameters, data), float)
    return y[:, [model.structure.output_names.index(o) for o in data.output_names]]


def fit_per_output(data: IdentificationData, simulated: np.ndarray) -> dict[str, float]:
    """The free-run fit [%] of `simulated` per output of `data`."""
    return {o: float(fit_percent(data.outputs[:, j], simulated[:, j]))
            for j, o in enumerate(data.output_names)}


def indented(progress: Progress | None) -> Progress | None:
    """`progress` with its lines indented by four spaces (a sub-step's lines)."""
    return None if progress is None else (lambda line: progress("    " + line))


def fit_nominal(nominal: ModelStructure, free: Sequence[str], train: IdentificationData, *,
                global_fit: GlobalFitOptions | None = None, **options: Any):
    """The nominal's output-error fit on the training run, as :func:`diagnose` makes it.

    Without `global_fit`, one
    :func:`~panto.identification.estimation.least_squares.fit_least_squares` run from the
    defaults (`options` go to it). With `global_fit`,
    :func:`~panto.identification.estimation.global_fit.fit_global` with those options (from the
    defaults, from the data's frequency response where the structure has ``linear_system`` (or
    a ``reference`` model's: the adequacy's black box), and perturbations; its verdict ends the
    result's ``message``); ``executor`` and ``max_evaluations`` in `options` override the ones
    of `global_fit`, ``progress``, ``initial``, ``bounds``, ``default``, ``reference`` and
    ``seeds`` are passed on, the rest go to every least-squares run.
    Not yet the default of :func:`diagnose`: on ``tests/test_diagnosis_effects.py``'s
    ``actuator_lag`` case the better nominal absorbs most of the hidden pressure lag and the
    verdict turns ``unexplained`` (the diagnosis' acceptance must first learn to judge a nominal
    at its global optimum).
    """
    return fit_from_start(nominal, train.select_outputs(fitted_outputs(nominal, train)), free=free,
                          global_fit=global_fit, **options)


def fitted_outputs(structure: ModelStructure, data: IdentificationData) -> tuple[str, ...]:
    """The data's outputs, checked to be outputs the structure simulates."""
    missing = [o for o in data.output_names if o not in structure.output_names]
    if missing:
        raise IdentificationError(f"{structure.name} does not simulate {missing} "
                                  f"(it has {list(structure.output_names)})")
    return data.output_names


#: The nominal's global refit gives each start this many times a fit's evaluation budget: every
#: later verdict stands on that refit, and on ill-conditioned nominals (a three-mass oscillator
#: seen through F_c alone) its starts converge only after 300-1700 evaluations; stopped at 400 they
#: left a clean case 5 points short of the truth's fit, and a mode was named for the difference.
GLOBAL_BUDGET = 4


def adequate_nominal(nominal: ModelStructure, free: Sequence[str], train: IdentificationData,
                     result: Any, global_fit: GlobalFitOptions | None,
                     fit_options: Mapping[str, Any], progress: Progress | None,
                     pool: Any = None) -> tuple[Any, Any]:
    """The nominal's fit and its adequacy; refitted globally when a black box shows that a single
    start did not converge (:attr:`DiagnosisOptions.adequacy`). The global refit's default start
    is `result` (a single start from the defaults with `fit_options`), not fitted again; `pool`
    (an executor or None) fits the black boxes and the global refit's independent starts in
    parallel."""
    data = train.select_outputs(fitted_outputs(nominal, train))
    adequacy = check_adequacy(nominal, result, data, progress=indented(progress), executor=pool)
    if adequacy.verdict != "not converged":
        return result, adequacy
    if progress:
        progress("diagnose: adequacy: " + adequacy.message + "; refitting the nominal globally")
    settings = dataclasses.replace(global_fit or GlobalFitOptions(), starts_executor=pool)
    budget = {**fit_options, "max_evaluations": GLOBAL_BUDGET * fit_options["max_evaluations"]}
    result = fit_nominal(nominal, free, train, progress=indented(progress), global_fit=settings,
                         default=None if "global_fit" in result.details else result,
                         reference=adequacy.black_box, **budget)
    return result, check_adequacy(nominal, result, data, reference=adequacy)


def mapping_candidates(result: Any) -> tuple[dict[str, float], ...]:
    """The free parameters of the candidates the nominal's global fit matched to the data's
    linear response (``details["global_fit"]["data_driven"]``), best first; none without one.
    An effect's global refit polishes them too (the effect at its start): the effect's basin
    can lie next to the nominal's best linear match where no screening point of the larger
    structure falls (seen held-out three-mass/sensor_inertia/411: from the nominal's best
    candidate the sensor mass's mapping reached the plant's basin, weighted error rms 0.06,
    where its own best was 0.64 at -47 kg)."""
    report = getattr(result, "details", {}).get("global_fit") or {}
    return tuple(dict(c["parameters"]) for c in report.get("data_driven", {}).get("candidates", ()))


def adequacy_quietly(nominal: ModelStructure, result: Any, train: IdentificationData) -> Any:
    """:func:`check_adequacy` of the nominal's fit, or None where no black box can be fitted."""
    try:
        return check_adequacy(nominal, result, train.select_outputs(fitted_outputs(nominal, train)))
    except (IdentificationError, ValueError, ArithmeticError, np.linalg.LinAlgError):
        return None


def black_box_validation(adequacy: Any, validation: IdentificationData
                          ) -> dict[str, float] | None:
    """The adequacy black box's free-run fit [%] on the validation run, per output it was fitted
    to; None without a black box (or where it cannot run on the validation run)."""
    box = getattr(adequacy, "black_box", None)
    if box is None or box.simulator is None:
        return None
    try:
        data = validation.select_outputs(tuple(adequacy.black_box_fit))
        return fit_per_output(data, np.asarray(box.simulator(data), float))
    except (IdentificationError, ValueError, ArithmeticError, np.linalg.LinAlgError):
        return None


__all__ = ["fit_nominal", "fitted_outputs", "adequate_nominal", "adequacy_quietly",
           "mapping_candidates",
           "black_box_validation", "indented", "Progress", "simulate", "fit_per_output"]
