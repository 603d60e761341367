"""Drive one FMU instance step by step: for co-simulation masters and the rig's virtual test bed.

:class:`panto.build_fmu.simulate.FmuSimulator` runs whole simulations with known input series. A
co-simulation master does not know the inputs in advance: at every communication point it sets
the inputs it has just computed, advances the FMU by one step and reads the outputs back.
:class:`FmuStepper` does exactly that, about ten thousand times per run, so the hot path uses
value references and fmpy's raw ctypes functions (no name look-ups, no per-call allocation).

Interfaces
    * **Co-Simulation** (``"CS"``): ``fmi2DoStep`` / ``fmi3DoStep`` with the inputs held over
      the step; the FMU integrates with its own solver (the project's FMUs: adaptive RODAS4,
      an L-stable Rosenbrock method, with sub-steps inside the communication step).
    * **Model Exchange** (``"ME"``): integrated by this class with **CVODE** (BDF, variable order
      and step, dense Jacobian; shipped with fmpy) between communication points. The inputs are
      held constant over a step (zero-order hold, as in Co-Simulation); because they jump at
      every communication point CVODE is re-initialised there (``CVodeReInit``), with the stop
      time set to the next communication point so that no right-hand side is evaluated beyond
      it. BDF is stable for the stiff contact spring, and the error is controlled by
      ``solver_tolerance``. State and time events of the FMU are handled (event mode, event
      iteration, re-initialisation).

Both interfaces hold the inputs constant over the step (zero-order hold), so for the same input
sequence they approximate the same continuous-time trajectory and agree to the solver tolerance.
Before the outputs are read at the end of a step the inputs are **not** changed, so a direct
feed-through output (e.g. a contact force ``k (xi - eta)``) is reported for the inputs of the step
just taken; a master that wants it for new inputs sets them first (:meth:`FmuStepper.set_inputs`).

Errors
    A failing FMI call raises :class:`panto.build_fmu.simulate.SimulationError` carrying the function
    name, the status, the time and the FMU's last log lines. Names the FMU does not have raise
    :class:`panto.build_fmu.simulate.UnknownVariableError` (a ``ValueError``) listing the valid names.

Examples
--------
>>> from panto.build_fmu.stepping import FmuStepper
>>> with FmuStepper("TwoMass.fmu", step_size=1e-3, inputs=["eta"],
...                 outputs=["xi", "F_c"]) as stepper:           # doctest: +SKIP
...     y = stepper.initialise({"eta": 0.0})
...     for k in range(1000):
...         y = stepper.step([0.001 * k * 1e-3])
"""
from __future__ import annotations

import contextlib
import ctypes
import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from fmpy.fmi1 import FMICallException

from panto.build_fmu.fmi_plumbing import make_cvode_solver
from panto.build_fmu.simulate import INTERFACES, FmuSimulator, SimulationError, check_names

_FATAL = 4
_OK_OR_WARNING = 1
#: CVODE's relative tolerance for Model Exchange stepping. Tighter than a whole-run simulation
#: needs (1e-6): CVODE restarts at every communication point, so its local errors add up over
#: thousands of restarts; at 1e-8 they stay far below the coupling error.
DEFAULT_ME_TOLERANCE = 1e-8


class _RawFloats:
    """Get/set a fixed list of Real (FMI 2) / Float64 (FMI 3) variables via raw ctypes calls."""

    def __init__(self, fmu: Any, fmi3: bool, references: Sequence[int]) -> None:
        self.size = len(references)
        self._references = (ctypes.c_uint32 * self.size)(*references)
        self._buffer = (ctypes.c_double * self.size)()
        self._values = np.ctypeslib.as_array(self._buffer) if self.size else np.zeros(0)
        self._component = fmu.component
        prefix = "fmi3" if fmi3 else "fmi2"
        kind = "Float64" if fmi3 else "Real"
        self._get_name, self._set_name = f"{prefix}Get{kind}", f"{prefix}Set{kind}"
        self._get = fmu._functions[self._get_name]
        self._set = fmu._functions[self._set_name]
        self._fmi3 = fmi3

    def get(self) -> np.ndarray:
        """Current values (a view of the buffer, overwritten by the next call)."""
        if self.size:
            if self._fmi3:
                status = self._get(self._component, self._references, self.size, self._buffer,
                                   self.size)
            else:
                status = self._get(self._component, self._references, self.size, self._buffer)
            if status > _OK_OR_WARNING:
                raise FMICallException(self._get_name, status)
        return self._values

    def set(self, values: Any) -> None:
        if self.size:
            self._values[:] = values
            if self._fmi3:
                status = self._set(self._component, self._references, self.size, self._buffer,
                                   self.size)
            else:
                status = self._set(self._component, self._references, self.size, self._buffer)
            if status > _OK_OR_WARNING:
                raise FMICallException(self._set_name, status)


@dataclass(frozen=True)
class StepperState:
    """A saved FMU state (``fmi2GetFMUstate`` / ``fmi3GetFMUState``) and the stepper's time.

    Valid for the stepper that made it until :meth:`FmuStepper.free_state`, :meth:`FmuStepper.reset`
    or :meth:`FmuStepper.close`.
    """

    handle: Any
    time: float
    inputs: tuple[float, ...]


def _set_stop_time_function() -> Any:
    """CVODE's ``CVodeSetStopTime`` (fmpy binds only part of the CVODE API)."""
    try:
        from fmpy.sundials.libraries import sundials_cvode
        from fmpy.sundials.sundials_types import sunrealtype

        function = sundials_cvode.CVodeSetStopTime
        function.argtypes = [ctypes.c_void_p, sunrealtype]
        function.restype = ctypes.c_int
        return function
    except (ImportError, AttributeError):  # pragma: no cover - other fmpy builds
        return None


class FmuStepper(FmuSimulator):
    """One FMU instance advanced one communication step at a time.

    Parameters
    ----------
    fmu_path : str or pathlib.Path
        ``.fmu`` file or extracted FMU folder (FMI 2.0 or 3.0).
    step_size : float
        Communication step :math:`h` (s) of :meth:`step`.
    inputs : sequence of str
        Inputs set by :meth:`step`, in this order (Real/Float64 inputs of the FMU). Inputs not
        named keep their start values.
    outputs : sequence of str
        Variables returned by :meth:`step`, in this order (any Real/Float64 variable).
    interface : {"CS", "ME"}, optional
        Co-Simulation (the FMU's own solver, default) or Model Exchange (CVODE, see module notes).
    parameters : mapping of str to value, optional
        Parameters (and start values) set before every initialisation.
    solver_tolerance : float, optional
        Relative tolerance: CVODE's for ME (default :data:`DEFAULT_ME_TOLERANCE`), the
        experiment tolerance for CS
        (default: the FMU's default experiment, else none).
    debug_logging : bool, optional
        Switch the FMU's debug logging on (messages land in the collected log).

    Attributes
    ----------
    time : float
        Current communication point (s); NaN before :meth:`initialise`.
    step_size : float
    stepped_input_names, output_names : tuple of str
        The inputs set by :meth:`step` and the outputs it returns (``input_names`` are all
        the FMU's inputs, as in :class:`FmuSimulator`).
    calls : int
        Number of :meth:`step` calls since the last initialisation.

    Raises
    ------
    UnknownVariableError
        For an input, output or parameter name the FMU does not have.
    ValueError
        For a non-positive step size or an interface the FMU lacks.
    """

    def __init__(self, fmu_path: Any, *, step_size: float, inputs: Sequence[str],
                 outputs: Sequence[str], interface: str = "CS",
                 parameters: Mapping[str, Any] | None = None,
                 solver_tolerance: float | None = None, debug_logging: bool = False) -> None:
        if not (isinstance(step_size, (int, float)) and math.isfinite(step_size)
                and step_size > 0.0):
            raise ValueError(f"step_size must be a positive number of seconds, got {step_size!r}")
        self._stepped_inputs = tuple(inputs)
        super().__init__(fmu_path, interface=interface, output_names=tuple(outputs),
                         debug_logging=debug_logging)
        md = self.model_description
        self.stepped_input_names = self._stepped_inputs
        self.parameters = self._coerce(self._checked_parameters(parameters or {}))
        self.step_size = float(step_size)
        if solver_tolerance is None and md.defaultExperiment is not None:
            solver_tolerance = md.defaultExperiment.tolerance
        if solver_tolerance is None and interface == "ME":
            solver_tolerance = DEFAULT_ME_TOLERANCE
        self.solver_tolerance = None if solver_tolerance is None else float(solver_tolerance)
        self.calls = 0
        self._states: list[Any] = []
        self._initialised = False
        self._set_stop_time = _set_stop_time_function() if interface == "ME" else None

    def _checked_parameters(self, parameters: Mapping[str, Any]) -> dict[str, Any]:
        check_names(list(parameters), list(self.variables), "variable",
                    self.model_description.modelName)
        return dict(parameters)

    # --- instance -----------------------------------------------------------------------------

    def _instantiate(self) -> None:
        check_names(self._stepped_inputs, self.input_names, "input",
                    self.model_description.modelName)
        super()._instantiate()
        self._in = _RawFloats(self._fmu, self.fmi3, self._references(self._stepped_inputs))
        self._out = _RawFloats(self._fmu, self.fmi3, self._references(self.output_names))
        fmu = self._fmu
        self._component = fmu.component
        if self.interface == "ME":
            self._do_step_raw = None
        elif self.fmi3:
            self._do_step_raw = fmu._functions["fmi3DoStep"]
            self._flags = tuple(ctypes.c_bool() for _ in range(3))
            self._last_time = ctypes.c_double()
            self._flag_refs = tuple(ctypes.byref(f) for f in self._flags) + (
                ctypes.byref(self._last_time),)
        else:
            self._do_step_raw = fmu._functions["fmi2DoStep"]
        self._step_solver: Any = None  # CVODE for ME, one per instance (fmpy's is not freed fully)
        self._states = []
        self._initialised = False

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickle as "a fresh, uninitialised stepper on the same FMU" (for process pools)."""
        return (_reopen_stepper, (str(self.fmu_path.resolve()), self.step_size,
                                  self._stepped_inputs, self.output_names, self.interface,
                                  dict(self.parameters), self.solver_tolerance))

    def __repr__(self) -> str:
        return (f"FmuStepper({str(self.fmu_path)!r}, step_size={self.step_size:g}, "
                f"interface={self.interface!r}, FMI {self.model_description.fmiVersion})")

    @property
    def time(self) -> float:
        """Current communication point (s)."""
        return self._time

    @property
    def can_get_and_set_state(self) -> bool:
        """Whether the FMU declares ``canGetAndSetFMUstate`` for the chosen interface."""
        md = self.model_description
        kind = md.coSimulation if self.interface == "CS" else md.modelExchange
        return bool(getattr(kind, "canGetAndSetFMUstate", False)
                    or getattr(kind, "canGetAndSetFMUState", False))

    # --- running ------------------------------------------------------------------------------

    def _input_vector(self, inputs: Mapping[str, float] | Sequence[float] | np.ndarray
                      ) -> np.ndarray:
        if isinstance(inputs, Mapping):
            check_names(list(inputs), self._stepped_inputs, "stepped input",
                        self.model_description.modelName)
            missing = [name for name in self._stepped_inputs if name not in inputs]
            if missing:
                raise ValueError(f"initialise: no value for input(s) {missing}")
            values = np.array([float(inputs[name]) for name in self._stepped_inputs])
        else:
            values = np.asarray(inputs, dtype=float).reshape(-1)
            if values.size != len(self._stepped_inputs):
                raise ValueError(f"expected {len(self._stepped_inputs)} input value(s) "
                                 f"{list(self._stepped_inputs)}, got {values.size}")
        if not np.all(np.isfinite(values)):
            raise ValueError(f"inputs must be finite, got {values.tolist()}")
        return values

    def initialise(self, inputs: Mapping[str, float] | Sequence[float] | np.ndarray,
                   start_time: float = 0.0) -> np.ndarray:
        """Set parameters and inputs, initialise the FMU at `start_time`, return the outputs.

        The instance is reset first if it has run before. The inputs are set in Initialization
        Mode, so an FMU that starts in static equilibrium (the project's, with
        ``start_in_equilibrium``) starts in equilibrium with them.

        Parameters
        ----------
        inputs : mapping of str to float, or array_like
            Values of the stepped inputs (by name, or in the order of `inputs`).
        start_time : float, optional
            Start time (s).

        Returns
        -------
        numpy.ndarray
            The outputs at `start_time` (a copy).
        """
        values = self._input_vector(inputs)
        self._free_states()
        self._prepare_instance()
        self._needs_reset = True
        self._time = float(start_time)
        self.calls = 0
        with self._fmi_errors():
            self._set_values(self.parameters)
            fmu, tolerance = self._fmu, self.solver_tolerance
            if self.fmi3:
                fmu.enterInitializationMode(tolerance=tolerance, startTime=self._time)
            else:
                fmu.setupExperiment(tolerance=tolerance, startTime=self._time)
                fmu.enterInitializationMode()
            self._in.set(values)
            fmu.exitInitializationMode()
            if self.interface == "ME":
                self._next_event = self._update_discrete_states()
                fmu.enterContinuousTimeMode()
                if self._step_solver is None:
                    self._step_solver = self._make_solver()
                else:
                    self._step_solver.restart(self._time, self.step_size)
            outputs = self._out.get().copy()
        self._initialised = True
        return outputs

    def set_inputs(self, inputs: Sequence[float] | np.ndarray) -> None:
        """Set the stepped inputs without advancing (e.g. to read a feed-through output)."""
        self._require_initialised()
        with self._fmi_errors():
            self._in.set(inputs)

    def outputs(self) -> np.ndarray:
        """The outputs at the current time and inputs (a copy)."""
        self._require_initialised()
        with self._fmi_errors():
            return self._out.get().copy()

    def step(self, inputs: Sequence[float] | np.ndarray,
             step_size: float | None = None) -> np.ndarray:
        """Set the inputs, advance one communication step, return the outputs at its end.

        Parameters
        ----------
        inputs : array_like
            Values of the stepped inputs, in the order of `inputs`, held over the step.
        step_size : float, optional
            This step's size (default: :attr:`step_size`).

        Returns
        -------
        numpy.ndarray
            The outputs at ``time + step_size`` (a copy).
        """
        if not self._initialised:
            self._require_initialised()
        h = self.step_size if step_size is None else step_size
        try:
            self._in.set(inputs)
            if self.interface == "CS":
                self._do_step(h)
            else:
                self._integrate(h)
            self._time += h
            self.calls += 1
            return self._out.get().copy()
        except FMICallException as error:
            raise self._simulation_error(error) from error
        except SimulationError:
            raise
        except Exception as error:  # CVODE failures
            raise SimulationError(f"{self.model_description.modelName} ({self.interface}): "
                                  f"{error} at t = {self._time:g} s", time=self._time,
                                  messages=self._log.messages) from error

    def _do_step(self, h: float) -> None:
        if self.fmi3:
            status = self._do_step_raw(self._component, self._time, h, True, *self._flag_refs)
            if status <= _OK_OR_WARNING and self._flags[1].value:
                raise self._termination(self._last_time.value)
        else:
            status = self._do_step_raw(self._component, self._time, h, 1)
        if status > _OK_OR_WARNING:
            raise FMICallException("fmi3DoStep" if self.fmi3 else "fmi2DoStep", status)

    def _make_solver(self) -> Any:
        fmu, md = self._fmu, self.model_description
        solver = make_cvode_solver(
            nx=md.numberOfContinuousStates, nz=md.numberOfEventIndicators,
            get_x=fmu.getContinuousStates, set_x=fmu.setContinuousStates,
            get_dx=fmu.getContinuousStateDerivatives if self.fmi3 else fmu.getDerivatives,
            get_z=fmu.getEventIndicators, get_nominals=fmu.getNominalsOfContinuousStates,
            set_time=fmu.setTime, startTime=self._time, maxStep=self.step_size,
            relativeTolerance=self.solver_tolerance)
        return solver

    def _integrate(self, h: float) -> None:
        """CVODE from the current time to ``time + h`` with the inputs held (see module notes)."""
        solver = self._step_solver
        solver.restart(self._time, h)
        stop_time = self._set_stop_time
        self._advance_me(solver, self._time, self._time + h, self._fmu.setTime,
                         None if stop_time is None
                         else lambda target: stop_time(solver.cvode_mem, target))

    def simulate(self, *args: Any, **kwargs: Any) -> Any:
        """A whole run as :meth:`FmuSimulator.simulate`; the stepping must be initialised anew."""
        self._free_states()
        self._initialised = False
        return super().simulate(*args, **kwargs)

    # --- FMU state ----------------------------------------------------------------------------

    def get_state(self) -> StepperState:
        """Save the FMU state (and the time and inputs) to come back to with :meth:`set_state`.

        Raises
        ------
        RuntimeError
            If the FMU does not support getting and setting its state.
        """
        self._require_initialised()
        if not self.can_get_and_set_state:
            raise RuntimeError(f"{self.model_description.modelName} cannot get/set its FMU "
                               f"state (canGetAndSetFMUstate is false)")
        with self._fmi_errors():
            handle = self._fmu.getFMUState()
        self._states.append(handle)
        return StepperState(handle, self._time, tuple(self._in._values.tolist()))

    def set_state(self, state: StepperState) -> None:
        """Go back to a state saved by :meth:`get_state` of this stepper."""
        self._require_initialised()
        if not any(state.handle is handle for handle in self._states):
            raise ValueError("this state does not belong to this stepper (or was freed)")
        with self._fmi_errors():
            self._fmu.setFMUState(state.handle)
            self._in.set(np.array(state.inputs))
        self._time = state.time
        if self.interface == "ME":
            self._step_solver.reset(self._time)

    def free_state(self, state: StepperState) -> None:
        """Release a saved state."""
        for i, handle in enumerate(self._states):
            if handle is state.handle:
                del self._states[i]
                with self._fmi_errors():
                    self._fmu.freeFMUState(handle)
                return

    def _free_states(self) -> None:
        states, self._states = self._states, []
        if self._fmu is not None:
            for handle in states:
                try:
                    self._fmu.freeFMUState(handle)
                except Exception:  # the instance may be in an error state; it goes anyway
                    pass

    # --- life cycle ---------------------------------------------------------------------------

    def reset(self) -> None:
        """Reset the instance (``fmi2Reset``/``fmi3Reset``); call :meth:`initialise` next."""
        self._free_states()
        self._initialised = False
        self._time = float("nan")
        self._prepare_instance()

    def close(self) -> None:
        """Free saved states and the instance and remove the extracted files (idempotent)."""
        self._free_states()
        self._initialised = False
        super().close()

    def __enter__(self) -> "FmuStepper":
        return self

    # --- errors -------------------------------------------------------------------------------

    def _require_initialised(self) -> None:
        if self._closed:
            raise RuntimeError(f"{self.model_description.modelName}: the stepper is closed")
        if not self._initialised:
            raise RuntimeError(f"{self.model_description.modelName}: call initialise() first")

    def _simulation_error(self, error: FMICallException) -> SimulationError:
        if error.status >= _FATAL:
            self._free_instance()
            self._initialised = False
        return SimulationError.from_call(error, model=self.model_description.modelName,
                                         interface=self.interface, time=self._time,
                                         messages=self._log.messages)

    @contextlib.contextmanager
    def _fmi_errors(self) -> Iterator[None]:
        """Turn fmpy's FMICallException into a SimulationError carrying the FMU's log."""
        try:
            yield
        except FMICallException as error:
            raise self._simulation_error(error) from error


def _reopen_stepper(fmu_path: str, step_size: float, inputs: Sequence[str],
                    outputs: Sequence[str], interface: str, parameters: dict[str, Any],
                    solver_tolerance: float | None) -> FmuStepper:
    return FmuStepper(fmu_path, step_size=step_size, inputs=inputs, outputs=outputs,
                      interface=interface, parameters=parameters,
                      solver_tolerance=solver_tolerance)


__all__ = ["FmuStepper", "StepperState", "SimulationError", "INTERFACES"]
