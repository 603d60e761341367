"""Multi-objective genetic identification: NSGA-II over the fits of two outputs (thesis 4.1.2-4.1.3).

The thesis fitted its grey-box models with MATLAB's multi-objective genetic algorithm on two
objectives, the fit on the cross-bar position and the fit on the contact force, and let the user
pick one solution of the resulting Pareto front (Fig. 4.7). Here the same is done with pymoo's
NSGA-II (Deb et al. 2002) through its ask-and-tell interface, so that each generation's population
is evaluated in parallel on any ``concurrent.futures`` executor (a process pool, or a Dask
distributed ``Client`` through ``client.get_executor()``).

Objectives (minimised), one per output ``j``:

.. math:: J_j(\\theta) = 100 - \\mathrm{fit}_j(\\theta)
          = 100 \\, \\frac{\\lVert y_j - \\hat y_j(\\theta) \\rVert}{\\lVert y_j - \\bar y_j \\rVert}

with :math:`\\hat y_j` the free-run simulation of the structure. Candidates for which the model is
invalid (no equilibrium, unstable, non-finite output) get the penalty :data:`PENALTY` and violate
the constraint, so NSGA-II's constrained domination ranks them behind every valid one.

Genes are the free parameters mapped to [0, 1]; a positive range spanning more than a decade is
mapped logarithmically (stiffnesses from 1e3 to 1e7 N/m get the same resolution per decade).

Examples
--------
>>> result = fit_pareto(structure, data, free=["k_c", "k_ph"], population=40,
...                     generations=30)                                  # doctest: +SKIP
>>> chosen = result.pick(rule="knee")                                    # doctest: +SKIP
>>> better = result.polish(chosen, data)                                 # doctest: +SKIP
>>> from panto.identification.estimation.plots import plot_pareto       # doctest: +SKIP
>>> plot_pareto(result, "pareto.png", picked=chosen, polished=better)    # doctest: +SKIP
"""
from __future__ import annotations

import dataclasses
import math
import os
import time
from concurrent.futures import Executor
from dataclasses import dataclass
from functools import partial
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from panto.identification.estimation.base import (IdentificationData, IdentificationError, IdentificationResult,
                                 ModelStructure, fit_percent)

#: Objective value (100 - fit %) given to a candidate whose model is invalid (fit of -900 %).
PENALTY = 1000.0

Progress = Callable[[str], None]


# ----------------------------------------------------------------------------------- genes
@dataclass(frozen=True)
class GeneMap:
    """Map between free parameter values and genes in [0, 1].

    A parameter with ``0 < lower`` and ``upper / lower > 10`` is mapped logarithmically,
    ``theta = lower (upper / lower)^g``; any other linearly, ``theta = lower + g (upper - lower)``.
    """

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    logarithmic: np.ndarray

    @classmethod
    def from_bounds(cls, names: Sequence[str], bounds: Mapping[str, tuple[float, float]]
                    ) -> "GeneMap":
        """Check the bounds of every free parameter (finite, lower < upper) and build the map."""
        lower, upper = [], []
        for name in names:
            if name not in bounds:
                raise IdentificationError(f"free parameter {name!r} has no bounds")
            low, high = (float(v) for v in bounds[name])
            if not (math.isfinite(low) and math.isfinite(high) and low < high):
                raise IdentificationError(
                    f"bounds of {name!r} must be finite with lower < upper, got ({low}, {high})")
            lower.append(low)
            upper.append(high)
        lower_a, upper_a = np.array(lower), np.array(upper)
        logarithmic = (lower_a > 0) & (upper_a > 10 * lower_a)
        return cls(tuple(names), lower_a, upper_a, logarithmic)

    def decode(self, genes: np.ndarray) -> np.ndarray:
        """Parameter values for genes, shape ``(..., n_free)``."""
        g = np.clip(np.asarray(genes, float), 0.0, 1.0)
        linear = self.lower + g * (self.upper - self.lower)
        with np.errstate(divide="ignore", invalid="ignore"):
            logarithmic = self.lower * (self.upper / self.lower) ** g
        return np.where(self.logarithmic, logarithmic, linear)

    def encode(self, values: np.ndarray) -> np.ndarray:
        """Genes for parameter values (clipped into the bounds)."""
        v = np.clip(np.asarray(values, float), self.lower, self.upper)
        linear = (v - self.lower) / (self.upper - self.lower)
        with np.errstate(divide="ignore", invalid="ignore"):
            logarithmic = np.log(v / self.lower) / np.log(self.upper / self.lower)
        return np.where(self.logarithmic, logarithmic, linear)


# ------------------------------------------------------------------------------ objective
@dataclass(frozen=True, eq=False)
class ParetoObjective:
    """Evaluates candidates: ``100 - fit %`` per objective output (picklable, sent to workers).

    Parameters
    ----------
    structure : ModelStructure
    data : IdentificationData
    base : mapping of str to float
        Values of all parameters that are not free (nominal or fixed).
    free : tuple of str
    outputs : tuple of str
        Objective outputs (names in ``structure.output_names`` and in the data).
    """

    structure: ModelStructure
    data: IdentificationData
    base: Mapping[str, float]
    free: tuple[str, ...]
    outputs: tuple[str, ...]

    def parameters(self, values: Sequence[float]) -> dict[str, float]:
        """All parameters: the base with the free ones set to `values`."""
        merged = dict(self.base)
        merged.update(zip(self.free, (float(v) for v in values)))
        return merged

    def fits(self, parameters: Mapping[str, float]) -> np.ndarray:
        """Fit [%] per objective output of the free-run simulation (may raise if invalid)."""
        simulated = np.asarray(self.structure.simulate(parameters, self.data), float)
        columns = [list(self.structure.output_names).index(name) for name in self.outputs]
        measured = np.column_stack([self.data.output(name) for name in self.outputs])
        return np.atleast_1d(fit_percent(measured, simulated[:, columns]))

    def __call__(self, rows: np.ndarray) -> list[tuple[list[float], str]]:
        """Objectives ``100 - fit`` for each row of free values, with a message if infeasible."""
        results = []
        for row in np.atleast_2d(rows):
            try:
                fits = self.fits(self.parameters(row))
                if not np.all(np.isfinite(fits)):
                    raise ArithmeticError("simulated output is not finite")
                results.append((np.minimum(100.0 - fits, PENALTY).tolist(), ""))
            except (ValueError, ArithmeticError, np.linalg.LinAlgError) as error:
                results.append(([PENALTY] * len(self.outputs), f"{type(error).__name__}: {error}"))
        return results


def resolve_executor(executor: Any) -> Executor | None:
    """A ``concurrent.futures`` executor from an executor, a Dask ``Client``, or None (serial)."""
    if executor is None or isinstance(executor, Executor):
        return executor
    if hasattr(executor, "get_executor"):  # dask.distributed.Client
        return executor.get_executor()
    if hasattr(executor, "submit"):
        return executor
    raise IdentificationError(f"executor must be a concurrent.futures.Executor or a Dask Client, "
                              f"not {type(executor).__name__}")


def evaluate_population(objective: ParetoObjective, rows: np.ndarray, executor: Any = None,
                        chunks: int | None = None) -> tuple[np.ndarray, list[str]]:
    """Objectives of all rows, shape ``(n, n_obj)``, and a message per row ("" when valid).

    The rows are split into `chunks` batches (default twice the local CPU count) submitted to
    the executor; without an executor they are evaluated here, one after the other.
    """
    pool = resolve_executor(executor)
    rows = np.atleast_2d(rows)
    if pool is None:
        pairs = objective(rows)
    else:
        n_chunks = max(1, min(len(rows), chunks or 2 * (os.cpu_count() or 1)))
        futures = [pool.submit(objective, part) for part in np.array_split(rows, n_chunks)]
        pairs = [pair for future in futures for pair in future.result()]
    return np.array([p[0] for p in pairs], float), [p[1] for p in pairs]


# -------------------------------------------------------------------------------- result
@dataclass(frozen=True, eq=False)
class ParetoResult:
    """The non-dominated solutions of a multi-objective fit, and how the search went.

    Attributes
    ----------
    structure : ModelStructure
    free : tuple of str
        Estimated parameters.
    objective_names : tuple of str
        The outputs whose fit is an objective (``("y_cb", "F_c")`` by default).
    front : tuple of dict
        All parameter values (free and fixed) of each non-dominated solution.
    objectives : ndarray, shape (n_front, n_objectives)
        Fit [%] per objective output of each solution (the GA minimised ``100 - fit``).
    population_objectives : ndarray, shape (n_population, n_objectives)
        Fit [%] of the final population (dominated solutions included), for the plot.
    history : tuple of dict
        Per generation: ``generation``, ``evaluations``, ``best_fit`` (best fit per objective in
        the population so far), ``best_cost`` (lowest least-squares cost :func:`polish_cost` of
        one candidate so far), ``front_size``, ``infeasible`` (in that generation), ``seconds``.
    bounds : dict
        The bounds the search used.
    n_evaluations : int
    wall_time : float
    message : str
    """

    structure: ModelStructure
    free: tuple[str, ...]
    objective_names: tuple[str, ...]
    front: tuple[dict, ...]
    objectives: np.ndarray
    population_objectives: np.ndarray
    history: tuple[dict, ...]
    bounds: Mapping[str, tuple[float, float]]
    n_evaluations: int
    wall_time: float
    message: str = ""

    @property
    def costs(self) -> np.ndarray:
        """The minimised objectives ``100 - fit`` of the front."""
        return 100.0 - self.objectives

    def pick(self, index: int | None = None, *, weights: Sequence[float] | None = None,
             rule: str = "knee") -> IdentificationResult:
        """One solution of the front as an :class:`IdentificationResult`.

        Parameters
        ----------
        index : int, optional
            The solution at this position of :attr:`front` (overrides the rest).
        weights : sequence of float, optional
            Minimise ``sum_j w_j (100 - fit_j)`` over the front (one weight per objective).
        rule : {"knee", "best:<output>"}
            ``"knee"``: the compromise closest to the ideal point, objectives normalised to
            [0, 1] over the front; ``"best:F_c"``: the best fit on that output.
        """
        chosen = self._choose(index, weights, rule)
        parameters = self.front[chosen]
        fits = dict(zip(self.objective_names, self.objectives[chosen].tolist()))
        details = {"pareto_index": chosen, "rule": rule if index is None and weights is None
                   else ("index" if index is not None else f"weights {list(weights)}"),
                   "front_size": len(self.front), "history": list(self.history)}
        return make_result(self, parameters, fits, method="nsga2", success=True,
                           message=f"Pareto solution {chosen} of {len(self.front)}"
                                   f" ({self.message})", details=details)

    def _choose(self, index: int | None, weights: Sequence[float] | None, rule: str) -> int:
        if not self.front:
            raise IdentificationError("the Pareto front is empty: every candidate was infeasible")
        if index is not None:
            if not -len(self.front) <= index < len(self.front):
                raise IdentificationError(f"index {index} outside the front of {len(self.front)}")
            return index % len(self.front)
        costs = self.costs
        if weights is not None:
            w = np.asarray(weights, float)
            if w.shape != (costs.shape[1],):
                raise IdentificationError(f"weights {list(weights)}: need one per objective "
                                          f"{list(self.objective_names)}")
            return int(np.argmin(costs @ w))
        if rule.startswith("best:"):
            name = rule.removeprefix("best:")
            if name not in self.objective_names:
                raise IdentificationError(f"rule {rule!r}: {name!r} is not an objective "
                                          f"{list(self.objective_names)}")
            return int(np.argmax(self.objectives[:, self.objective_names.index(name)]))
        if rule != "knee":
            raise IdentificationError(f"unknown rule {rule!r} (use 'knee' or 'best:<output>')")
        return knee_index(costs)

    def polish(self, choice: IdentificationResult | int | None, data: IdentificationData, *,
               executor: Any = None, progress: Progress | None = None,
               **least_squares_options: Any) -> IdentificationResult:
        """Refine a chosen solution by Levenberg-Marquardt; never returns a worse one.

        The LM cost is ``sum_j (1 - fit_j / 100)^2`` over the objective outputs (the residuals of
        :func:`panto.identification.estimation.least_squares.fit_least_squares` are normalised per output so that
        their squared norm is exactly this). The polished solution is kept only when this cost on
        `data` is not larger than the chosen one's; otherwise (or when LM fails) the choice is
        returned, with the reason in ``details["polish"]``.
        """
        from panto.identification.estimation.least_squares import fit_least_squares

        chosen = choice if isinstance(choice, IdentificationResult) else self.pick(choice)
        objective = ParetoObjective(self.structure, data, dict(chosen.parameters), self.free,
                                    self.objective_names)
        before = objective.fits(chosen.parameters)
        options = {"bounds": dict(self.bounds), **least_squares_options}
        try:
            polished = fit_least_squares(self.structure, data.select_outputs(self.objective_names),
                                         free=self.free, initial=dict(chosen.parameters),
                                         executor=executor, progress=progress, **options)
            after = objective.fits(polished.parameters)
            reason = polished.message
        except (ValueError, ArithmeticError, RuntimeError) as error:
            polished, after, reason = None, np.full(len(before), np.nan), f"LM failed: {error}"
        kept = polished is not None and np.all(np.isfinite(after)) and \
            polish_cost(after) <= polish_cost(before)
        summary = {"before": dict(zip(self.objective_names, before.tolist())),
                   "after": dict(zip(self.objective_names, after.tolist())),
                   "kept": "polished" if kept else "pareto", "message": reason}
        if progress:
            progress(f"polish: fit {_format(before, self.objective_names)} -> "
                     f"{_format(after, self.objective_names)}, kept {summary['kept']}")
        base = polished if kept else chosen
        fits = dict(zip(self.objective_names, (after if kept else before).tolist()))
        details = {**dict(chosen.details), **dict(base.details), "polish": summary}
        return dataclasses.replace(base, fit=fits, details=details,
                                   method="nsga2+levenberg-marquardt" if kept else chosen.method)


def polish_cost(fits: np.ndarray) -> float:
    """Least-squares cost of fits [%]: ``sum_j (1 - fit_j / 100)^2``."""
    return float(np.sum((1.0 - np.asarray(fits, float) / 100.0) ** 2))


def knee_index(costs: np.ndarray) -> int:
    """Index of the point closest to the ideal point, each objective scaled to [0, 1]."""
    low, high = costs.min(axis=0), costs.max(axis=0)
    span = np.where(high > low, high - low, 1.0)
    return int(np.argmin(np.linalg.norm((costs - low) / span, axis=1)))


def simulate_outputs(structure: ModelStructure, parameters: Mapping[str, float],
                     outputs: Sequence[str], data: IdentificationData) -> np.ndarray:
    """The structure's simulated `outputs` (columns in that order) on `data`."""
    simulated = np.asarray(structure.simulate(parameters, data), float)
    return simulated[:, [list(structure.output_names).index(name) for name in outputs]]


def make_result(pareto: ParetoResult, parameters: Mapping[str, float], fits: Mapping[str, float],
                *, method: str, success: bool, message: str,
                details: Mapping[str, Any]) -> IdentificationResult:
    """An :class:`IdentificationResult` for one parameter set of a Pareto search."""
    n = len(pareto.free)
    return IdentificationResult(
        structure=pareto.structure.name, method=method, parameters=dict(parameters),
        free=pareto.free, std={name: math.nan for name in pareto.free},
        covariance=np.full((n, n), np.nan), fit=dict(fits), success=success, message=message,
        wall_time=pareto.wall_time, n_evaluations=pareto.n_evaluations,
        simulator=partial(simulate_outputs, pareto.structure, dict(parameters),
                          pareto.objective_names),
        details=details)


def _format(fits: np.ndarray, names: Sequence[str]) -> str:
    return ", ".join(f"{name} {value:.1f} %" for name, value in zip(names, fits))


# ---------------------------------------------------------------------------------- search
@dataclass(frozen=True)
class _Setup:
    objective: ParetoObjective
    genes: GeneMap
    bounds: dict


def _setup(structure: ModelStructure, data: IdentificationData, free: Sequence[str],
           bounds: Mapping[str, tuple[float, float]] | None, objectives: Sequence[str],
           initial: Mapping[str, float] | None) -> _Setup:
    free = tuple(free)
    unknown = [n for n in free if n not in structure.parameter_names]
    if unknown or not free:
        raise IdentificationError(f"{structure.name}: free parameters {unknown or '(none)'} not "
                                  f"among {list(structure.parameter_names)}")
    for name in objectives:
        if name not in structure.output_names:
            raise IdentificationError(f"{structure.name}: objective {name!r} is not an output "
                                      f"{list(structure.output_names)}")
        data.output(name)  # names the data if it lacks the output
    merged = {**structure.bounds(), **dict(bounds or {})}
    genes = GeneMap.from_bounds(free, merged)
    base = {**structure.nominal(), **{k: float(v) for k, v in (initial or {}).items()}}
    used = {name: (float(genes.lower[i]), float(genes.upper[i])) for i, name in enumerate(free)}
    return _Setup(ParetoObjective(structure, data, base, free, tuple(objectives)), genes, used)


def fit_pareto(structure: ModelStructure, data: IdentificationData, *, free: Sequence[str],
               bounds: Mapping[str, tuple[float, float]] | None = None,
               objectives: Sequence[str] = ("y_cb", "F_c"), population: int = 40,
               generations: int = 30, executor: Any = None, seed: int | None = None,
               progress: Progress | None = None,
               initial: Mapping[str, float] | None = None,
               stop: Callable[[dict], bool] | None = None) -> ParetoResult:
    """Multi-objective fit of `structure` to `data` with NSGA-II (thesis section 4.1.3).

    Parameters
    ----------
    structure : ModelStructure
    data : IdentificationData
        Inputs and the objective outputs (NaN samples are left out of the fits).
    free : sequence of str
        Parameters to estimate; the others keep `initial` or their nominal values.
    bounds : mapping, optional
        (lower, upper) per free parameter, finite; default the structure's bounds.
    objectives : sequence of str
        Outputs whose ``100 - fit %`` is minimised (thesis: cross bar and force).
    population, generations : int
        Population size and number of generations (the thesis used 1000 individuals).
    executor : concurrent.futures.Executor or dask.distributed.Client, optional
        Evaluates each generation's population in parallel; None evaluates serially.
    seed : int, optional
        Seed of the random initial population and of NSGA-II's operators.
    progress : callable, optional
        Called with one line per generation.
    initial : mapping, optional
        Starting values: free ones are put into the initial population as one individual,
        the others are held fixed at them.
    stop : callable, optional
        Called with each generation's :attr:`ParetoResult.history` record; True ends the
        search early (e.g. ``lambda r: r["best_cost"] <= target`` to stop at a given fit).

    Returns
    -------
    ParetoResult
    """
    from pymoo.algorithms.moo.nsga2 import NSGA2
    from pymoo.core.evaluator import Evaluator
    from pymoo.core.problem import Problem
    from pymoo.problems.static import StaticProblem

    if population < 4 or generations < 1:
        raise IdentificationError(f"population {population} (>= 4) and generations "
                                  f"{generations} (>= 1) too small")
    setup = _setup(structure, data, free, bounds, objectives, initial)
    start = time.perf_counter()
    problem = Problem(n_var=len(setup.genes.names), n_obj=len(objectives), n_ieq_constr=1,
                      xl=0.0, xu=1.0)
    algorithm = NSGA2(pop_size=population, sampling=_initial_genes(setup, population, seed,
                                                                   initial))
    algorithm.setup(problem, termination=("n_gen", generations), seed=seed, verbose=False)
    history: list[dict] = []
    best = np.full(len(objectives), np.inf)
    best_cost = math.inf
    evaluations = 0
    while algorithm.has_next():
        individuals = algorithm.ask()
        costs, messages = evaluate_population(setup.objective,
                                              setup.genes.decode(individuals.get("X")), executor)
        infeasible = np.array([bool(m) for m in messages])
        Evaluator().eval(StaticProblem(problem, F=costs,
                                       G=np.where(infeasible, 1.0, -1.0)[:, None]), individuals)
        algorithm.tell(infills=individuals)
        evaluations += len(costs)
        if (~infeasible).any():
            best = np.minimum(best, costs[~infeasible].min(axis=0))
            best_cost = min(best_cost, min(polish_cost(100.0 - c) for c in costs[~infeasible]))
        history.append(_generation_record(len(history) + 1, evaluations, best, best_cost,
                                          algorithm, int(infeasible.sum()), start, messages))
        if progress:
            progress(_progress_line(history[-1], generations, objectives))
        if stop is not None and stop(history[-1]):
            break
    return _pareto_result(setup, algorithm, history, evaluations, start, len(history))


def _initial_genes(setup: _Setup, population: int, seed: int | None,
                   initial: Mapping[str, float] | None) -> np.ndarray:
    """Latin-hypercube initial genes; the `initial` free values as the first individual."""
    rng = np.random.default_rng(seed)
    n = len(setup.genes.names)
    strata = (rng.permuted(np.tile(np.arange(population), (n, 1)), axis=1).T
              + rng.random((population, n))) / population
    if initial and any(name in initial for name in setup.genes.names):
        values = [float(initial.get(name, setup.objective.base[name]))
                  for name in setup.genes.names]
        strata[0] = setup.genes.encode(np.array(values))
    return strata


def _generation_record(generation: int, evaluations: int, best: np.ndarray, best_cost: float,
                       algorithm: Any, infeasible: int, start: float,
                       messages: list[str]) -> dict:
    record = {"generation": generation, "evaluations": evaluations,
              "best_fit": (100.0 - best).tolist(), "best_cost": best_cost,
              "front_size": len(algorithm.opt),
              "infeasible": infeasible, "seconds": time.perf_counter() - start}
    reasons = sorted({m for m in messages if m})
    if reasons:
        record["infeasible_reasons"] = reasons[:3]
    return record


def _progress_line(record: dict, generations: int, objectives: Sequence[str]) -> str:
    fits = ", ".join(f"{name} {fit:.1f} %" for name, fit in zip(objectives, record["best_fit"]))
    return (f"generation {record['generation']}/{generations}: best fit {fits}; front "
            f"{record['front_size']}, {record['infeasible']} infeasible, "
            f"{record['evaluations']} evaluations, {record['seconds']:.1f} s")


def _pareto_result(setup: _Setup, algorithm: Any, history: list[dict], evaluations: int,
                   start: float, generations: int) -> ParetoResult:
    optimum = algorithm.opt
    feasible = np.asarray(optimum.get("G"))[:, 0] <= 0
    genes = np.asarray(optimum.get("X"))[feasible]
    costs = np.asarray(optimum.get("F"))[feasible]
    unique = np.unique(np.round(genes, 12), axis=0, return_index=True)[1] if len(genes) else []
    order = sorted(unique, key=lambda i: tuple(costs[i]))
    values = setup.genes.decode(genes[order]) if len(order) else np.empty((0, genes.shape[1]))
    front = tuple(setup.objective.parameters(row) for row in values)
    final = np.asarray(algorithm.pop.get("F"))
    message = (f"{generations} generations of {len(algorithm.pop)}, {evaluations} evaluations, "
               f"{len(front)} non-dominated" if front else "no feasible candidate found")
    return ParetoResult(
        structure=setup.objective.structure, free=setup.objective.free,
        objective_names=setup.objective.outputs, front=front,
        objectives=100.0 - costs[order] if len(order) else np.empty((0, costs.shape[1])),
        population_objectives=100.0 - final, history=tuple(history), bounds=setup.bounds,
        n_evaluations=evaluations, wall_time=time.perf_counter() - start, message=message)
