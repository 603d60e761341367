"""The co-simulation loop in C: an FMI 2.0 Co-Simulation FMU stepped along the compiled catenary.

The master's loop (`panto.catenary_cosim.master`) does, per communication step, three FMI calls
(``fmi2SetReal``, ``fmi2DoStep``, ``fmi2GetReal``), one or more catenary steps and a handful of
records. Run from Python, through fmpy's ctypes functions, the calls and the bookkeeping cost
about as much as the arithmetic itself. This module runs the same loop in C: ``cosim_run``
calls the FMU's own ``fmi2SetReal``/``fmi2DoStep``/``fmi2GetReal`` through their addresses in
the FMU's shared library (the instance fmpy created and initialised), steps the catenary with
``catenary_advance`` of `panto.catenary_cosim.kernel` (the same C step the Python loop calls)
and writes the records into the master's arrays. Every operation is the Python loop's, in the
same order and in the same floating-point arithmetic, so both loops give the same run
(tests/test_cosim_master.py compares them).

Used when the FMU is FMI 2.0 driven as Co-Simulation and the catenary has its compiled step;
otherwise (Model Exchange, FMI 3.0, a user's catenary, no C compiler,
``PANTO_CATENARY_KERNEL=0``) the master keeps its Python loop. The library is built from
:data:`panto.catenary_cosim.kernel.C_SOURCE` and :data:`LOOP_SOURCE` like the kernel (cached by
the source's hash).
"""
from __future__ import annotations

import ctypes
from collections.abc import Callable
from functools import lru_cache
from typing import Any

import numpy as np

from panto.catenary_cosim import kernel

LOOP_SOURCE = r"""
/* ---- the co-simulation loop (panto.catenary_cosim.coupling_kernel) ---- */
#include <stddef.h>
#include <time.h>

typedef int (*fmi2_set_real_t)(void *, const unsigned int *, size_t, const double *);
typedef int (*fmi2_get_real_t)(void *, const unsigned int *, size_t, double *);
typedef int (*fmi2_do_step_t)(void *, double, double, int);

typedef struct {
    void *component, *set_real, *get_real, *do_step;
    const unsigned int *input_references, *output_references;
    long inputs_count, outputs_count, substeps, has_head, supports;
    double *inputs, *outputs;
    const long *support_unknown;
    double time, step, dt, start, stop, speed, offset, x;
    double *position, *force, *wire, *head, *uplift;
    double fmu_seconds, catenary_seconds;
    long failed_call, failed_status;
} coupling_state;

static double monotonic_seconds(void)
{
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    return (double)now.tv_sec + 1e-9 * (double)now.tv_nsec;
}

/* Communication steps first..last (master._run's loop body). Returns last + 1, or the step at
   which a call failed (failed_call: 1 fmi2SetReal, 2 fmi2DoStep, 3 fmi2GetReal, 4 catenary). */
long cosim_run(catenary_state *c, coupling_state *p, long first, long last)
{
    fmi2_set_real_t set_real = (fmi2_set_real_t)p->set_real;
    fmi2_get_real_t get_real = (fmi2_get_real_t)p->get_real;
    fmi2_do_step_t do_step = (fmi2_do_step_t)p->do_step;
    long n, j, k;
    for (n = first; n <= last; n++) {
        double t0 = monotonic_seconds(), t1, t2, force, wire, x = p->x;
        int status = set_real(p->component, p->input_references, (size_t)p->inputs_count,
                              p->inputs);
        if (status > 1) { p->failed_call = 1; p->failed_status = status; return n; }
        status = do_step(p->component, p->time, p->step, 1);
        if (status > 1) { p->failed_call = 2; p->failed_status = status; return n; }
        p->time += p->step;
        status = get_real(p->component, p->output_references, (size_t)p->outputs_count,
                          p->outputs);
        if (status > 1) { p->failed_call = 3; p->failed_status = status; return n; }
        t1 = monotonic_seconds();
        force = p->outputs[0] > 0.0 ? p->outputs[0] : 0.0;
        for (j = 1; j <= p->substeps; j++) {
            double at = x + p->speed * p->dt * (double)j;
            status = catenary_advance(c, force, at < p->stop ? at : p->stop);
            if (status) { p->failed_call = 4; p->failed_status = status; return n; }
        }
        x = p->start + p->speed * p->dt * (double)p->substeps * (double)n;
        if (x > p->stop) x = p->stop;
        wire = catenary_height(c, x);
        t2 = monotonic_seconds();
        p->fmu_seconds += t1 - t0;
        p->catenary_seconds += t2 - t1;
        p->inputs[0] = wire + p->offset;
        p->x = x;
        p->position[n] = x;
        p->force[n] = force;
        p->wire[n] = wire;
        p->head[n] = p->has_head ? p->outputs[1] - p->offset : NAN;
        for (k = 0; k < p->supports; k++) {
            long i = p->support_unknown[k];
            p->uplift[n * p->supports + k] = i >= 0 ? c->u[i] : 0.0;
        }
    }
    return last + 1;
}
"""

_CALLS = {1: "fmi2SetReal", 2: "fmi2DoStep", 3: "fmi2GetReal"}


class CouplingState(ctypes.Structure):
    """``coupling_state`` of :data:`LOOP_SOURCE`: the FMU's instance, functions and value
    references, the run's constants, the record arrays and the clocks [s]."""

    _fields_ = ([(name, ctypes.c_void_p) for name in (
                    "component", "set_real", "get_real", "do_step", "input_references",
                    "output_references")]
                + [(name, ctypes.c_long) for name in (
                    "inputs_count", "outputs_count", "substeps", "has_head", "supports")]
                + [(name, ctypes.c_void_p) for name in ("inputs", "outputs", "support_unknown")]
                + [(name, ctypes.c_double) for name in (
                    "time", "step", "dt", "start", "stop", "speed", "offset", "x")]
                + [(name, ctypes.c_void_p) for name in (
                    "position", "force", "wire", "head", "uplift")]
                + [(name, ctypes.c_double) for name in ("fmu_seconds", "catenary_seconds")]
                + [(name, ctypes.c_long) for name in ("failed_call", "failed_status")])


@lru_cache(maxsize=1)
def load_library() -> ctypes.CDLL | None:
    """The compiled loop (catenary step included), or None if it cannot be built."""
    library = kernel.build_library(kernel.C_SOURCE + LOOP_SOURCE, "cosim_loop")
    if library is None:
        return None
    kernel.declare_step_functions(library)
    library.cosim_run.restype = ctypes.c_long
    library.cosim_run.argtypes = [ctypes.POINTER(kernel.CatenaryState),
                                  ctypes.POINTER(CouplingState), ctypes.c_long, ctypes.c_long]
    return library


def fmi2_handles(stepper: Any) -> dict[str, Any] | None:
    """The raw FMI 2.0 Co-Simulation handles of an initialised
    :class:`panto.build_fmu.stepping.FmuStepper`, or None (Model Exchange, FMI 3.0, another
    stepper).

    Returns
    -------
    dict or None
        ``component``, the addresses of ``set_real``, ``get_real`` and ``do_step``, and the
        value references (ctypes arrays) of the stepped ``inputs`` and the ``outputs``.
    """
    if getattr(stepper, "interface", None) != "CS" or getattr(stepper, "fmi3", True):
        return None
    try:  # the stepper's own raw ctypes functions (its hot path), not a second loading
        functions = {"set_real": stepper._in._set, "get_real": stepper._out._get,
                     "do_step": stepper._do_step_raw}
        handles = {name: ctypes.cast(function, ctypes.c_void_p).value
                   for name, function in functions.items()}
        component = stepper._component
        handles["component"] = getattr(component, "value", component)
        handles["inputs"], handles["outputs"] = stepper._in._references, stepper._out._references
        handles["start_time"] = float(stepper.time)
    except (AttributeError, TypeError, ctypes.ArgumentError):
        return None
    return handles if all(handles[name] for name in ("set_real", "get_real", "do_step",
                                                     "component")) else None


def compiled_loop_available(catenary: Any, stepper: Any) -> bool:
    """Whether :func:`run_loop` can run this catenary and stepper."""
    return (getattr(catenary, "compiled_state", None) is not None
            and fmi2_handles(stepper) is not None and load_library() is not None)


def run_loop(catenary: Any, stepper: Any, inputs: np.ndarray, record: dict[str, np.ndarray], *,
             offset: float, start: float, stop: float, speed: float, substeps: int,
             has_head: bool, report: Callable[[int, float, float], None] | None = None,
             report_every: int = 0) -> tuple[float, float]:
    """Communication steps 1 .. len(record) - 1 of the master's loop, in C.

    Parameters
    ----------
    catenary : Catenary
        With its compiled step (``compiled_state``); its time and step count are advanced.
    stepper : FmuStepper
        Initialised, FMI 2.0, Co-Simulation; its time and call count are advanced.
    inputs : numpy.ndarray
        The stepped inputs (height first), updated in place.
    record : dict of numpy.ndarray
        ``position``, ``force``, ``wire``, ``head`` [m, N, m, m] and ``uplift`` (steps + 1,
        supports) [m], row 0 already written; rows 1.. are filled.
    offset, start, stop, speed, substeps, has_head
        As in the master's loop (m, m, m, m/s).
    report : callable, optional
        Called with (step, x [m], force [N]) every `report_every` steps.

    Returns
    -------
    (float, float)
        Wall seconds in the FMU calls and in the catenary steps.
    """
    library, handles = load_library(), fmi2_handles(stepper)
    if library is None or handles is None:
        raise RuntimeError("the compiled co-simulation loop is not available")
    steps = record["force"].size - 1
    nodes, elements = np.asarray(catenary.mesh.support_nodes), catenary.mesh.elements
    keep = {"inputs": np.ascontiguousarray(inputs, dtype=float),
            "outputs": np.zeros(len(stepper.output_names)),
            "support_unknown": np.where((nodes > 0) & (nodes < elements), 2 * (nodes - 1),
                                        -1).astype(np.int64)}
    for name in ("position", "force", "wire", "head", "uplift"):
        if not (record[name].flags.c_contiguous and record[name].dtype == np.float64):
            raise ValueError(f"record {name!r} must be a contiguous float64 array")
    state = CouplingState(
        component=handles["component"], set_real=handles["set_real"],
        get_real=handles["get_real"], do_step=handles["do_step"],
        input_references=ctypes.addressof(handles["inputs"]),
        output_references=ctypes.addressof(handles["outputs"]),
        inputs_count=len(handles["inputs"]), outputs_count=len(handles["outputs"]),
        substeps=substeps, has_head=int(has_head), supports=len(nodes),
        time=handles["start_time"], step=stepper.step_size, dt=catenary.time_step,
        start=start, stop=stop, speed=speed, offset=offset, x=start,
        **{name: array.ctypes.data for name, array in keep.items()},
        **{name: record[name].ctypes.data for name in ("position", "force", "wire", "head",
                                                         "uplift")})
    first, chunk = 1, report_every if report_every > 0 else steps
    pointer = ctypes.byref(catenary.compiled_state)
    while first <= steps:
        last = min(steps, first + chunk - 1)
        done = library.cosim_run(pointer, ctypes.byref(state), first, last)
        _account(catenary, stepper, state, done - first)
        if done <= last:
            _raise_failure(stepper, state)
        if report is not None:
            report(last, state.x, float(record["force"][last]))
        first = last + 1
    inputs[:] = keep["inputs"]
    return state.fmu_seconds, state.catenary_seconds


def _account(catenary: Any, stepper: Any, state: CouplingState, steps: int) -> None:
    """Advance the catenary's and the stepper's clocks and counters over `steps` steps."""
    catenary.count_compiled_steps(steps * state.substeps)
    stepper._time = state.time
    stepper.calls += steps


def _raise_failure(stepper: Any, state: CouplingState) -> None:
    """Raise what the Python loop raises for the failed call."""
    if state.failed_call == 4:
        from panto.catenary_cosim.integration import check_status

        check_status(int(state.failed_status))
    from fmpy.fmi1 import FMICallException

    error = FMICallException(_CALLS[int(state.failed_call)], int(state.failed_status))
    raise stepper._simulation_error(error) from error


__all__ = ["LOOP_SOURCE", "CouplingState", "load_library", "fmi2_handles",
           "compiled_loop_available", "run_loop"]
