"""Output-error least squares with a bounded Levenberg-Marquardt-type method (thesis section 4.1.1).

:func:`fit_least_squares` fits the free parameters of any :class:`ModelStructure` to one
experiment by minimising the sum of squared, per-output normalised free-run errors

.. math::

    V(\\theta) = \\tfrac12 \\sum_j \\lVert r_j \\rVert^2, \\qquad
    r_j = \\frac{y_j - \\hat y_j(\\theta)}{\\lVert y_j - \\bar y_j \\rVert},

so that ``fit_j = 100 (1 - ||r_j||)`` is the thesis' fit metric (eq. in section 4.1.3) and the
cost weighs the outputs (force, cross-bar position) as the fit does. NaN samples are left out.

Algorithm
    Levenberg-Marquardt with Marquardt's scaling (thesis eq. 4.14),
    ``(J^T J + lambda diag(J^T J)) h = -J^T r``, the damping ``lambda`` divided by 3 after a
    successful step and multiplied by 4 after a failed one. Bounds: a parameter at a bound whose
    gradient points outwards is held there for the step (an active set), every step is clipped
    into the bounds. Written here rather than taken from :func:`scipy.optimize.least_squares`:
    MINPACK's ``"lm"`` has no bounds (a sine or logistic transform would make the Jacobian vanish
    at a bound and distort the covariance), and ``"trf"`` computes a singular value decomposition
    of the full Jacobian every iteration, which a threaded BLAS on a busy two-core machine turns
    into half a second (here only ``J^T J`` and an ``n x n`` solve are needed). The parameters are
    optimised as ``z = ln(theta / theta_0)`` when their lower bound is positive (masses,
    stiffnesses, dampers: scale-free steps, relative uncertainty) and as
    ``z = (theta - theta_0) / s`` otherwise, ``s`` the nominal magnitude. Stops when the relative
    cost decrease of a step, the step or the gradient falls below ``tolerance``.

Jacobian
    Forward differences in ``z`` (step ``step``, default the structure's ``difference_step`` or
    1e-6), the columns evaluated in parallel through an executor when one is given. A column whose
    forward point is invalid is taken backwards. Optionally (``broyden``, for structures whose run
    is expensive) a Jacobian is reused for a few iterations with Broyden's rank-1 secant updates
    and computed afresh after failed steps and before the run may stop; the damping trials of a
    step then go in pairs to the executor (:func:`_run`, :func:`_step`).

Uncertainty and identifiability
    :mod:`panto.identification.estimation.uncertainty`: the sandwich covariance from the Jacobian with the
    residual variance per output (parameters at a bound left out), 95 % intervals
    ``theta exp(+-1.96 sigma_z)`` for the log-parameterised and ``theta +- 1.96 sigma`` for the
    others, none at a bound, the weak directions of the Fisher information with the parameters
    they involve, and a :class:`ParameterEstimate` per parameter (value, unit, verdict, group).

Fixing what the data cannot pin
    With ``fix_unidentifiable`` the fit is repeated with the fewest parameters fixed at their
    prior (``initial`` or the structure's nominal) that remove the not-identifiable directions
    (:func:`~panto.identification.estimation.uncertainty.parameters_to_fix`), from the previous
    optimum, until none is left; they are reported as "fixed at prior (not identifiable from
    this run)" instead of running to a bound.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from panto.identification.estimation.base import (IdentificationData, IdentificationError, IdentificationResult,
                                 ModelStructure, fit_percent)
from panto.identification.estimation.uncertainty import (ParameterEstimate, describe_identifiability,
                                                        parameter_estimates, parameters_to_fix,
                                                        uncertainty)

Progress = Callable[[str], None]
#: z-value of the two-sided 95 % normal interval.
Z95 = 1.959963984540054


#: Damping trials of a step on a Broyden-updated Jacobian before it is computed afresh.
_UPDATED_TRIALS = 4


class _Budget(Exception):
    """The evaluation budget ran out (internal)."""


@dataclass(frozen=True, eq=False)
class Problem:
    """One least-squares problem: structure, data, free parameters and their transform.

    Picklable (it is what the executor's workers receive).
    """

    structure: ModelStructure
    data: IdentificationData
    free: tuple[str, ...]
    base: Mapping[str, float]
    reference: np.ndarray
    scale: np.ndarray
    logarithmic: np.ndarray
    columns: tuple[int, ...]
    spreads: np.ndarray
    valid: np.ndarray

    def parameters(self, z: np.ndarray) -> dict[str, float]:
        """All parameter values for the transformed free vector `z`."""
        # np.minimum/np.maximum: np.clip's values (NaN kept) at a third of its cost (this runs
        # for every column of the frequency mapping's Jacobians)
        theta = np.where(self.logarithmic,
                         self.reference * np.exp(np.minimum(np.maximum(z, -300.0), 300.0)),
                         self.reference + self.scale * z)
        return {**self.base, **dict(zip(self.free, theta.tolist()))}

    def theta(self, z: np.ndarray) -> np.ndarray:
        """Free parameter values for `z`."""
        return np.array([self.parameters(z)[n] for n in self.free])

    def z_of(self, theta: np.ndarray) -> np.ndarray:
        """Inverse transform."""
        theta = np.asarray(theta, float)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.logarithmic, np.log(theta / self.reference),
                            (theta - self.reference) / self.scale)

    def derivative(self, z: np.ndarray) -> np.ndarray:
        """``d theta / d z`` per free parameter."""
        return np.where(self.logarithmic, self.theta(z), self.scale)

    def simulate(self, z: np.ndarray) -> np.ndarray:
        """Simulated outputs in the data's output order."""
        y = np.asarray(self.structure.simulate(self.parameters(z), self.data), float)
        return y[:, list(self.columns)]

    def residuals(self, z: np.ndarray) -> np.ndarray:
        """Stacked normalised residuals (NaN samples dropped)."""
        y_hat = self.simulate(z)
        if y_hat.shape[0] != len(self.data) or not np.all(np.isfinite(y_hat)):
            raise IdentificationError(f"{self.structure.name}: non-finite simulation")
        errors = (self.data.outputs - y_hat) / self.spreads
        return errors.T[self.valid.T]

    def split(self, r: np.ndarray) -> list[np.ndarray]:
        """Residual vector split per output."""
        counts = np.cumsum(self.valid.sum(axis=0))[:-1]
        return np.split(r, counts)


def evaluate_points(problem: Problem, points: Sequence[np.ndarray]) -> list[np.ndarray | str]:
    """Residuals at each point, or the reason the model is invalid there (executor task)."""
    out: list[np.ndarray | str] = []
    for z in points:
        try:
            out.append(problem.residuals(np.asarray(z, float)))
        except (ValueError, ArithmeticError, RuntimeError, np.linalg.LinAlgError) as error:
            out.append(str(error) or type(error).__name__)
    return out


class _Counter:
    """Evaluation counter, budget, the best point seen and progress."""

    def __init__(self, problem: Problem, budget: int, progress: Progress | None) -> None:
        self.problem, self.budget, self.progress = problem, budget, progress
        self.count, self.best_cost, self.best_z = 0, math.inf, None
        self.iterations = 0

    def charge(self, n: int) -> None:
        if self.count + n > self.budget:
            raise _Budget()
        self.count += n

    def record(self, z: np.ndarray, r: np.ndarray) -> None:
        cost = 0.5 * float(r @ r)
        if cost < self.best_cost:
            self.best_cost, self.best_z = cost, np.array(z, float)

    def report(self, r: np.ndarray) -> None:
        self.iterations += 1
        if self.progress:
            fits = fits_from_residuals(self.problem, r)
            text = ", ".join(f"{k} {v:.2f} %" for k, v in fits.items())
            self.progress(f"  iteration {self.iterations}: {self.count} evaluations, cost "
                          f"{0.5 * float(r @ r):.6g}, fit {text}")


def _map(executor: Any, problem: Problem, points: list[np.ndarray]) -> list[np.ndarray | str]:
    if executor is None or len(points) < 2:
        return evaluate_points(problem, points)
    workers = max(1, int(getattr(executor, "_max_workers", 2) or 2))
    chunks = [points[i::workers] for i in range(min(workers, len(points)))]
    results = list(executor.map(evaluate_points, [problem] * len(chunks), chunks))
    out: list[np.ndarray | str] = [""] * len(points)
    for i, chunk in enumerate(results):
        out[i::len(chunks)] = chunk
    return out


def _jacobian(problem: Problem, z: np.ndarray, r: np.ndarray, step: float, upper: np.ndarray,
              executor: Any, counter: _Counter) -> np.ndarray:
    """Forward differences (backward where the forward point is invalid or out of bounds)."""
    n = len(z)
    signs = np.where(z + step <= upper, 1.0, -1.0)
    points = [z + signs[k] * step * np.eye(n)[k] for k in range(n)]
    counter.charge(n)
    results = _map(executor, problem, points)
    retry = [k for k, res in enumerate(results) if isinstance(res, str)]
    if retry:
        counter.charge(len(retry))
        again = _map(executor, problem, [z - signs[k] * step * np.eye(n)[k] for k in retry])
        for k, res in zip(retry, again):
            signs[k] = -signs[k]
            results[k] = res
    jac = np.zeros((len(r), n))
    for k, res in enumerate(results):
        if not isinstance(res, str):
            jac[:, k] = (res - r) / (signs[k] * step)
    return jac


def fits_from_residuals(problem: Problem, r: np.ndarray) -> dict[str, float]:
    """Fit [%] per output from the normalised residuals."""
    return {name: 100.0 * (1.0 - float(np.linalg.norm(part)))
            for name, part in zip(problem.data.output_names, problem.split(r))}


def _run(problem: Problem, z0: np.ndarray, lower: np.ndarray, upper: np.ndarray, *,
         step: float, executor: Any, progress: Progress | None, budget: int,
         tolerance: float, broyden: int = 0) -> dict[str, Any]:
    """One bounded Levenberg-Marquardt run from `z0` (module notes); a plain summary.

    With ``broyden = k > 0`` the finite-difference Jacobian is reused for up to `k` further
    iterations with Broyden's rank-1 update ``J += (dr - J dz) dz^T / (dz^T dz)`` after each
    accepted step; it is computed afresh when a step with an updated Jacobian fails to lower
    the cost in :data:`_UPDATED_TRIALS` trials (the damping then goes back to its value before
    them) or declares convergence (only a fresh Jacobian may stop the run).
    """
    counter = _Counter(problem, budget, progress)
    counter.charge(1)
    r = evaluate_points(problem, [z0])[0]
    if isinstance(r, str):
        return {"z": z0, "status": "invalid", "message": f"model invalid at the start point: {r}",
                "evaluations": counter.count, "iterations": 0}
    z, damping = np.clip(np.asarray(z0, float), lower, upper), 1e-3
    jac, age = None, 0
    try:
        while True:
            counter.report(r)
            if broyden == 0 or jac is None or age > broyden:
                jac, age = _jacobian(problem, z, r, step, upper, executor, counter), 0
            before = damping
            z_new, r_new, damping, reason = _step(problem, z, r, jac, lower, upper, damping,
                                                  tolerance, counter,
                                                  trials=_UPDATED_TRIALS if age > 0 else None,
                                                  pairs=executor if broyden > 0 else None)
            if age > 0 and (reason or z_new is z):  # decided on an updated Jacobian: refresh
                jac = None
                if z_new is z:  # its failed trials say nothing about the damping
                    damping = before
                    continue
            elif reason:
                return {"z": z_new, "status": "converged", "message": f"converged: {reason}",
                        "evaluations": counter.count, "iterations": counter.iterations}
            if broyden > 0 and jac is not None:
                dz, dr = z_new - z, r_new - r
                jac, age = jac + np.outer(dr - jac @ dz, dz / float(dz @ dz)), age + 1
            z, r = z_new, r_new
    except _Budget:
        return {"z": z, "status": "budget", "message": "not converged: maximum of "
                f"{budget} model evaluations reached", "evaluations": counter.count,
                "iterations": counter.iterations}


def _step(problem: Problem, z: np.ndarray, r: np.ndarray, jac: np.ndarray, lower: np.ndarray,
          upper: np.ndarray, damping: float, tolerance: float, counter: _Counter,
          trials: int | None = None, pairs: Any = None
          ) -> tuple[np.ndarray, np.ndarray, float, str]:
    """Marquardt's step (thesis eq. 4.14), retried with more damping until the cost falls.

    ``(J^T J + lambda diag(J^T J)) h = -J^T r`` on the parameters not held at a bound by the
    gradient; the step is clipped into the bounds. Returns the new point, its residuals, the
    damping for the next iteration and, when converged, the reason (else ""). After `trials`
    failed trials (if given) it returns `z` itself (the same object), no reason and the raised
    damping. With an executor `pairs` each trial is evaluated together with the next one (4 times
    the damping) on it, which the next trial then takes: the same steps, the wall time of one.
    """
    cost = 0.5 * float(r @ r)
    hessian, gradient = jac.T @ jac, jac.T @ r
    at_lower = (z <= lower) & (gradient > 0)
    at_upper = (z >= upper) & (gradient < 0)
    moving = ~(at_lower | at_upper) & (np.diag(hessian) > 0)
    if not moving.any() or np.max(np.abs(gradient[moving])) <= tolerance * max(cost, 1e-300):
        return z, r, damping, "the gradient vanishes (first-order optimality)"
    h_ff = hessian[np.ix_(moving, moving)]
    scaling = np.maximum(np.diag(h_ff), 1e-12 * np.max(np.diag(h_ff)))

    def trial(damping: float) -> np.ndarray:
        step = np.zeros_like(z)
        step[moving] = np.linalg.solve(h_ff + damping * np.diag(scaling), -gradient[moving])
        return np.clip(z + step, lower, upper)

    spare: dict[float, Any] = {}
    while damping < 1e12:
        try:
            z_new = trial(damping)
        except np.linalg.LinAlgError:
            damping *= 10.0
            continue
        if damping in spare:
            r_new = spare.pop(damping)
        elif pairs is not None:
            try:
                z_next = trial(damping * 4.0)
            except np.linalg.LinAlgError:
                z_next = None
            points = [z_new] if z_next is None else [z_new, z_next]
            counter.charge(len(points))
            results = _map(pairs, problem, points)
            r_new = results[0]
            if z_next is not None:
                spare[damping * 4.0] = results[1]
        else:
            counter.charge(1)
            r_new = evaluate_points(problem, [z_new])[0]
        if not isinstance(r_new, str):
            new_cost = 0.5 * float(r_new @ r_new)
            counter.record(z_new, r_new)
            if new_cost < cost:
                small = np.linalg.norm(z_new - z) <= tolerance * (tolerance + np.linalg.norm(z))
                reason = ("the cost no longer decreases (relative change below "
                          f"{tolerance:g})" if cost - new_cost <= tolerance * cost else
                          "the step is below the tolerance" if small else "")
                return z_new, r_new, max(damping / 3.0, 1e-12), reason
        damping *= 4.0
        trials = None if trials is None else trials - 1
        if trials == 0:
            return z, r, damping, ""
    return z, r, damping, "no step decreases the cost (local minimum within the bounds)"


def _run_task(problem: Problem, z0: np.ndarray, lower: np.ndarray, upper: np.ndarray,
              options: dict[str, Any]) -> dict[str, Any]:
    """A whole run inside a worker (multistart)."""
    return _run(problem, z0, lower, upper, executor=None, progress=None, **options)


# --- set-up ---------------------------------------------------------------------------------

def make_problem(structure: ModelStructure, data: IdentificationData, free: Sequence[str],
                 initial: Mapping[str, float] | None,
                 bounds: Mapping[str, tuple[float, float]] | None
                 ) -> tuple[Problem, np.ndarray, np.ndarray, np.ndarray]:
    """Check the options and build the problem; returns ``(problem, z0, lower, upper)``.

    Raises :class:`IdentificationError` naming the parameter, value or output at fault.
    """
    known = tuple(structure.parameter_names)
    free = tuple(free)
    if not free:
        raise IdentificationError(f"{structure.name}: no free parameters given")
    for what, names in (("free", free), ("initial", initial or {}), ("bounds", bounds or {})):
        unknown = [n for n in names if n not in known]
        if unknown:
            raise IdentificationError(f"{structure.name}: {what}: unknown parameter(s) {unknown}; "
                                      f"known: {list(known)}")
    if len(set(free)) != len(free):
        raise IdentificationError(f"{structure.name}: free parameters repeated: {list(free)}")
    missing = [o for o in data.output_names if o not in structure.output_names]
    if missing:
        raise IdentificationError(f"{data.source or 'data'}: output(s) {missing} are not simulated "
                                  f"by {structure.name} (it has {list(structure.output_names)})")
    measured = int(np.isfinite(np.asarray(data.outputs, float)).sum())
    if measured <= len(free):
        raise IdentificationError(f"{data.source or 'data'}: {measured} measured output samples for "
                                  f"{len(free)} free parameters; a fit needs more samples than "
                                  "parameters (give a longer run or fix parameters)")
    base = {**structure.nominal(), **{k: float(v) for k, v in (initial or {}).items()}}
    limits = {**structure.bounds(), **{k: tuple(map(float, v)) for k, v in (bounds or {}).items()}}
    lower = np.array([limits[n][0] for n in free], float)
    upper = np.array([limits[n][1] for n in free], float)
    theta0 = np.array([base[n] for n in free], float)
    # a value a few ulps beyond its bound is at it: a fit's result at a log-parameterised bound
    # comes back through exp(ln(bound / theta_0)) and is often passed on as the next start
    theta0 = np.where(np.isclose(theta0, lower, rtol=1e-12, atol=0.0), np.maximum(theta0, lower),
                      theta0)
    theta0 = np.where(np.isclose(theta0, upper, rtol=1e-12, atol=0.0), np.minimum(theta0, upper),
                      theta0)
    for name, lo, hi, value in zip(free, lower, upper, theta0):
        if not lo < hi:
            raise IdentificationError(f"{structure.name}: bounds of {name!r} are [{lo:g}, {hi:g}]: "
                                      "the lower bound must be below the upper one")
        if not lo <= value <= hi:
            raise IdentificationError(f"{structure.name}: initial {name} = {value:g} lies outside "
                                      f"its bounds [{lo:g}, {hi:g}]")
    logarithmic = lower > 0.0
    magnitude = np.where(theta0 != 0.0, np.abs(theta0),
                         np.where(np.isfinite(upper - lower), (upper - lower) / 100.0, 1.0))
    valid = np.isfinite(data.outputs)
    spreads = np.array([np.linalg.norm(data.outputs[valid[:, j], j]
                                       - data.outputs[valid[:, j], j].mean())
                        if valid[:, j].any() else 0.0 for j in range(len(data.output_names))])
    flat = [o for o, s in zip(data.output_names, spreads) if not s > 0.0]
    if flat:
        raise IdentificationError(f"{data.source or 'data'}: output(s) {flat} are constant or "
                                  "have no valid samples: nothing to fit")
    problem = Problem(structure, data, free, base, theta0, magnitude, logarithmic,
                      tuple(structure.output_names.index(o) for o in data.output_names),
                      spreads, valid)
    return problem, np.zeros(len(free)), problem.z_of(lower), problem.z_of(upper)


def random_starts(lower: np.ndarray, upper: np.ndarray, count: int,
                  rng: np.random.Generator) -> list[np.ndarray]:
    """`count` points uniform in the transformed bounds (log-uniform for positive parameters);
    an infinite bound is replaced by 3 units of ``z`` from the other one (or from 0)."""
    lo = np.where(np.isfinite(lower), lower, np.where(np.isfinite(upper), upper - 3.0, -3.0))
    hi = np.where(np.isfinite(upper), upper, lo + 6.0)
    return [rng.uniform(lo, hi) for _ in range(count)]


# --- the estimator ----------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class FittedSimulator:
    """``simulator(data)``: a structure with fixed parameters, outputs in the fitted order."""

    structure: ModelStructure
    parameters: Mapping[str, float]
    output_names: tuple[str, ...]

    def __call__(self, data: IdentificationData) -> np.ndarray:
        y = np.asarray(self.structure.simulate(dict(self.parameters), data), float)
        return y[:, [self.structure.output_names.index(o) for o in self.output_names]]


def fit_least_squares(structure: ModelStructure, data: IdentificationData, *,
                      free: Sequence[str], initial: Mapping[str, float] | None = None,
                      bounds: Mapping[str, tuple[float, float]] | None = None,
                      executor: Any = None, progress: Progress | None = None,
                      max_evaluations: int = 2000, multistart: int = 0,
                      rng: np.random.Generator | None = None, step: float | None = None,
                      tolerance: float = 1e-6, broyden: int | None = None,
                      identifiability_threshold: float = 0.5,
                      fix_unidentifiable: bool = False) -> IdentificationResult:
    """Fit `free` parameters of `structure` to `data` by bounded Levenberg-Marquardt (module notes).

    Parameters
    ----------
    structure : ModelStructure
    data : IdentificationData
        Its outputs (a subset of the structure's, any order) are fitted.
    free : sequence of str
        Parameters to estimate; the others keep `initial` or their nominal values.
    initial : mapping, optional
        Start values (any parameters; default nominal).
    bounds : mapping, optional
        ``(lower, upper)`` per parameter, overriding ``structure.bounds()``.
    executor : concurrent.futures.Executor, optional
        Evaluates the Jacobian's columns (and multistart runs) in parallel.
    progress : callable, optional
        Receives a line per iteration (evaluations, cost, fit).
    max_evaluations : int
        Budget of model simulations per run (Jacobian columns included).
    multistart : int
        Extra runs from random points within the bounds (``rng``); the best run is returned.
    rng : numpy.random.Generator, optional
        For the multistart points (default ``numpy.random.default_rng()``).
    step : float, optional
        Finite-difference step in the transformed parameters (default
        ``structure.difference_step`` or 1e-6).
    tolerance : float
        Stop when a step lowers the cost by less than this fraction (or the step or the
        gradient is that small).
    broyden : int, optional
        Reuse each finite-difference Jacobian for up to this many further iterations with
        Broyden rank-1 updates (:func:`_run`; default the structure's ``broyden_updates``, else
        0: a fresh Jacobian every iteration).
    identifiability_threshold : float
        Relative standard deviation above which a parameter (or direction) is not identifiable.
    fix_unidentifiable : bool
        Refit with the not-identifiable parameters fixed at their prior (module notes); they
        are left out of ``free`` and named in ``details["fixed_at_prior"]``.

    Returns
    -------
    IdentificationResult
        ``success`` False with the reason in ``message`` when the start point is invalid or the
        budget ran out. ``details``: ``intervals_95``, ``relative_std``, ``identifiability``,
        ``residual_std`` (per output, physical units), ``initial``, ``bounds``, ``cost``,
        ``at_bounds``, ``runs`` (multistart), ``iterations``; with `fix_unidentifiable`
        ``fixed_at_prior`` (name -> reason) and ``first_fit``. ``estimates``: a
        :class:`ParameterEstimate` per requested parameter (fixed ones included).

    Raises
    ------
    IdentificationError
        For bad options: unknown parameter, bounds violated, outputs the structure lacks.
    """
    started = time.perf_counter()
    problem, z0, lower, upper = make_problem(structure, data, free, initial, bounds)
    step = float(step if step is not None else getattr(structure, "difference_step", 1e-6))
    broyden = int(broyden if broyden is not None else getattr(structure, "broyden_updates", 0))
    options = {"step": step, "budget": int(max_evaluations), "tolerance": float(tolerance),
               "broyden": broyden}
    starts = [z0]
    if multistart > 0:
        rng = rng if rng is not None else np.random.default_rng()
        starts += random_starts(lower, upper, int(multistart), rng)
    if progress:
        progress(f"{structure.name}: {len(problem.free)} free parameters, {len(data)} samples, "
                 f"outputs {list(data.output_names)}, {len(starts)} start(s)")
    runs = _run_all(problem, starts, lower, upper, options, executor, progress)
    best = min(runs, key=lambda run: run.get("cost", math.inf))
    result = _result(problem, best, runs, lower, upper, executor, identifiability_threshold,
                     options, started)
    if fix_unidentifiable:
        result = _fix_unidentifiable(problem, result, bounds, executor, progress,
                                     identifiability_threshold, options, started)
    if progress:
        progress(f"{structure.name}: {result.message}; fit " +
                 ", ".join(f"{k} {v:.2f} %" for k, v in result.fit.items()))
    return result


def _run_all(problem: Problem, starts: list[np.ndarray], lower: np.ndarray, upper: np.ndarray,
             options: dict[str, Any], executor: Any, progress: Progress | None) -> list[dict]:
    """The run from the initial point (Jacobian columns in parallel), then the multistarts."""
    runs = [_run(problem, starts[0], lower, upper, executor=executor, progress=progress,
                 **options)]
    if len(starts) > 1:
        if executor is not None:
            futures = [executor.submit(_run_task, problem, z, lower, upper, options)
                       for z in starts[1:]]
            runs += [f.result() for f in futures]
        else:
            runs += [_run(problem, z, lower, upper, executor=None, progress=None, **options)
                     for z in starts[1:]]
    for i, run in enumerate(runs):
        res = evaluate_points(problem, [run["z"]])[0] if run["status"] != "invalid" else "invalid"
        run["cost"] = 0.5 * float(res @ res) if not isinstance(res, str) else math.inf
        if progress and len(runs) > 1:
            progress(f"  start {i}: {run['message']}, cost {run['cost']:.6g}")
    return runs


def _result(problem: Problem, best: dict, runs: list[dict], lower: np.ndarray, upper: np.ndarray,
            executor: Any, threshold: float, options: dict[str, Any],
            started: float) -> IdentificationResult:
    structure, free = problem.structure, problem.free
    z = np.asarray(best["z"], float)
    parameters = problem.parameters(z)
    evaluations = sum(run["evaluations"] for run in runs)
    details: dict[str, Any] = {
        "initial": {n: problem.base[n] for n in free},
        "bounds": {n: (float(lo), float(hi)) for n, lo, hi in
                   zip(free, problem.theta(lower), problem.theta(upper))},
        "runs": [{k: v for k, v in run.items() if k != "z"} |
                 {"parameters": dict(zip(free, problem.theta(run["z"]).tolist()))}
                 for run in runs],
        "iterations": best.get("iterations", 0),
        "algorithm": "Levenberg-Marquardt (Marquardt scaling, eq. 4.14) with bounds by "
                     "projection, on log/normalised parameters, forward-difference Jacobian",
    }
    nan = {n: math.nan for n in free}
    fits = {o: math.nan for o in problem.data.output_names}
    covariance = np.full((len(free), len(free)), np.nan)
    std = nan
    estimates: dict[str, ParameterEstimate] = {}
    success = best["status"] == "converged"
    message = best["message"]
    if best["status"] != "invalid":
        r = problem.residuals(z)
        counter = _Counter(problem, 10 ** 9, None)
        jac = _jacobian(problem, z, r, options["step"], upper, executor, counter)
        evaluations += counter.count + 1
        sides = {n: "lower" if abs(zi - lo) < 1e-6 else "upper"
                 for n, zi, lo, hi in zip(free, z, lower, upper)
                 if abs(zi - lo) < 1e-6 or abs(zi - hi) < 1e-6}
        info = uncertainty(problem, z, r, jac, threshold, np.array([n not in sides for n in free]))
        estimates = parameter_estimates(problem, z, info, sides, structure_units(structure))
        covariance, std = info["covariance"], dict(zip(free, info["std"].tolist()))
        fits = fits_from_residuals(problem, r)
        details.update(
            cost=0.5 * float(r @ r),
            intervals_95={n: e.interval_95 for n, e in estimates.items()},
            relative_std=dict(zip(free, info["relative_std"].tolist())),
            identifiability=info["identifiability"], residual_std=info["residual_std"],
            at_bounds=list(sides), at_bound_sides=sides, fisher_z=info["fisher"])
        fits = {o: float(np.atleast_1d(v)[0]) for o, v in fits.items()}
    return IdentificationResult(
        structure=structure.name, method="levenberg-marquardt", parameters=parameters,
        free=tuple(free), std=std, covariance=covariance, fit=fits, success=success,
        message=message, wall_time=time.perf_counter() - started, n_evaluations=evaluations,
        simulator=FittedSimulator(structure, dict(parameters), problem.data.output_names),
        details=details, estimates=estimates)


def structure_units(structure: ModelStructure) -> dict[str, str]:
    """Unit per parameter from the structure's optional ``units()`` ({} when it has none)."""
    units = getattr(structure, "units", None)
    return dict(units()) if callable(units) else {}


def _fix_unidentifiable(problem: Problem, result: IdentificationResult,
                        bounds: Mapping[str, tuple[float, float]] | None, executor: Any,
                        progress: Progress | None, threshold: float, options: dict[str, Any],
                        started: float) -> IdentificationResult:
    """Refit with the not-identifiable parameters fixed at their prior (module notes)."""
    first, fixed = result, {}
    while "fisher_z" in result.details:
        free = list(result.free)
        report = result.details["identifiability"]
        chosen = parameters_to_fix(free, result.details["fisher_z"], threshold,
                                   list(report["not_identifiable"]))
        kept = [n for n in free if n not in chosen]
        if not chosen or not kept:
            break
        fixed.update({n: report["not_identifiable"][n] for n in chosen})
        if progress:
            progress(f"{problem.structure.name}: fixed at prior (not identifiable from this run): "
                     f"{', '.join(chosen)}; refitting {len(kept)} parameters")
        start = {**problem.base, **{n: result.parameters[n] for n in kept}}
        sub, z0, lower, upper = make_problem(problem.structure, problem.data, kept, start, bounds)
        runs = _run_all(sub, [z0], lower, upper, options, executor, progress)
        evaluations = result.n_evaluations
        result = _result(sub, runs[0], runs, lower, upper, executor, threshold, options, started)
        result = replace(result, n_evaluations=result.n_evaluations + evaluations)
    if not fixed:
        return result
    units = structure_units(problem.structure)
    estimates = dict(result.estimates) | {n: ParameterEstimate(
        n, problem.base[n], units.get(n, "-"), logarithmic=bool(problem.logarithmic[k]),
        verdict="not identifiable", fixed=True, reason=why)
        for k, n in enumerate(problem.free) for why in [fixed.get(n)] if why is not None}
    first_fit = {"parameters": {n: first.parameters[n] for n in problem.free},
                 "fit": dict(first.fit), "message": first.message,
                 "identifiability": first.details.get("identifiability")}
    details = {**result.details, "fixed_at_prior": fixed, "first_fit": first_fit,
               "initial": first.details["initial"], "bounds": first.details["bounds"]}
    return replace(result, estimates={n: estimates[n] for n in problem.free if n in estimates},
                   details=details, wall_time=time.perf_counter() - started,
                   message=f"{result.message}; fixed at prior (not identifiable from this run): "
                           f"{', '.join(fixed)}")


__all__ = ["fit_least_squares", "make_problem", "uncertainty", "describe_identifiability",
           "structure_units", "ParameterEstimate",
           "FittedSimulator", "Problem", "random_starts", "fit_percent"]
