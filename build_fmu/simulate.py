"""Simulate the project's FMUs (FMI 2.0 and 3.0, Model Exchange or Co-Simulation) with fmpy.

Identification and design loops simulate one FMU thousands of times with different parameters.
:class:`FmuSimulator` therefore extracts the FMU once, reads its model description once and
instantiates it once; every :meth:`FmuSimulator.simulate` call resets the instance
(``fmi2Reset`` / ``fmi3Reset``), sets the parameters, initialises and runs. A fresh
``fmpy.simulate_fmu`` per run re-extracts and re-instantiates and is several times slower.
:func:`simulate_fmu_with_inputs` is the one-call facade for a single run.

Inputs
    Given as samples on the time grid; between samples they are **piecewise linear** (linear
    interpolation), and an input that is not given is held at its start value.

    * Model Exchange: exact; every right-hand-side evaluation of the solver (SUNDIALS CVODE,
      BDF, as shipped with fmpy) sets the inputs to :math:`u(t)`.
    * Co-Simulation: the FMU holds its inputs constant over a communication step, so over
      :math:`[t_k, t_{k+1}]` it receives the mean :math:`\\bar u_k = \\frac{1}{t_{k+1}-t_k}
      \\int_{t_k}^{t_{k+1}} u\\,dt` of the piecewise-linear input (the midpoint value when the
      step is one sample interval). This matches the Model Exchange run to second order in the
      step. Before the outputs at :math:`t_{k+1}` are read, the inputs are set to their samples
      :math:`u(t_{k+1})`, so direct feed-through outputs (e.g. a contact force) are exact.

Errors
    Names that the model does not have raise :class:`UnknownVariableError` listing the valid
    names. A failing FMI call raises :class:`SimulationError`, which carries the function name,
    the status, the simulation time and the FMU's log messages (e.g. "linkage cannot close at
    ..."). The instance is then reset (or, after a fatal error, re-instantiated) on the next run.
"""
from __future__ import annotations

import math
import shutil
import weakref
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Callable

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.simulation import instantiate_fmu

from panto.fmu_src.response import TimeResponse

from .fmi_plumbing import (STATUS_LABELS, FloatChannel, LogCollector, PiecewiseLinearInputs,
                           make_cvode_solver)
from .parameter_sources import fmu_parameter_values

INTERFACES = {"CS": "CoSimulation", "ME": "ModelExchange"}
DEFAULT_ME_TOLERANCE = 1e-6
_FLOAT_TYPES = ("Real", "Float64")
_FATAL = 4


class UnknownVariableError(ValueError):
    """A variable name the FMU does not have (or not with the role asked for)."""


class SimulationError(RuntimeError):
    """An FMU call failed, or the FMU asked to terminate, during a simulation.

    Attributes
    ----------
    function : str or None
        FMI function that failed, e.g. ``"fmi2ExitInitializationMode"``.
    status : int or None
        Its status (3 = error, 4 = fatal).
    time : float or None
        Simulation time (s) at which it failed.
    messages : tuple of str
        The FMU's log messages of the failed run, e.g.
        ``("[ERROR] Pantograph: linkage cannot close at phi1 = 1.2 rad",)``.
    """

    def __init__(self, message: str, *, function: str | None = None, status: int | None = None,
                 time: float | None = None, messages: Sequence[str] = ()) -> None:
        self.function = function
        self.status = status
        self.time = time
        self.messages = tuple(messages)
        details = "".join(f"\n  {line}" for line in self.messages)
        super().__init__(message + (f"\nFMU log:{details}" if details else ""))

    @classmethod
    def from_call(cls, error: FMICallException, *, model: str, interface: str, time: float,
                  messages: Sequence[str]) -> "SimulationError":
        """The error for a failed FMU call `error` of `model` at simulation time `time` [s]."""
        label = STATUS_LABELS[error.status].lower() if 0 <= error.status < 6 else "?"
        return cls(f"{model} ({interface}): {error.function} failed with status {error.status} "
                   f"({label}) at t = {time:g} s", function=error.function, status=error.status,
                   time=time, messages=messages)


def _describe_names(names: Sequence[str]) -> str:
    return ", ".join(sorted(names)) if names else "(none)"


def check_names(given: Sequence[str], valid: Sequence[str], role: str, model: str) -> None:
    """Raise :class:`UnknownVariableError` naming every name of `given` not in `valid`."""
    unknown = [name for name in given if name not in valid]
    if unknown:
        raise UnknownVariableError(f"{model} has no {role} named {', '.join(map(repr, unknown))}; "
                                   f"valid {role} names: {_describe_names(valid)}")


def _start_value(variable: Any) -> Any:
    """The start value of a model variable as a Python number (None when it has none)."""
    start = variable.start
    if start is None or isinstance(start, (bool, int, float)):
        return start
    if variable.type == "Boolean":
        return str(start).strip().lower() in ("true", "1")
    if variable.type in ("Real", "Float64", "Float32"):
        return float(start)
    if variable.type == "String":
        return start
    return int(start)


def _output_times(time: np.ndarray, output_interval: float | None) -> np.ndarray:
    if output_interval is None:
        return time
    if not output_interval > 0.0:
        raise ValueError(f"output_interval must be positive, got {output_interval!r}")
    count = int(math.floor((time[-1] - time[0]) / output_interval * (1 + 1e-12))) + 1
    grid = time[0] + output_interval * np.arange(count)
    if math.isclose(grid[-1], time[-1], rel_tol=1e-12, abs_tol=1e-12):
        grid[-1] = time[-1]  # never step past the end of the inputs (the FMU's stop time)
        return grid
    return np.append(grid, time[-1])


def _time_grid(time: Any) -> np.ndarray:
    grid = np.asarray(time, dtype=float)
    if grid.ndim != 1 or grid.size < 2:
        raise ValueError(f"time must be a 1-D array of at least 2 points, got shape {grid.shape}")
    if not np.all(np.isfinite(grid)) or np.any(np.diff(grid) <= 0.0):
        raise ValueError("time must be finite and strictly increasing")
    return grid


class FmuSimulator:
    """One extracted FMU and one instance of it, simulated again and again.

    Parameters
    ----------
    fmu_path : str or pathlib.Path
        An ``.fmu`` file (extracted once, to a temporary folder removed by :meth:`close`) or
        an already extracted FMU folder.
    interface : {"CS", "ME"}, optional
        Co-Simulation (the FMU's own solver; default) or Model Exchange (CVODE from fmpy).
    output_names : sequence of str, optional
        Variables to record (default: all outputs). Any Real/Float64 variable may be named.
    debug_logging : bool, optional
        Switch the FMU's debug logging on (its messages go to the log collected per run).
    validate : bool, optional
        Validate the model description against the FMI schema when reading it (default True).

    Attributes
    ----------
    model_description : fmpy.model_description.ModelDescription
        Read once.
    variables : dict of str to fmpy ModelVariable
        All model variables by name.
    input_names, parameter_names, output_names : tuple of str
        Inputs and (independent) parameters of the model, and the recorded variables.
    fmi3 : bool
        Whether it is an FMI 3.0 FMU (else FMI 2.0), from the model description.

    Raises
    ------
    UnknownVariableError
        If an output name is not a Real/Float64 variable of the model.
    ValueError
        If `interface` is not ``"CS"``/``"ME"``, the FMU does not provide it, or it is not an
        FMI 2.0/3.0 FMU.

    Notes
    -----
    One run (:meth:`simulate`): ``fmi2Reset``/``fmi3Reset`` if the instance has run before
    (after a fatal error, or if the reset fails, the instance is freed and instantiated
    afresh); start values and parameters set in the Instantiated state; FMI 2.0
    ``fmi2SetupExperiment(tolerance, start, stop)`` + ``fmi2EnterInitializationMode``, FMI 3.0
    ``fmi3EnterInitializationMode(tolerance, start, stop)``; the inputs at ``time[0]`` set in
    Initialization Mode (so an FMU that starts in static equilibrium uses them);
    ``ExitInitializationMode``; for ME the event iteration (``fmi2NewDiscreteStates`` /
    ``fmi3UpdateDiscreteStates``) and Continuous-Time Mode, for FMI 3.0 CS Step Mode directly
    (instantiated without event mode); the run; ``Terminate``.

    A simulator is not thread-safe: give each thread or process its own. Pickling one (as
    process-pool executors do) pickles the FMU path, and unpickling opens a new simulator.

    Examples
    --------
    >>> import numpy as np
    >>> from panto.build_fmu.simulate import FmuSimulator
    >>> time = np.linspace(0.0, 2.0, 401)
    >>> with FmuSimulator("Toy.fmu", interface="ME") as simulator:  # doctest: +SKIP
    ...     for k in (4000.0, 5000.0, 6000.0):
    ...         response = simulator.simulate(time, {"eta": 0.01 + 0 * time, "p": 4.0},
    ...                                       parameters={"k": k})
    ...         print(k, response["F_c"][-1])
    """

    def __init__(self, fmu_path: str | Path, *, interface: str = "CS",
                 output_names: Sequence[str] | None = None, debug_logging: bool = False,
                 validate: bool = True) -> None:
        if interface not in INTERFACES:
            raise ValueError(f"interface must be one of {sorted(INTERFACES)}, got {interface!r}")
        self.fmu_path = Path(fmu_path)
        self.interface = interface
        self._debug_logging = debug_logging
        self._fmu: Any = None
        self._unzipdir = self.fmu_path
        if not self.fmu_path.is_dir():
            self._unzipdir = Path(extract(str(self.fmu_path)))
            self._cleanup = weakref.finalize(self, shutil.rmtree, str(self._unzipdir), True)
        self.model_description = read_model_description(str(self._unzipdir), validate=validate)
        md = self.model_description
        self.fmi3 = md.fmiVersion.startswith("3.")
        if md.fmiVersion != "2.0" and not self.fmi3:
            raise ValueError(f"{self.fmu_path}: FMI {md.fmiVersion} is not supported (2.0, 3.0)")
        if (md.coSimulation if interface == "CS" else md.modelExchange) is None:
            raise ValueError(f"{self.fmu_path}: the FMU has no {INTERFACES[interface]} interface")
        self.variables = {variable.name: variable for variable in md.modelVariables}
        self.input_names = self._names_with_causality("input")
        self.parameter_names = self._names_with_causality("parameter")
        float_names = [name for name, variable in self.variables.items()
                       if variable.type in _FLOAT_TYPES and variable.causality != "independent"]
        self.output_names = tuple(self._names_with_causality("output") if output_names is None
                                  else output_names)
        check_names(self.output_names, float_names, "Real/Float64 variable", md.modelName)
        check_names(self.input_names, float_names, "Real/Float64 input", md.modelName)
        self._validate = validate
        self._log = LogCollector()
        self._needs_reset, self._closed = False, False
        self._time = float("nan")
        self._instantiate()

    # --- instance life cycle ----------------------------------------------------------------

    def _instantiate(self) -> None:
        logger = self._log.fmi3_logger if self.fmi3 else self._log.fmi2_logger
        try:
            self._fmu = instantiate_fmu(str(self._unzipdir), self.model_description,
                                        INTERFACES[self.interface],
                                        debug_logging=self._debug_logging, logger=logger)
        except Exception as error:
            raise SimulationError(f"{self.model_description.modelName}: instantiation failed: "
                                  f"{error}", messages=self._log.messages) from error
        self._solver: Any = None  # CVODE for ME, made at the first run (bound to this instance)
        self._inputs = FloatChannel(self._fmu, self.fmi3, self._references(self.input_names))
        self._outputs = FloatChannel(self._fmu, self.fmi3, self._references(self.output_names))
        self._needs_reset = False

    def _names_with_causality(self, causality: str) -> tuple[str, ...]:
        return tuple(name for name, variable in self.variables.items()
                     if variable.causality == causality)

    def _references(self, names: Sequence[str]) -> list[int]:
        return [self.variables[name].valueReference for name in names]

    def _prepare_instance(self) -> None:
        """Bring the instance back to the Instantiated state after an earlier run."""
        self._log.messages.clear()
        if self._fmu is None:
            self._instantiate()
        elif self._needs_reset:
            try:
                self._fmu.reset()
                self._needs_reset = False
            except Exception:
                self._free_instance()
                self._instantiate()

    def _free_instance(self) -> None:
        fmu, self._fmu, self._solver = self._fmu, None, None
        if fmu is not None:
            try:
                fmu.freeInstance()
            except Exception:  # an instance in a fatal state may refuse; the library is gone
                pass

    def close(self) -> None:
        """Free the instance and remove the extracted files (idempotent)."""
        self._closed = True
        self._free_instance()
        cleanup = getattr(self, "_cleanup", None)
        if cleanup is not None:
            cleanup()

    def __repr__(self) -> str:
        state = "closed" if self._closed else "open"
        return (f"FmuSimulator({str(self.fmu_path)!r}, interface={self.interface!r}, "
                f"FMI {self.model_description.fmiVersion}, {state})")

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickle as "open the same FMU again", so a simulator can go to a process pool worker.

        The worker extracts and instantiates its own copy (the FMU path must be reachable).
        """
        return (_reopen, (str(self.fmu_path.resolve()), self.interface, self.output_names,
                          self._debug_logging, self._validate))

    def __enter__(self) -> "FmuSimulator":
        return self

    def __exit__(self, *exc_info: Any) -> None:
        self.close()

    @property
    def default_parameters(self) -> dict[str, Any]:
        """Parameter name → default (start) value from the model description."""
        return {name: _start_value(self.variables[name]) for name in self.parameter_names}

    # --- one run ------------------------------------------------------------------------------

    def simulate(self, time: Sequence[float] | np.ndarray,
                 inputs: Mapping[str, Any] | None = None, *,
                 parameters: Mapping[str, float] | str | Path | Any | None = None,
                 start_values: Mapping[str, Any] | None = None,
                 output_interval: float | None = None,
                 solver_tolerance: float | None = None) -> TimeResponse:
        """Simulate from ``time[0]`` to ``time[-1]`` with the given inputs and parameters.

        Parameters
        ----------
        time : array_like, shape (n,)
            Time points (s) of the input samples, strictly increasing, n >= 2; also the output
            points unless `output_interval` is given.
        inputs : mapping of str to array_like or float, optional
            Input name → samples at `time` (shape (n,)) or a constant. Inputs not given are
            held at their start values. Piecewise linear in between (see module notes).
        parameters : mapping of str to float, parameter file or identification result, optional
            Parameter name → value, set before initialisation; others keep their defaults. A
            parameter file (``parameters.json`` of ``panto identify --out``: units converted,
            model checked) or an identification result (its values of the FMU's parameters) is
            read by :func:`panto.build_fmu.parameter_sources.fmu_parameter_values`.
        start_values : mapping of str to float, optional
            Start values of other variables (e.g. initial states), set before initialisation.
        output_interval : float, optional
            Record on ``time[0] + k * output_interval`` (plus ``time[-1]``) instead of `time`.
        solver_tolerance : float, optional
            Relative tolerance. ME: CVODE's (default: the FMU's default experiment, else 1e-6;
            absolute tolerance = relative tolerance × the FMU's state nominals). CS: passed as
            the experiment tolerance (default: the default experiment's, else none); the
            project's runtime uses the smaller of it and its ``solver_tolerance`` parameter.

        Returns
        -------
        TimeResponse
            The recorded variables at the output times, with units and metadata (model, FMI
            version, interface, all parameter values used, tolerance, number of events).

        Raises
        ------
        UnknownVariableError
            For an input, parameter or start-value name the model does not have.
        ValueError
            For a bad time grid or input samples of the wrong length or not finite.
        SimulationError
            If an FMU call fails (carries the FMU's log) or the FMU asks to terminate.
        """
        md = self.model_description
        if self._closed:
            raise RuntimeError(f"{md.modelName}: the simulator is closed")
        grid = _time_grid(time)
        table = self._input_table(grid, dict(inputs or {}))
        parameters = fmu_parameter_values(parameters, model=md.modelName,
                                          parameter_names=self.parameter_names,
                                          units={n: self.variables[n].unit or ""
                                                 for n in self.parameter_names})
        start_values = dict(start_values or {})
        check_names(list(parameters), self.parameter_names, "parameter", md.modelName)
        check_names(list(start_values), list(self.variables), "variable", md.modelName)
        parameters, start_values = self._coerce(parameters), self._coerce(start_values)
        output_times = _output_times(grid, output_interval)
        solver_tolerance = self._solver_tolerance(solver_tolerance)

        self._prepare_instance()
        self._needs_reset = True
        self._time = float(grid[0])
        try:
            self._set_values({**start_values, **parameters})
            self._initialise(grid[0], grid[-1], table.at(grid[0]), solver_tolerance)
            run = self._run_me if self.interface == "ME" else self._run_cs
            outputs, events = run(output_times, table, solver_tolerance)
            self._fmu.terminate()
        except FMICallException as error:
            raise self._call_failed(error) from error
        except SimulationError:
            raise
        except Exception as error:  # solver failures (CVODE) and the like
            raise SimulationError(f"{md.modelName} ({self.interface}): {error} at t = "
                                  f"{self._time:g} s", time=self._time,
                                  messages=self._log.messages) from error
        return self._response(output_times, outputs, parameters, start_values,
                              solver_tolerance, events)

    def _solver_tolerance(self, given: float | None) -> float | None:
        """The relative tolerance of a run: `given`, else the default experiment's, else (ME)
        :data:`DEFAULT_ME_TOLERANCE`; None for CS without either."""
        experiment = self.model_description.defaultExperiment
        if given is None and experiment is not None:
            given = experiment.tolerance
        if given is None and self.interface == "ME":
            given = DEFAULT_ME_TOLERANCE
        return None if given is None else float(given)

    def _call_failed(self, error: FMICallException) -> SimulationError:
        """The :class:`SimulationError` for a failed FMU call (the instance freed if fatal)."""
        if error.status >= _FATAL:
            self._free_instance()
        return SimulationError.from_call(error, model=self.model_description.modelName,
                                         interface=self.interface, time=self._time,
                                         messages=self._log.messages)

    def _input_table(self, grid: np.ndarray, inputs: dict[str, Any]) -> PiecewiseLinearInputs:
        check_names(list(inputs), self.input_names, "input", self.model_description.modelName)
        columns = []
        for name in self.input_names:
            value = inputs.get(name, _start_value(self.variables[name]) or 0.0)
            samples = np.asarray(value, dtype=float)
            if samples.ndim == 0:
                samples = np.full(grid.shape, float(samples))
            if samples.shape != grid.shape:
                raise ValueError(f"input {name!r} has shape {samples.shape}, time has "
                                 f"{grid.shape}")
            if not np.all(np.isfinite(samples)):
                raise ValueError(f"input {name!r} has non-finite samples (first at index "
                                 f"{int(np.flatnonzero(~np.isfinite(samples))[0])})")
            columns.append(samples)
        values = np.column_stack(columns) if columns else np.zeros((grid.size, 0))
        return PiecewiseLinearInputs(grid, values)

    def _coerce(self, values: Mapping[str, Any]) -> dict[str, Any]:
        """Values converted to the Python type of each variable, refusing what cannot be."""
        coerced = {}
        for name, value in values.items():
            kind = self.variables[name].type
            try:
                if kind == "Boolean":
                    if value not in (0, 1):  # True/False, 0/1, 0.0/1.0
                        raise ValueError("expected True/False or 0/1")
                    coerced[name] = bool(value)
                elif kind == "String":
                    coerced[name] = str(value)
                elif kind in ("Real", "Float64", "Float32"):
                    coerced[name] = float(value)
                    if not math.isfinite(coerced[name]):
                        raise ValueError("not finite")
                else:
                    coerced[name] = int(value)
                    if coerced[name] != value:
                        raise ValueError("expected an integer")
            except (TypeError, ValueError) as error:
                raise ValueError(f"{self.model_description.modelName}: bad value {value!r} for "
                                 f"{kind} variable {name!r} ({error})") from None
        return coerced

    def _set_values(self, values: Mapping[str, Any]) -> None:
        """Set parameters / start values by name, each with the setter of its type."""
        for name, value in values.items():
            kind = self.variables[name].type
            if self.fmi3:
                setter = f"set{'Int64' if kind == 'Enumeration' else kind}"
            else:
                setter = f"set{'Integer' if kind == 'Enumeration' else kind}"
            getattr(self._fmu, setter)([self.variables[name].valueReference], [value])

    def _initialise(self, start: float, stop: float, inputs: np.ndarray,
                    tolerance: float | None) -> None:
        fmu = self._fmu
        if self.fmi3:
            fmu.enterInitializationMode(tolerance=tolerance, startTime=start, stopTime=stop)
        else:
            fmu.setupExperiment(tolerance=tolerance, startTime=start, stopTime=stop)
            fmu.enterInitializationMode()
        self._inputs.set(inputs)
        fmu.exitInitializationMode()
        if self.interface == "ME":
            self._next_event = self._update_discrete_states()
            fmu.enterContinuousTimeMode()

    def _termination(self, time: float) -> SimulationError:
        return SimulationError(f"{self.model_description.modelName} ({self.interface}) asked to "
                               f"terminate at t = {time:g} s", time=time,
                               messages=self._log.messages)

    def _update_discrete_states(self) -> float:
        """Event iteration; returns the next time event (inf if none)."""
        update = self._fmu.updateDiscreteStates if self.fmi3 else self._fmu.newDiscreteStates
        needed, next_event = True, math.inf
        while needed:
            needed, terminate, _, _, defined, event_time = update()
            if terminate:
                raise self._termination(self._time)
            next_event = event_time if defined else math.inf
        return next_event

    def _run_cs(self, times: np.ndarray, table: PiecewiseLinearInputs,
                tolerance: float | None) -> tuple[np.ndarray, int]:
        """doStep from output time to output time with step-mean inputs."""
        outputs = np.empty((times.size, self._outputs.size))
        outputs[0] = self._outputs.get()
        means, samples = table.means(times), table.sample(times)
        do_step, set_inputs, get_outputs = self._fmu.doStep, self._inputs.set, self._outputs.get
        for k in range(times.size - 1):
            self._time = times[k]
            set_inputs(means[k])
            result = do_step(times[k], times[k + 1] - times[k])
            if self.fmi3 and result[1]:
                raise self._termination(result[3])
            set_inputs(samples[k + 1])
            outputs[k + 1] = get_outputs()
        return outputs, 0

    def _run_me(self, times: np.ndarray, table: PiecewiseLinearInputs,
                tolerance: float) -> tuple[np.ndarray, int]:
        """CVODE (BDF) over the FMU's derivatives, with state and time events."""
        self._table = table
        set_time_and_inputs = self._set_time_and_inputs
        solver = self._cvode_solver(float(times[0]), (times[-1] - times[0]) / 50.0, tolerance)
        outputs = np.empty((times.size, self._outputs.size))
        outputs[0] = self._outputs.get()
        events, t = 0, float(times[0])
        for k in range(1, times.size):
            t, handled = self._advance_me(solver, t, float(times[k]), set_time_and_inputs)
            events += handled
            outputs[k] = self._outputs.get()
        return outputs, events

    def _advance_me(self, solver: Any, t: float, end: float, set_time: Callable[[float], None],
                    before_advance: Callable[[float], None] | None = None) -> tuple[float, int]:
        """Integrate from `t` to `end` through time, state and step events; return (end, events).

        `set_time(t)` hands the FMU the time (and the inputs at it) after each solver step;
        `before_advance(target)` runs before each one (e.g. to set CVODE's stop time).
        """
        fmu = self._fmu
        completed_step = self.model_description.modelExchange.needsCompletedIntegratorStep
        events = 0
        while end - t > 1e-13 * max(1.0, abs(end)):
            target = min(end, self._next_event)
            if before_advance is not None:
                before_advance(target)
            state_event, t = solver.advance(t, target)
            set_time(t)
            step_event = False
            if completed_step:
                step_event, terminate = fmu.completedIntegratorStep()
                if terminate:
                    raise self._termination(t)
            if state_event or step_event or t >= self._next_event - 1e-13:
                fmu.enterEventMode()
                self._next_event = self._update_discrete_states()
                fmu.enterContinuousTimeMode()
                solver.reset(t)
                events += 1
        return t, events

    def _set_time_and_inputs(self, t: float) -> None:
        """Time and inputs u(t) of the current run, before each evaluation of the FMU."""
        self._time = t
        self._fmu.setTime(t)
        self._inputs.set(self._table.at(t))

    def _cvode_solver(self, start: float, max_step: float, tolerance: float) -> Any:
        """The instance's CVODE solver, restarted at `start` (made anew for a new tolerance)."""
        if self._solver is not None and self._solver.reltol == tolerance:
            self._solver.restart(start, max_step)
            return self._solver
        fmu, md = self._fmu, self.model_description
        self._solver = make_cvode_solver(
            nx=md.numberOfContinuousStates, nz=md.numberOfEventIndicators,
            get_x=fmu.getContinuousStates, set_x=fmu.setContinuousStates,
            get_dx=fmu.getContinuousStateDerivatives if self.fmi3 else fmu.getDerivatives,
            get_z=fmu.getEventIndicators, get_nominals=fmu.getNominalsOfContinuousStates,
            set_time=self._set_time_and_inputs, startTime=start, maxStep=max_step,
            relativeTolerance=tolerance)
        return self._solver

    def _response(self, times: np.ndarray, outputs: np.ndarray, parameters: dict[str, Any],
                  start_values: dict[str, Any], tolerance: float | None,
                  events: int) -> TimeResponse:
        md = self.model_description
        units = {}
        for name in self.output_names:
            variable = self.variables[name]
            declared = getattr(variable, "declaredType", None)
            units[name] = variable.unit or (declared.unit if declared is not None else None) or ""
        metadata = {
            "model": md.modelName, "fmi_version": md.fmiVersion, "interface": self.interface,
            "fmu": str(self.fmu_path), "parameters": {**self.default_parameters, **parameters},
            "start_values": dict(start_values), "input_interpolation": "linear",
            "solver": "CVODE (BDF, fmpy)" if self.interface == "ME" else "FMU internal",
            "solver_tolerance": tolerance, "events": events}
        signals = {name: outputs[:, i] for i, name in enumerate(self.output_names)}
        return TimeResponse(times, signals, units=units, metadata=metadata)


def _reopen(fmu_path: str, interface: str, output_names: Sequence[str], debug_logging: bool,
            validate: bool) -> FmuSimulator:
    return FmuSimulator(fmu_path, interface=interface, output_names=output_names,
                        debug_logging=debug_logging, validate=validate)


def simulate_fmu_with_inputs(fmu_path: str | Path, time: Sequence[float] | np.ndarray,
                             inputs: Mapping[str, Any] | None = None, *,
                             interface: str = "CS", output_names: Sequence[str] | None = None,
                             **options: Any) -> TimeResponse:
    """Simulate an FMU once with input time series (facade over :class:`FmuSimulator`).

    For many runs of the same FMU, keep one :class:`FmuSimulator` instead: it extracts and
    instantiates once.

    Parameters
    ----------
    fmu_path : str or pathlib.Path
        ``.fmu`` file or extracted FMU folder.
    time, inputs
        As in :meth:`FmuSimulator.simulate`.
    interface : {"CS", "ME"}, optional
        Co-Simulation (default) or Model Exchange.
    output_names : sequence of str, optional
        Variables to record (default: the outputs).
    **options
        Keyword options of :meth:`FmuSimulator.simulate` (``parameters``, ``start_values``,
        ``output_interval``, ``solver_tolerance``).

    Returns
    -------
    TimeResponse

    Examples
    --------
    >>> import numpy as np
    >>> from panto.build_fmu.simulate import simulate_fmu_with_inputs
    >>> time = np.linspace(0.0, 1.0, 201)
    >>> response = simulate_fmu_with_inputs("Toy.fmu", time, {"eta": 0.01 * time},
    ...                                     parameters={"k": 5000.0})  # doctest: +SKIP
    >>> response.plot()  # doctest: +SKIP
    """
    with FmuSimulator(fmu_path, interface=interface, output_names=output_names) as simulator:
        return simulator.simulate(time, inputs, **options)


__all__ = ["FmuSimulator", "simulate_fmu_with_inputs", "SimulationError",
           "UnknownVariableError", "PiecewiseLinearInputs", "INTERFACES"]
