"""Adequacy before anything else: the nominal's fit beside a flexible linear black box.

A structure fitted to training data can fall short for two reasons that have nothing to do with an
unmodelled *nonlinear* effect: the fit stopped in a local minimum, or the structure cannot express
the linear dynamics the data show (a missing mode, a lag, a delay). Both show when a black-box
state-space model (:func:`~panto.identification.structures.blackbox.fit_state_space`: subspace
estimate refined by output error, no physics) of the structure's own order, and of two more
states, fits the same data clearly better.

Clearly better
    Fits per output ``f_j`` [%] give the normalised residual sums ``r_j = (1 - f_j / 100)^2``.
    With ``N`` samples per output, ``m`` outputs, ``p`` the nominal's free parameters and ``q``
    the black box's, the black box is clearly better when (a) the F statistic
    ``((R_nom - R_bb) / (q - p)) / (R_bb / (m N - q))``, ``R = sum_j r_j``, exceeds its
    ``1 - significance`` quantile (Seber & Wild, *Nonlinear Regression*, 1989, sec. 5.3: the
    black-box class of order ``n`` holds every linear model of ``n`` states, so a linear nominal
    is nested in it) and (b) some output gains more than ``floor`` fit points (the diagnosis'
    relevance floor, 0.2 points: with 10^4 samples (a) alone flags hundredths of a point).
    With nonlinear data the black box is the best *linear* approximation; a nominal that beats it
    is adequate in this sense.

Verdicts
    ``adequate``: the black box is not clearly better; the nominal's cost is at the level no linear
    model of that order improves on, which certifies a global optimum *in cost* (a parameter valley
    is the identifiability report's business).
    ``cannot express``: clearly better although the nominal was fitted globally from the data's
    own frequency response (``details["global_fit"]`` present): the structure lacks linear
    dynamics the data hold.
    ``not converged``: clearly better after a single start; refit globally to tell the two apart.
    In both latter cases a diagnosis must not name a nonlinear effect for that difference.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np
from scipy import stats

from panto.identification.estimation.base import (IdentificationData, IdentificationError,
                                                  IdentificationResult, ModelStructure)
from panto.identification.structures.blackbox import fit_state_space

Progress = Callable[[str], None]
#: Fit points some output must gain for the black box to be clearly better (the diagnosis'
#: ``support.IMPROVEMENT_FLOOR``).
RELEVANCE_FLOOR = 0.2
#: Significance level of the F test.
SIGNIFICANCE = 0.01
#: Black-box order when the structure has no ``linear_system`` to count its states.
DEFAULT_ORDER = 6


@dataclass(frozen=True)
class Adequacy:
    """The nominal's training fit beside the best black box's, and what it means.

    Attributes
    ----------
    verdict : str
        ``"adequate"``, ``"not converged"`` or ``"cannot express"`` (module notes).
    nominal_fit, black_box_fit : mapping of str to float
        Fit [%] per output on the same data (the black box: the best of the orders tried).
    order : int
        State dimension of that black box; ``orders`` all that were tried.
    f_statistic, p_value : float
        The F test of the module notes (NaN when the black box has no more parameters).
    message : str
        One sentence for reports.
    """

    verdict: str
    nominal_fit: Mapping[str, float]
    black_box_fit: Mapping[str, float]
    order: int
    orders: tuple[int, ...]
    f_statistic: float
    p_value: float
    floor: float
    significance: float
    message: str
    black_box: IdentificationResult | None = field(default=None, repr=False, compare=False)

    @property
    def clearly_better(self) -> bool:
        """Whether the black box fits clearly better than the nominal."""
        return self.verdict != "adequate"

    @property
    def gap(self) -> dict[str, float]:
        """Black-box fit minus nominal fit per output [fit points]."""
        return {o: self.black_box_fit[o] - self.nominal_fit[o] for o in self.nominal_fit}

    def to_dict(self) -> dict[str, Any]:
        """Plain values for JSON."""
        return {"verdict": self.verdict, "nominal_fit": dict(self.nominal_fit),
                "black_box_fit": dict(self.black_box_fit), "gap": self.gap,
                "order": self.order, "orders": list(self.orders),
                "f_statistic": _plain(self.f_statistic), "p_value": _plain(self.p_value),
                "floor": self.floor, "significance": self.significance,
                "message": self.message}


def state_order(structure: ModelStructure, parameters: Mapping[str, float],
                data: IdentificationData) -> int:
    """States of the structure's linear system at `parameters`, or :data:`DEFAULT_ORDER`."""
    linear_system = getattr(structure, "linear_system", None)
    if callable(linear_system):
        try:
            return max(1, int(np.asarray(linear_system(dict(parameters), data)[0]).shape[0]))
        except (NotImplementedError, ValueError, ArithmeticError, np.linalg.LinAlgError):
            pass
    return DEFAULT_ORDER


def check_adequacy(structure: ModelStructure, result: IdentificationResult,
                   data: IdentificationData, *, orders: Sequence[int] | None = None,
                   floor: float = RELEVANCE_FLOOR, significance: float = SIGNIFICANCE,
                   max_evaluations: int = 100, progress: Progress | None = None,
                   reference: Adequacy | None = None, executor: Any = None,
                   black_box: tuple[IdentificationResult, int, tuple[int, ...]] | None = None
                   ) -> Adequacy:
    """Fit black boxes to `data` and judge the nominal `result` against the best of them.

    Parameters
    ----------
    structure : ModelStructure
        The nominal (its ``linear_system`` gives the default order ``n``).
    result : IdentificationResult
        The nominal's fit on `data` (its ``fit`` per output; ``details["global_fit"]`` tells a
        global fit).
    data : IdentificationData
        The data the nominal was fitted on, with the same outputs.
    orders : sequence of int, optional
        Black-box orders tried (default ``n`` and ``n + 2``).
    floor, significance : float
        Module notes.
    max_evaluations : int
        Output-error refinement budget of each black box.
    progress : callable, optional
        Receives one line per black box.
    reference : Adequacy, optional
        An earlier check on the same data whose best black box is reused (after a refit of the
        nominal).
    executor : concurrent.futures.Executor, optional
        Fits the black boxes of the orders in parallel (the result is the serial one).
    black_box : tuple, optional
        :func:`best_black_box`'s result on the same data, reused (fitted before the nominal, as
        its global fit's reference).
    """
    missing = [o for o in data.output_names if o not in result.fit]
    if missing:
        raise IdentificationError(f"adequacy: the nominal's result has no fit for {missing}")
    if reference is not None and reference.black_box is not None:
        best, best_order, orders = reference.black_box, reference.order, reference.orders
    elif black_box is not None:
        best, best_order, orders = black_box
    else:
        best, best_order, orders = best_black_box(structure, result.parameters, data,
                                                  orders=orders,
                                                  max_evaluations=max_evaluations,
                                                  progress=progress, executor=executor)
    nominal = {o: float(result.fit[o]) for o in data.output_names}
    black_box = {o: float(best.fit[o]) for o in data.output_names}
    f_stat, p_value = _f_test(nominal, black_box, len(data), len(best.free), len(result.free))
    relevant = max(black_box[o] - nominal[o] for o in nominal) > floor
    significant = math.isfinite(p_value) and p_value < significance
    verdict = "adequate" if not (relevant and significant) else \
        "cannot express" if "global_fit" in result.details else "not converged"
    return Adequacy(verdict, nominal, black_box, best_order, orders, f_stat, p_value, floor,
                    significance, _message(verdict, nominal, black_box, best_order, p_value),
                    best)


def best_black_box(structure: ModelStructure, parameters: Mapping[str, float],
                   data: IdentificationData, *, orders: Sequence[int] | None = None,
                   max_evaluations: int = 100, progress: Progress | None = None,
                   executor: Any = None) -> tuple[IdentificationResult, int, tuple[int, ...]]:
    """The black boxes of :func:`check_adequacy` fitted to `data` (orders ``n`` and ``n + 2``,
    ``n`` the structure's states at `parameters`, unless `orders`): the best of them, its order
    and the orders tried. Also the linear model whose frequency response a global fit's
    data-driven starts match (``reference`` of
    :func:`~panto.identification.estimation.global_fit.fit_global`)."""
    n = state_order(structure, parameters, data)
    orders = tuple(int(k) for k in (orders or (n, n + 2)))
    varying = _varying_inputs(data)
    boxes = list(executor.map(_black_box, [varying] * len(orders), orders,
                              [max_evaluations] * len(orders))) \
        if executor is not None and len(orders) > 1 else \
        [_black_box(varying, order, max_evaluations) for order in orders]
    best, best_order = None, orders[0]
    for order, box in zip(orders, boxes):
        if progress:
            progress(f"adequacy: black box of order {order}: " + _fits(box.fit))
        if best is None or _residual(box.fit) < _residual(best.fit):
            best, best_order = box, order
    assert best is not None
    return best, best_order, orders


def reference_for(structure: ModelStructure, parameters: Mapping[str, float],
                  data: IdentificationData, options: Mapping[str, Any], adequacy: bool,
                  progress: Progress | None = None
                  ) -> tuple[IdentificationResult, int, tuple[int, ...]] | None:
    """:func:`best_black_box` fitted before a global fit whose adequacy is checked (`adequacy`
    and ``options["global_fit"]``): its data-driven starts then match the black box's response
    (``reference``), and :func:`with_adequacy` reuses it; None otherwise, or where no black box
    can be fitted (the adequacy then says why)."""
    if not adequacy or options.get("global_fit") is None:
        return None
    try:
        return best_black_box(structure, parameters, data, progress=progress)
    except (IdentificationError, ValueError, ArithmeticError, np.linalg.LinAlgError):
        return None


def with_adequacy(structure: ModelStructure, result: IdentificationResult,
                  data: IdentificationData, *, progress: Progress | None = None,
                  black_box: tuple[IdentificationResult, int, tuple[int, ...]] | None = None
                  ) -> IdentificationResult:
    """`result` with its :func:`check_adequacy` in ``details["adequacy"]`` and the message.

    After a global fit, an adequate nominal's fit is at the optimum in cost even when fewer than
    two starts agreed (the message says so)."""
    adequacy = check_adequacy(structure, result, data, progress=progress, black_box=black_box)
    text = f"adequacy: {adequacy.message}"
    report = result.details.get("global_fit")
    if report is not None and adequacy.verdict == "adequate" and not report["global_optimum"]:
        text += "; so the global optimum in cost is reached although the starts did not show it"
    return dataclasses.replace(result, message=f"{result.message}; {text}",
                               details={**result.details, "adequacy": adequacy.to_dict()})


def fit_checked(structure: ModelStructure, data: IdentificationData,
                parameters: Mapping[str, float], adequacy: bool, *,
                progress: Progress | None = None, **fit: Any) -> IdentificationResult:
    """:func:`~panto.identification.estimation.global_fit.fit_from_start` of `structure` on
    `data` with the options `fit`, and, when `adequacy`, the black box fitted first
    (:func:`reference_for` at `parameters`, the start's values: the global fit's data-driven
    starts match its response) and reused by :func:`with_adequacy`: the least-squares path of
    every structure's ``identify``."""
    from panto.identification.estimation.global_fit import fit_from_start

    box = reference_for(structure, parameters, data, fit, adequacy, progress)
    result = fit_from_start(structure, data, progress=progress,
                            reference=None if box is None else box[0], **fit)
    if adequacy:
        result = with_adequacy(structure, result, data, progress=progress, black_box=box)
    return result


def _black_box(data: IdentificationData, order: int, max_evaluations: int
               ) -> IdentificationResult:
    """The black box of `order` states fitted to `data` (an executor's task)."""
    return fit_state_space(data, order, max_evaluations=max_evaluations)


def _varying_inputs(data: IdentificationData) -> IdentificationData:
    """`data` without its constant inputs (a pressure held fixed): they carry no dynamics, and the
    black box removes levels itself."""
    keep = [j for j in range(data.inputs.shape[1]) if np.ptp(data.inputs[:, j]) > 0]
    if not keep:
        raise IdentificationError(f"{data.source or 'data'}: every input is constant; no black box "
                                  "can be fitted for the adequacy check")
    if len(keep) == data.inputs.shape[1]:
        return data
    return dataclasses.replace(data, inputs=data.inputs[:, keep],
                               input_names=tuple(data.input_names[j] for j in keep))


def _residual(fit: Mapping[str, float]) -> float:
    return sum((1.0 - f / 100.0) ** 2 if math.isfinite(f) else math.inf for f in fit.values())


def _f_test(nominal: Mapping[str, float], black_box: Mapping[str, float], samples: int,
            q: int, p: int) -> tuple[float, float]:
    """F statistic and p-value of the black box's extra parameters (module notes)."""
    r_nom, r_bb = _residual(nominal), _residual(black_box)
    dof = len(nominal) * samples - q
    extra = q - p
    if extra < 1 or dof < 1 or not (math.isfinite(r_nom) and math.isfinite(r_bb)) or r_bb <= 0:
        return math.nan, math.nan
    f_stat = ((r_nom - r_bb) / extra) / (r_bb / dof)
    return float(f_stat), float(stats.f.sf(f_stat, extra, dof))


def _message(verdict: str, nominal: Mapping[str, float], black_box: Mapping[str, float],
             order: int, p_value: float) -> str:
    pairs = ", ".join(f"{o} {nominal[o]:.2f} % vs {black_box[o]:.2f} %" for o in nominal)
    head = f"nominal vs black box of order {order}: {pairs}"
    if verdict == "adequate":
        return head + ": the black box is not clearly better; the nominal's linear dynamics " \
            "are at the level of the data (its fit is at the optimum in cost)"
    why = "the structure cannot express the linear dynamics of the data" \
        if verdict == "cannot express" else \
        "the nominal fit did not reach its optimum, or the structure cannot express the linear " \
        "dynamics (fit it globally to tell)"
    return head + f" (F test p = {p_value:.2g}): {why}; no nonlinear effect is named for " \
        "this difference"


def _fits(fit: Mapping[str, float]) -> str:
    return ", ".join(f"{k} {v:.2f} %" for k, v in fit.items())


def _plain(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


__all__ = ["Adequacy", "check_adequacy", "fit_checked", "with_adequacy", "state_order",
           "RELEVANCE_FLOOR", "SIGNIFICANCE"]
