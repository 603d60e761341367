"""Cross-check built FMUs outside fmpy: an independent importer and an independent checker.

fmpy is the project's importer and validator. To catch faults that fmpy tolerates, every
Co-Simulation FMU is also

* run by an independent co-simulation engine installable from PyPI
  (:func:`simulate_in_independent_importer`):

  ========== ============ ============ ==========================================
  importer   FMI 2.0 CS   FMI 3.0 CS   notes
  ========== ============ ============ ==========================================
  ecospy     yes          yes          needs ``libtbb.so.12``: PyPI package
                                       ``tbb`` (preloaded here) or Debian
                                       ``libtbb12``; ignores FMU error statuses,
                                       which are found in its debug log instead
  libcosimpy yes          no           aborts the process when the FMU returns
                                       an error, and crashes on FMI 3.0
  ========== ============ ============ ==========================================

  Neither runs Model Exchange: :mod:`panto.build_fmu.crosscheck_me` does, in the FMU
  Manipulation Toolbox's container. Because both can kill the process that loads them, each run
  happens in a child Python process (this file alone, not the package); the importer's messages
  about errors and warnings are passed on to this module's logger. Inputs are constant or vary
  from one communication step to the next.

* checked by the FMU Manipulation Toolbox (:func:`check_fmu_with_toolbox`): XSD schema of
  ``modelDescription.xml`` and the semantic rules the schema cannot express (causality,
  variability, ``initial``, start values, model structure). It does not look at the binaries.
"""
from __future__ import annotations

import ctypes
import dataclasses
import importlib
import importlib.metadata
import json
import logging
import math
import os
import re
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Literal

import numpy as np

if TYPE_CHECKING:
    from fmpy.model_description import ModelDescription

LOGGER = logging.getLogger(__name__)

Importer = Literal["ecospy", "libcosimpy"]

INSTANCE_NAME = "model"
"""Name of the FMU instance inside the independent importers."""

TOOLBOX_LOGGER = "fmu_manipulation_toolbox"
"""Logger on which the toolbox's checkers report the problems they find."""

_FMU_ERROR = re.compile(r"\bfmi[23](Error|Fatal)\b|\] (Error|Fatal) |FMI status=(error|fatal)")
"""An importer's log line saying that the FMU returned an error status (ecos FMI 2, ecos FMI 3,
libcosim)."""
_NOTEWORTHY = re.compile(r"\b(error|warning|fatal)\b|terminate called|abort", re.IGNORECASE)
"""An importer's log line passed on to :data:`LOGGER`."""
_LOG_PREFIX = re.compile(r"^\[\d{4}-\d\d-\d\d [^\]]*\]\s*(\[0x[0-9a-f]+\]\s*)?")
"""The time stamp (and thread id) that starts an ecos or libcosim log line."""


class CrosscheckError(Exception):
    """Base class of the errors raised while cross-checking an FMU."""


class ImporterUnavailableError(CrosscheckError):
    """The independent importer cannot be loaded on this machine."""


class UnsupportedFmuError(CrosscheckError):
    """The independent importer cannot handle this kind of FMU (FMI version, interface)."""


class UnknownVariableError(CrosscheckError, ValueError):
    """A variable name is not in the FMU, or has the wrong causality or type."""


class ImporterRunError(CrosscheckError):
    """The independent importer failed, or the FMU returned an error status in it."""


@dataclasses.dataclass(frozen=True)
class _Request:
    """One run, as handed to the child process (JSON)."""

    importer: str
    fmu_path: str
    steps: int
    step_size: float
    start_values: dict[str, float | int | bool]
    outputs: list[str]
    input_series: dict[str, list[float]] = dataclasses.field(default_factory=dict)
    """Values of time-varying inputs, one per communication step (held over the step)."""


def simulate_in_independent_importer(
    fmu_path: str | os.PathLike,
    *,
    stop_time: float,
    step_size: float,
    outputs: Sequence[str],
    inputs: Mapping[str, float | Sequence[float]] | None = None,
    parameters: Mapping[str, float] | None = None,
    importer: Importer = "ecospy",
) -> dict[str, np.ndarray]:
    """Run an FMU's Co-Simulation interface in an importer independent of fmpy.

    The FMU is simulated from 0 to `stop_time` with fixed communication steps. An input given
    as a number is held constant; one given as a sequence is sampled at the communication
    points and held over each step (as fmpy does for an FMU that cannot interpolate inputs:
    the value at ``t_k`` is set before the step from ``t_k``; the output recorded at ``t_k+1``
    is read after it, before the next value is set). The run happens in a child process.

    Parameters
    ----------
    fmu_path : str or os.PathLike
        The ``.fmu`` file.
    stop_time : float
        End of the simulation in s; an integer multiple of `step_size`.
    step_size : float
        Communication step in s.
    outputs : sequence of str
        Names of the Real (FMI 2.0) / Float64 (FMI 3.0) variables to record.
    inputs : mapping of str to float or sequence of float, optional
        Values of input variables: a constant, or ``stop_time / step_size + 1`` samples at the
        communication points ``0, h, ..., stop_time`` (the first is also the start value
        used at initialisation; the last enters no step).
    parameters : mapping of str to float, optional
        Values of parameters (Boolean and Integer parameters are converted).
    importer : {"ecospy", "libcosimpy"}
        The engine. ``"ecospy"`` handles FMI 2.0 and 3.0; ``"libcosimpy"`` FMI 2.0 only.

    Returns
    -------
    dict of str to numpy.ndarray
        ``"time"`` (the communication points ``0, h, ..., stop_time``) and one array per
        output, sampled at those points.

    Raises
    ------
    UnsupportedFmuError
        If the FMU has no Co-Simulation interface or the importer cannot handle its FMI
        version.
    UnknownVariableError
        If an input, parameter or output is not a variable of that kind in the FMU.
    ImporterUnavailableError
        If the importer's native library cannot be loaded.
    ImporterRunError
        If the importer fails, or the FMU returns an error status (e.g. refuses a value).
    """
    path = Path(fmu_path)
    if importer not in _SIMULATORS:
        raise ValueError(f"importer={importer!r} is not one of {sorted(_SIMULATORS)}")
    description = _read_co_simulation_description(path)
    if importer == "libcosimpy" and description.fmiVersion != "2.0":
        raise UnsupportedFmuError(f"libcosimpy handles FMI 1.0 and 2.0 only; '{path}' is FMI "
                                  f"{description.fmiVersion}")
    steps = _count_steps(stop_time, step_size)
    series = _input_series(inputs or {}, steps)
    initial = {name: values[0] if name in series else values
               for name, values in (inputs or {}).items()}
    start_values = {
        **_convert_start_values(path, description, initial, ("input",)),
        **_convert_start_values(path, description, parameters or {}, ("parameter",)),
    }
    _check_outputs(path, description, outputs)
    request = _Request(importer, str(path.resolve()), steps, step_size, start_values,
                       list(outputs), series)
    return _run_in_child_process(request)


def check_fmu_with_toolbox(fmu_path: str | os.PathLike) -> list[str]:
    """Check an FMU with the FMU Manipulation Toolbox's checkers (as ``fmutool -check``).

    Runs every registered checker: the XSD validation of ``modelDescription.xml`` against the
    FMI 2.0 or 3.0 schema and the semantic checks of the standard's rules.

    Parameters
    ----------
    fmu_path : str or os.PathLike
        The ``.fmu`` file.

    Returns
    -------
    list of str
        The problems reported, verbatim; an empty list means the FMU is accepted.

    Raises
    ------
    FileNotFoundError
        If `fmu_path` is not a file.
    """
    path = Path(fmu_path)
    if not path.is_file():
        raise FileNotFoundError(f"No FMU file at '{path}'")
    from fmu_manipulation_toolbox.checker import get_checkers
    from fmu_manipulation_toolbox.operations import FMU, FMUError

    collector = _ErrorCollector()
    logger = logging.getLogger(TOOLBOX_LOGGER)
    logger.addHandler(collector)
    try:
        with FMU(str(path)) as fmu:
            for checker in get_checkers():
                fmu.apply_operation(checker())
    except FMUError as error:  # not a ZIP archive, no or unreadable modelDescription.xml
        collector.messages.append(str(error))
    finally:
        logger.removeHandler(collector)
    return collector.messages


class _ErrorCollector(logging.Handler):
    """Keep the messages of the records of level ERROR and above."""

    def __init__(self) -> None:
        super().__init__(level=logging.ERROR)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


# ----------------------------------------------------------------------------- input checks
def _read_co_simulation_description(path: Path) -> ModelDescription:
    from fmpy import read_model_description

    if not path.is_file():
        raise FileNotFoundError(f"No FMU file at '{path}'")
    description = read_model_description(str(path), validate=False)
    if description.coSimulation is None:
        raise UnsupportedFmuError(f"'{path}' has no Co-Simulation interface")
    return description


def _count_steps(stop_time: float, step_size: float) -> int:
    if not (step_size > 0 and stop_time > 0):
        raise ValueError(f"stop_time={stop_time} and step_size={step_size} must be positive")
    steps = round(stop_time / step_size)
    if not math.isclose(steps * step_size, stop_time, rel_tol=1e-9):
        raise ValueError(f"stop_time={stop_time} is not a multiple of step_size={step_size}")
    return steps


def _input_series(inputs: Mapping[str, float | Sequence[float]],
                  steps: int) -> dict[str, list[float]]:
    """The time-varying inputs' samples at the communication points, checked."""
    series = {}
    for name, values in inputs.items():
        if np.ndim(values) == 0:
            continue
        samples = np.asarray(values, dtype=float)
        if samples.shape != (steps + 1,) or not np.all(np.isfinite(samples)):
            raise ValueError(f"input {name!r}: {steps + 1} finite samples expected (one per "
                             f"communication point), got shape {samples.shape}")
        series[name] = samples.tolist()
    return series


def _convert_start_values(path: Path, description: ModelDescription, values: Mapping[str, float],
                          causalities: tuple[str, ...]) -> dict[str, float | int | bool]:
    """Check the names and give each value the Python type of its FMI variable."""
    variables = {variable.name: variable for variable in description.modelVariables}
    converted: dict[str, float | int | bool] = {}
    for name, value in values.items():
        variable = variables.get(name)
        if variable is None or variable.causality not in causalities:
            raise UnknownVariableError(f"'{path}' has no {' or '.join(causalities)} variable "
                                       f"named '{name}' (value {value})")
        if variable.type == "Boolean":
            converted[name] = bool(value)
        elif variable.type.startswith(("Int", "UInt", "Enumeration")):  # FMI 2 Integer too
            converted[name] = int(value)
        else:
            converted[name] = float(value)
    return converted


def _check_outputs(path: Path, description: ModelDescription, outputs: Sequence[str]) -> None:
    if not outputs:
        raise ValueError("outputs must name at least one variable")
    real_types = {"Real", "Float64", "Float32"}
    real_names = {variable.name for variable in description.modelVariables
                  if variable.type in real_types}
    unknown = [name for name in outputs if name not in real_names]
    if unknown:
        raise UnknownVariableError(f"'{path}' has no Real/Float variable(s) named {unknown}")


# ----------------------------------------------------------------------------- child process
def _run_in_child_process(request: _Request) -> dict[str, np.ndarray]:
    """Run `request` in a child Python process; raise what it raised, or its crash."""
    with tempfile.TemporaryDirectory(prefix="crosscheck_") as directory:
        files = [Path(directory) / name for name in ("request.json", "result.npz", "error.json")]
        files[0].write_text(json.dumps(dataclasses.asdict(request)), encoding="utf-8")
        completed = subprocess.run([sys.executable, "-c", _CHILD_CODE, __file__, *map(str, files)],
                                   capture_output=True, text=True)
        log = _summarise_log(completed.stdout + completed.stderr)
        for line in log:
            if _NOTEWORTHY.search(line) or _FMU_ERROR.search(line):
                LOGGER.warning("%s: %s", request.importer, line)
        _raise_child_failure(request, completed.returncode, log, files[1], files[2])
        with np.load(files[1]) as result:
            return {name: result[name] for name in result.files}


def _raise_child_failure(request: _Request, exit_code: int, log: list[str], result_file: Path,
                         error_file: Path) -> None:
    """Raise the error the child reported, or an :class:`ImporterRunError` if it failed.

    The FMU's own error messages are appended: libcosim reports the FMU's last log message,
    which need not be the cause.
    """
    fmu_errors = [line for line in log if _FMU_ERROR.search(line)][:5]
    if error_file.exists():
        error = json.loads(error_file.read_text(encoding="utf-8"))
        raise _ERRORS[error["type"]]("\n".join([error["message"], *fmu_errors]))
    if exit_code != 0 or fmu_errors or not result_file.exists():
        details = "\n".join(fmu_errors or log[-5:])
        raise ImporterRunError(f"{request.importer} failed on '{request.fmu_path}' "
                               f"(exit code {exit_code}):\n{details}")


def _summarise_log(text: str) -> list[str]:
    """The distinct lines of an importer's output without time stamps, repeats counted."""
    counts: dict[str, int] = {}
    for line in text.splitlines():
        line = _LOG_PREFIX.sub("", line).strip()
        if line:
            counts[line] = counts.get(line, 0) + 1
    return [line if count == 1 else f"{line} (x{count})" for line, count in counts.items()]


_CHILD_CODE = ("import importlib.util, sys; "
               "spec = importlib.util.spec_from_file_location('_crosscheck_child', sys.argv[1]); "
               "module = sys.modules[spec.name] = importlib.util.module_from_spec(spec); "
               "spec.loader.exec_module(module); module._serve_request()")
"""The child's program: this file loaded alone, not the package around it (whose imports would
cost every run about 0.4 s), then :func:`_serve_request`."""


def _serve_request() -> None:
    """Entry point of the child process: ``request.json result.npz error.json`` last in argv."""
    request_file, result_file, error_file = sys.argv[-3:]
    request = _Request(**json.loads(Path(request_file).read_text(encoding="utf-8")))
    try:
        result = _SIMULATORS[request.importer](request)
    except CrosscheckError as error:
        report = {"type": type(error).__name__, "message": str(error)}
        Path(error_file).write_text(json.dumps(report), encoding="utf-8")
        return
    np.savez(result_file, **result)


# ----------------------------------------------------------------------------- ecospy
def _load_ecospy() -> ModuleType:
    """Import ecospy, first loading the TBB library it links to from the PyPI package ``tbb``."""
    tbb_library = _find_pip_tbb_library()
    if tbb_library is not None:
        ctypes.CDLL(str(tbb_library), mode=ctypes.RTLD_GLOBAL)
    try:
        return importlib.import_module("ecospy")
    except OSError as error:
        raise ImporterUnavailableError(
            f"ecospy's native library cannot be loaded ({error}); install the PyPI package 'tbb' "
            "(pip install tbb) or the Debian package libtbb12") from error


def _find_pip_tbb_library() -> Path | None:
    if os.name == "nt":
        return None  # ecospy ships its Windows dependencies
    try:
        files = importlib.metadata.files("tbb") or []
    except importlib.metadata.PackageNotFoundError:
        return None
    for file in files:
        if file.name == "libtbb.so.12":
            return Path(file.locate()).resolve()
    return None


def _simulate_with_ecospy(request: _Request) -> dict[str, np.ndarray]:
    ecospy = _load_ecospy()
    ecospy.EcosLib.set_log_level("debug")  # the only place where ecos reports FMU error statuses
    rows = []
    with ecospy.EcosSimulationStructure() as structure:
        structure.add_model(INSTANCE_NAME, request.fmu_path)
        structure.add_parameter_set("start", {f"{INSTANCE_NAME}::{name}": value
                                              for name, value in request.start_values.items()})
        with ecospy.EcosSimulation(structure=structure, step_size=request.step_size) as simulation:
            if not simulation.init(parameter_set="start"):
                raise ImporterRunError(f"ecospy could not initialise '{request.fmu_path}': "
                                       f"{ecospy.EcosLib.get_last_error()}")
            _check_ecospy_start_values(simulation, request)
            identifiers = [f"{INSTANCE_NAME}::{name}" for name in request.outputs]
            for step in range(request.steps + 1):
                if step:
                    for name, values in request.input_series.items():
                        simulation.set_real(f"{INSTANCE_NAME}::{name}", values[step - 1])
                    simulation.step()
                rows.append([simulation.get_time(), *map(simulation.get_real, identifiers)])
            simulation.terminate()
    columns = np.array(rows).T
    return {"time": columns[0], **dict(zip(request.outputs, columns[1:]))}


def _check_ecospy_start_values(simulation, request: _Request) -> None:
    """ecos ignores the status of the FMU's setters: read every value back."""
    getters = {bool: simulation.get_bool, int: simulation.get_integer, float: simulation.get_real}
    for name, value in request.start_values.items():
        held = getters[type(value)](f"{INSTANCE_NAME}::{name}")
        if held != value:
            raise ImporterRunError(f"'{request.fmu_path}' holds {name} = {held} after ecospy "
                                   f"set it to {value}: the FMU refused the value")


# ----------------------------------------------------------------------------- libcosimpy
def _simulate_with_libcosimpy(request: _Request) -> dict[str, np.ndarray]:
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy._internal import get_last_error_message

    execution, index, references = _load_libcosimpy_execution(request)
    observer = CosimObserver.create_time_series(buffer_size=request.steps + 1)
    execution.add_observer(observer)
    for name in request.outputs:
        observer.start_time_series(index, references[name], CosimVariableType.REAL)
    if not all(_step_libcosimpy(execution, index, references, request)):
        raise ImporterRunError(f"libcosimpy failed on '{request.fmu_path}': "
                               f"{get_last_error_message()}")
    series = {name: _read_libcosimpy_samples(observer, index, references[name], request.steps)
              for name in request.outputs}
    return {"time": series[request.outputs[0]][0],
            **{name: values for name, (_, values) in series.items()}}


def _step_libcosimpy(execution, index: int, references: dict[str, int],
                     request: _Request) -> Iterator[bool]:
    """Run all steps, yielding each call's success; time-varying inputs are overridden
    before each step (libcosim sets an override on the FMU before its next doStep)."""
    if not request.input_series:
        yield execution.step(request.steps)
        return
    from libcosimpy.CosimManipulator import CosimManipulator

    override = CosimManipulator.create_override()
    execution.add_manipulator(override)
    execution.override = override  # like the slave, it must outlive the execution
    names = list(request.input_series)
    for step in range(request.steps):
        yield override.slave_real_values(index, [references[name] for name in names],
                                         [request.input_series[name][step] for name in names])
        yield execution.step(1)


def _load_libcosimpy_execution(request: _Request) -> tuple[object, int, dict[str, int]]:
    """An execution holding the FMU with its start values; the slave index; value references."""
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimSlave import CosimLocalSlave
    from libcosimpy._internal import get_last_error_message

    log_output_level(CosimLogLevel.WARNING)  # its default, debug, prints every FMI call
    execution = CosimExecution.from_step_size(round(request.step_size * 1e9))  # time in ns
    slave = CosimLocalSlave(request.fmu_path, INSTANCE_NAME)
    index = execution.add_local_slave(slave) if slave.ptr() else -1
    if index < 0:
        raise ImporterRunError(f"libcosimpy could not load '{request.fmu_path}': "
                               f"{get_last_error_message()}")
    references = {variable.name.decode(): variable.reference
                  for variable in execution.slave_variables(index)}
    setters = {bool: execution.boolean_initial_value, int: execution.integer_initial_value,
               float: execution.real_initial_value}
    for name, value in request.start_values.items():
        if not setters[type(value)](index, references[name], value):
            raise ImporterRunError(f"libcosimpy refused the start value {name} = {value}")
    execution.slave = slave  # the slave must outlive the execution that runs it
    return execution, index, references


def _read_libcosimpy_samples(observer, index: int, reference: int,
                             steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Time (s) and values of one variable at steps 0..`steps` of a time-series observer.

    libcosimpy trims each reply by the number of samples whose step number is 0, so step 0 and
    steps 1.. are asked separately, each with one spare slot; this also works once fixed.
    """
    first_times, _, first_values = observer.time_series_real_samples(
        index, reference, from_step=0, sample_count=2)
    times, _, values = observer.time_series_real_samples(
        index, reference, from_step=1, sample_count=steps + 1)
    if not first_times or len(times) < steps:
        raise ImporterRunError(f"libcosimpy recorded {len(times)} of {steps} steps of value "
                               f"reference {reference}")
    return (np.array([first_times[0], *times[:steps]]) * 1e-9,
            np.array([first_values[0], *values[:steps]]))


_SIMULATORS: dict[str, Callable[[_Request], dict[str, np.ndarray]]] = {
    "ecospy": _simulate_with_ecospy,
    "libcosimpy": _simulate_with_libcosimpy,
}
_ERRORS: dict[str, type[CrosscheckError]] = {
    error.__name__: error for error in (CrosscheckError, ImporterUnavailableError,
                                        UnsupportedFmuError, UnknownVariableError, ImporterRunError)
}
