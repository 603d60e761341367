"""FMI plumbing under :mod:`panto.build_fmu.simulate`: log collection, batched float get/set,
piecewise-linear inputs and fmpy's CVODE solver made to report a failing FMU call.

None of it knows about a particular model; :class:`panto.build_fmu.simulate.FmuSimulator` puts it
together.
"""
from __future__ import annotations

import bisect
import ctypes
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

STATUS_LABELS = ("OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING")


class LogCollector:
    """Keeps the last log messages an FMU sends through its logger callback."""

    def __init__(self, length: int = 200) -> None:
        self.messages: deque[str] = deque(maxlen=length)

    @staticmethod
    def _text(value: Any) -> str:
        return value.decode("utf-8", "replace") if isinstance(value, bytes) else str(value or "")

    def add(self, status: int, category: Any, message: Any) -> None:
        label = STATUS_LABELS[status] if 0 <= status < len(STATUS_LABELS) else str(status)
        category = self._text(category)
        self.messages.append(f"[{label}]{f' {category}:' if category else ''} "
                             f"{self._text(message)}")

    def fmi2_logger(self, environment, instance_name, status, category, message) -> None:
        self.add(status, category, message)

    def fmi3_logger(self, environment, status, category, message) -> None:
        self.add(status, category, message)


class FloatChannel:
    """Batched get/set of Real (FMI 2) / Float64 (FMI 3) variables with preallocated buffers."""

    def __init__(self, fmu: Any, fmi3: bool, references: Sequence[int]) -> None:
        self.size = len(references)
        self._references = (ctypes.c_uint32 * self.size)(*references)
        self._buffer = (ctypes.c_double * self.size)()
        self._values = np.ctypeslib.as_array(self._buffer) if self.size else np.zeros(0)
        self._fmu, self._fmi3 = fmu, fmi3

    def get(self) -> np.ndarray:
        """Current values (a view of the buffer, overwritten by the next call)."""
        if self.size:
            if self._fmi3:
                self._fmu.fmi3GetFloat64(self._fmu.component, self._references, self.size,
                                         self._buffer, self.size)
            else:
                self._fmu.fmi2GetReal(self._fmu.component, self._references, self.size,
                                      self._buffer)
        return self._values

    def set(self, values: np.ndarray) -> None:
        if self.size:
            self._values[:] = values
            if self._fmi3:
                self._fmu.fmi3SetFloat64(self._fmu.component, self._references, self.size,
                                         self._buffer, self.size)
            else:
                self._fmu.fmi2SetReal(self._fmu.component, self._references, self.size,
                                      self._buffer)


@dataclass(frozen=True)
class PiecewiseLinearInputs:
    """Input samples ``values[k, j]`` of input ``j`` at ``time[k]``, linear in between.

    Outside ``[time[0], time[-1]]`` the end values are held.
    """

    time: np.ndarray
    values: np.ndarray

    def __post_init__(self) -> None:
        # per-segment slopes and a Python list of times: u(t) costs one bisect and one axpy
        slopes = np.diff(self.values, axis=0) / np.diff(self.time)[:, None]
        object.__setattr__(self, "_slopes", slopes)
        object.__setattr__(self, "_times", self.time.tolist())

    def at(self, t: float) -> np.ndarray:
        """Interpolated inputs :math:`u(t)` (end values held outside the sampled span)."""
        k = bisect.bisect_right(self._times, t) - 1
        if k < 0:
            return self.values[0]
        if k >= len(self._times) - 1:
            return self.values[-1]
        return self.values[k] + self._slopes[k] * (t - self._times[k])

    def integral(self, t: np.ndarray) -> np.ndarray:
        """:math:`\\int_{t_0}^{t} u\\,dt` for each point of `t` inside the sampled span."""
        time, values = self.time, self.values
        steps = np.diff(time)[:, None]
        cumulative = np.vstack([np.zeros((1, values.shape[1])),
                                np.cumsum(0.5 * steps * (values[1:] + values[:-1]), axis=0)])
        k = np.clip(np.searchsorted(time, t, side="right") - 1, 0, time.size - 2)
        offset = (t - time[k])[:, None]
        slope = (values[k + 1] - values[k]) / steps[k]
        return cumulative[k] + values[k] * offset + 0.5 * slope * offset**2

    def sample(self, t: np.ndarray) -> np.ndarray:
        """Interpolated inputs at each point of `t`, shape (len(t), n)."""
        return np.column_stack([np.interp(t, self.time, column) for column in self.values.T]) \
            if self.values.shape[1] else np.zeros((len(t), 0))

    def means(self, t: np.ndarray) -> np.ndarray:
        """Mean of :math:`u` over each interval ``[t[k], t[k+1]]``, shape (len(t) - 1, n)."""
        return np.diff(self.integral(t), axis=0) / np.diff(t)[:, None]


def make_cvode_solver(**options: Any) -> Any:
    """fmpy's CVODE wrapper, made to report a failing FMU call instead of losing it.

    One solver serves all the runs of an instance (:meth:`restart` re-initialises it): fmpy's
    solver does not free its vectors, matrix and linear solver, so one per run would leak.

    fmpy's right-hand-side and root callbacks let an exception escape into ctypes, which prints
    and drops it, and CVODE then fails with a generic message. Here the callbacks keep the
    exception and return -1 (unrecoverable), no further FMU call is made, and ``advance``
    re-raises it.
    """
    from fmpy.sundials import CVodeSetMaxStep, CVodeSolver

    class GuardedCVodeSolver(CVodeSolver):
        failure: BaseException | None = None

        def __init__(self, *, set_x: Any, **solver_options: Any) -> None:
            def set_states_unless_failed(x: Any, n: int) -> None:
                if self.failure is None:  # fmpy sets the states back even after a failure
                    set_x(x, n)

            super().__init__(set_x=set_states_unless_failed, **solver_options)

        def f(self, t, y, ydot, user_data):  # right-hand side
            try:
                return super().f(t, y, ydot, user_data)
            except Exception as error:
                self.failure = error
                return -1

        def g(self, t, y, gout, user_data):  # event indicators
            try:
                return super().g(t, y, gout, user_data)
            except Exception as error:
                self.failure = error
                return -1

        def restart(self, time: float, max_step: float) -> None:
            """Start a new run from the FMU's current states (``CVodeReInit``)."""
            self.failure = None
            self.reset(time)
            CVodeSetMaxStep(self.cvode_mem, max_step)

        def advance(self, t: float, stop: float) -> tuple[bool, float]:
            try:
                event, _, t = self.step(t, stop)
            except Exception:  # CVODE's error, or a later call refused in the Error state
                if self.failure is not None:
                    raise self.failure from None
                raise
            return event, t

    solver = GuardedCVodeSolver(input=_NO_INPUT_APPLIER, maxNumSteps=100_000, **options)
    _silence_sundials_printing(solver)
    return solver


class _NoInputApplier:
    """fmpy's solver applies inputs in its root function; ours are set with the time."""

    @staticmethod
    def apply(*args: Any, **kwargs: Any) -> None:
        pass


_NO_INPUT_APPLIER = _NoInputApplier()


def _silence_sundials_printing(solver: Any) -> None:
    """Keep only fmpy's error handler (which records the message) and drop SUNDIALS' printer."""
    try:
        from fmpy.sundials.sundials_context import SUNContext_PushErrHandler, sundials_core

        sundials_core.SUNContext_ClearErrHandlers(solver.sunctx)
        SUNContext_PushErrHandler(solver.sunctx, solver.ehfun_, None)
    except Exception:  # older/newer fmpy: printing is harmless, the error is still raised
        pass


__all__ = ["STATUS_LABELS", "LogCollector", "FloatChannel", "PiecewiseLinearInputs",
           "make_cvode_solver"]
