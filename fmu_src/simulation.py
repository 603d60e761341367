"""Simulation of the models on the Python path (SciPy's ``solve_ivp``).

The inputs are sampled signals, linear between samples (as :mod:`panto.build_fmu.simulate` feeds the
FMUs) or held constant between samples (``interpolation="hold"``). The integration restarts at
every sample so that the kinks or steps of the inputs do not spoil the error control.
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
    p = model.parameters.vector()
    numeric = model.numeric
    states = np.empty((time.size, x.size))
    outputs = np.empty((time.size, len(model.output_names)))
    states[0], outputs[0] = x, numeric.outputs(p, x, u[0])
    for k in range(time.size - 1):
        t0, dt, u0 = time[k], time[k + 1] - time[k], u[k]
        slope = (u[k + 1] - u[k]) / dt if interpolation == "linear" else 0.0 * u0

        def inputs_at(t, t0=t0, u0=u0, slope=slope):
            return u0 + (t - t0) * slope

        sol = _integrate(numeric, p, x, (t0, time[k + 1]), inputs_at, solver)
        if not sol.success:
            raise RuntimeError(f"{model.name}: integration failed at t = {time[k]:g} s ({sol.message})")
        x = sol.y[:, -1]
        states[k + 1] = x
        outputs[k + 1] = numeric.outputs(p, x, u[k + 1])
    return _response(model, time, u, states, outputs)


def _integrate(numeric: Any, p: np.ndarray, x: np.ndarray, span: tuple[float, float],
               inputs_at: Callable[[float], np.ndarray], solver: SolverOptions) -> Any:
    """One :func:`scipy.integrate.solve_ivp` run over `span` from the state `x`."""
    jacobian = {} if solver.method in ("RK23", "RK45", "DOP853") else {
        "jac": lambda t, z: numeric.jacobians(p, z, inputs_at(t))[0]}
    return solve_ivp(lambda t, z: numeric.derivatives(p, z, inputs_at(t)), span, x,
                     method=solver.method, rtol=solver.rtol, atol=solver.atol, **jacobian)


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
