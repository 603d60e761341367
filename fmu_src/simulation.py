"""Simulation of the models on the Python path (SciPy's ``solve_ivp``).

The inputs are sampled signals, linear between samples (as :mod:`panto.build_fmu.simulate` feeds the
FMUs) or held constant between samples (``interpolation="hold"``). The integration restarts where
the inputs have a kink or a step, so that these do not spoil the error control, and runs through
every stretch of samples where the input is one smooth (constant or affine) function, reading the
states at the samples from the solver's dense output.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
from scipy.integrate import solve_ivp

from panto.fmu_src.models import Model
from panto.fmu_src.response import TimeResponse


@dataclass(frozen=True, kw_only=True)
class SolverOptions:
    """Settings of :func:`scipy.integrate.solve_ivp` for :func:`simulate_model`.

    Parameters
    ----------
    method : str
        The default LSODA switches to an implicit method with the exact Jacobian where the
        contact spring makes the problem stiff; explicit methods (RK23, RK45, DOP853) get none.
    rtol : float
        Relative tolerance.
    atol : float
        Absolute tolerance, in the units of the states.
    """

    method: str = "LSODA"
    rtol: float = 1e-8
    atol: float = 1e-10


def simulate_model(
    model: Model,
    time: np.ndarray,
    inputs: Mapping[str, np.ndarray | float],
    *,
    initial_state: np.ndarray | None = None,
    interpolation: str = "linear",
    solver: SolverOptions | None = None,
) -> TimeResponse:
    """Simulate a model on the Python path.

    Parameters
    ----------
    model : Model
        The model and its parameters.
    time : array_like
        Strictly increasing output times [s]; inputs are sampled on the same grid.
    inputs : mapping
        ``{"eta": array or constant, "p": array or constant}`` sampled at ``time``.
    initial_state : array_like, optional
        Initial state x = [q; v]; by default the static equilibrium for the first input sample.
    interpolation : {"linear", "hold"}
        Inputs between samples: linear interpolation or zero-order hold.
    solver : SolverOptions, optional
        Method and tolerances of :func:`scipy.integrate.solve_ivp` (default ``SolverOptions()``).

    Returns
    -------
    TimeResponse
        Outputs and states at ``time``.
    """
    solver = solver or SolverOptions()
    time = np.asarray(time, dtype=float)
    if time.ndim != 1 or time.size < 2 or np.any(np.diff(time) <= 0):
        raise ValueError("time must be a strictly increasing 1-D array with at least two samples")
    if interpolation not in ("linear", "hold"):
        raise ValueError(f"interpolation must be 'linear' or 'hold', not {interpolation!r}")
    u = _input_matrix(model, inputs, time.size)
    x = model.equilibrium(*u[0]) if initial_state is None else np.asarray(initial_state, float)
    # Python floats: the generated functions evaluate math on them about 3x faster than on
    # NumPy scalars (same IEEE operations, identical results).
    p = model.parameters.vector().tolist()
    numeric = model.numeric
    states = np.empty((time.size, x.size))
    states[0] = x
    for first, last in _smooth_stretches(time, u, interpolation):
        inputs_at = _input_function(time[first:last + 1], u[first:last + 1], interpolation)
        sol = _integrate(numeric, p, x, time[first:last + 1], inputs_at, solver)
        if not sol.success:
            raise RuntimeError(f"{model.name}: integration failed after t = {time[first]:g} s "
                               f"({sol.message})")
        states[first + 1:last + 1] = sol.y[:, 1:].T
        x = states[last]
    outputs = np.array([numeric.outputs(p, state.tolist(), sample.tolist())
                        for state, sample in zip(states, u)])
    return _response(model, time, u, states, outputs)


def _smooth_stretches(time: np.ndarray, u: np.ndarray, interpolation: str) -> list[tuple[int, int]]:
    """Index pairs ``(first, last)`` of the sample stretches over which the input is smooth.

    With ``"hold"`` a stretch ends where the held value changes; with ``"linear"`` where the
    slope changes (a kink), compared to 1e-9 of the slopes' scale so that the rounding of an
    evenly sampled ramp does not cut it. Consecutive stretches share their boundary sample.
    """
    if interpolation == "hold":
        change = np.any(u[1:-1] != u[:-2], axis=1)  # interval k+1 holds another value than k
    else:
        slope = np.diff(u, axis=0) / np.diff(time)[:, None]
        scale = np.max(np.abs(slope), axis=0)
        change = np.any(np.abs(np.diff(slope, axis=0)) > 1e-9 * scale, axis=1)
    boundaries = np.concatenate([[0], np.flatnonzero(change) + 1, [time.size - 1]])
    return list(zip(boundaries[:-1].tolist(), boundaries[1:].tolist()))


def _input_function(time: np.ndarray, u: np.ndarray, interpolation: str
                    ) -> Callable[[float], list[float]]:
    """The input over one smooth stretch: the held first sample, or linear between the samples."""
    if interpolation == "hold":
        held = u[0].tolist()
        return lambda t: held
    if time.size == 2:
        t0, u0, slope = time[0], u[0], (u[1] - u[0]) / (time[1] - time[0])
        return lambda t: (u0 + (t - t0) * slope).tolist()
    columns = u.T
    return lambda t: [float(np.interp(t, time, column)) for column in columns]


def _integrate(numeric: Any, p: list[float], x: np.ndarray, time: np.ndarray,
               inputs_at: Callable[[float], list[float]], solver: SolverOptions) -> Any:
    """One :func:`scipy.integrate.solve_ivp` run from ``x`` at ``time[0]``, sampled at ``time``."""
    jacobian = {} if solver.method in ("RK23", "RK45", "DOP853") else {
        "jac": lambda t, z: numeric.jacobians(p, z.tolist(), inputs_at(t))[0]}
    return solve_ivp(lambda t, z: numeric.derivatives(p, z.tolist(), inputs_at(t)),
                     (time[0], time[-1]), x, t_eval=time, method=solver.method,
                     rtol=solver.rtol, atol=solver.atol, **jacobian)


def _input_matrix(model: Model, inputs: Mapping[str, np.ndarray | float], n: int) -> np.ndarray:
    unknown = sorted(set(inputs) - set(model.input_names))
    if unknown:
        raise ValueError(f"unknown input(s) {unknown}; {model.name} has {list(model.input_names)}")
    columns = []
    for name in model.input_names:
        if name not in inputs:
            raise ValueError(f"input {name!r} is missing (give an array or a constant)")
        values = np.broadcast_to(np.asarray(inputs[name], dtype=float), (n,))
        if not np.all(np.isfinite(values)):
            raise ValueError(f"input {name!r} contains NaN or infinite values")
        columns.append(values)
    return np.stack(columns, axis=1)


def _response(model: Model, time, u, states, outputs) -> TimeResponse:
    spec = model.numeric.model
    signals, units = {}, {}
    for variable, column in zip(spec.inputs, u.T):
        signals[variable.name], units[variable.name] = column, variable.unit
    for variable, column in zip(spec.outputs, outputs.T):
        signals[variable.name], units[variable.name] = column, variable.unit
    for variable, column in zip(spec.coordinates + spec.velocities, states.T):
        if variable.name not in signals:
            signals[variable.name], units[variable.name] = column, variable.unit
    return TimeResponse(time=time, signals=signals, units=units,
                        metadata={"model": model.name, "interface": "python",
                                  "parameters": dict(model.parameters.values)})
