"""Model Exchange outside fmpy: the FMU Manipulation Toolbox's container as the importer.

fmpy is the only Python package that integrates Model Exchange FMUs on its own; the co-simulation
engines of :mod:`panto.build_fmu.crosscheck` (ecospy, libcosimpy) run Co-Simulation only. The FMU
Manipulation Toolbox (PyPI ``fmu-manipulation-toolbox``, already the project's checker) builds
*containers*: a Co-Simulation FMU of its own (``container.so``, shipped in the wheel) that imports
the FMUs it embeds. One embedded through its Model Exchange interface is integrated by the
container's C code with explicit Euler or classical Runge-Kutta (RK4) at the container's step,
through ``fmi3InstantiateModelExchange``, ``fmi3SetContinuousStates``,
``fmi3GetContinuousStateDerivatives``, ... (FMI 2.0 likewise). It prefers an FMU's Co-Simulation
interface, so :func:`simulate_model_exchange_in_container` embeds a copy whose
``modelDescription.xml`` has no ``<CoSimulation>`` element. The container itself is then driven
through its Co-Simulation interface by fmpy; fmpy never calls the embedded FMU.

What the container does not do: it locates no events (event indicators are not watched; a state
event is noticed only at the next step) and controls no error (fixed steps).

Other Model Exchange importers looked for on the package index (2026-11) and why they are not
used: OMSimulator (3.0.0.post198, .post116 and 2.1.3 looked at) is a source package whose build
downloads its binaries from its vendor's server, not from the index; PyFMI's last release there
is 2.5 (2018: FMI 1.0 and 2.0 only, and it needs FMI Library built by hand); fmuloader binds the
FMI 3.0 functions with ctypes but leaves the integration to its user.
"""
from __future__ import annotations

import logging
import os
import re
import tempfile
import zipfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Literal

import numpy as np

from .crosscheck import UnsupportedFmuError, _count_steps, _input_series

CONTAINER_SOLVERS = {"euler": 0, "rk4": 1}
"""Codes of the container's integrators (its input ``container.solver``)."""

_CO_SIMULATION = re.compile(r"<CoSimulation\b[^>]*?(/>|>.*?</CoSimulation>)", re.DOTALL)


def model_exchange_only(fmu_path: str | os.PathLike, target: str | os.PathLike) -> Path:
    """Copy an FMU without its Co-Simulation interface (``<CoSimulation>`` removed).

    Parameters
    ----------
    fmu_path : str or os.PathLike
        A ``.fmu`` offering Model Exchange (and possibly Co-Simulation).
    target : str or os.PathLike
        The ``.fmu`` file to write.

    Returns
    -------
    pathlib.Path
        `target`.

    Raises
    ------
    UnsupportedFmuError
        If the FMU has no Model Exchange interface.
    """
    target = Path(target)
    with zipfile.ZipFile(fmu_path) as source, zipfile.ZipFile(target, "w",
                                                              zipfile.ZIP_DEFLATED) as copy:
        for item in source.infolist():
            data = source.read(item)
            if item.filename == "modelDescription.xml":
                text = data.decode("utf-8")
                if "<ModelExchange" not in text:
                    raise UnsupportedFmuError(f"'{fmu_path}' has no Model Exchange interface")
                data = _CO_SIMULATION.sub("", text, count=1).encode("utf-8")
            copy.writestr(item, data)
    return target


def simulate_model_exchange_in_container(
    fmu_path: str | os.PathLike,
    *,
    stop_time: float,
    step_size: float,
    outputs: Sequence[str],
    inputs: Mapping[str, float | Sequence[float]] | None = None,
    solver_step: float | None = None,
    solver: Literal["euler", "rk4"] = "rk4",
) -> dict[str, np.ndarray]:
    """Integrate an FMU's Model Exchange interface in a toolbox container.

    Parameters
    ----------
    fmu_path : str or os.PathLike
        The ``.fmu`` file (FMI 2.0 or 3.0, with Model Exchange).
    stop_time : float
        End of the simulation in s; an integer multiple of `step_size`.
    step_size : float
        Communication step in s: where inputs change and outputs are recorded.
    outputs : sequence of str
        Names of the outputs to record.
    inputs : mapping of str to float or sequence of float, optional
        As in :func:`panto.build_fmu.crosscheck.simulate_in_independent_importer`: a constant or
        one sample per communication point, held over the step.
    solver_step : float, optional
        The container's fixed integration step in s (default `step_size`); it should divide
        `step_size`.
    solver : {"rk4", "euler"}
        The container's integrator.

    Returns
    -------
    dict of str to numpy.ndarray
        ``"time"`` (``0, h, ..., stop_time``) and one array per output.

    Raises
    ------
    UnsupportedFmuError
        If the FMU has no Model Exchange interface, or the container does not embed it as one.
    """
    from fmpy import simulate_fmu
    from fmu_manipulation_toolbox.container import FMUContainer

    steps = _count_steps(stop_time, step_size)
    inputs = dict(inputs or {})
    series = {name: np.asarray(values, dtype=float) for name, values in
              {**{n: np.full(steps + 1, float(v)) for n, v in inputs.items() if np.ndim(v) == 0},
               **_input_series(inputs, steps)}.items()}
    times = np.linspace(0.0, stop_time, steps + 1)
    with tempfile.TemporaryDirectory(prefix="container_me_") as directory:
        embedded = model_exchange_only(fmu_path, Path(directory) / "embedded.fmu")
        container = FMUContainer("ModelExchangeHost", directory, fmi_version=_fmi_version(embedded))
        logger = logging.getLogger("fmu_manipulation_toolbox")
        level, logger.level = logger.level, logging.ERROR  # its INFO lines on every build
        try:
            if not container.get_fmu(embedded.name).is_me:
                raise UnsupportedFmuError(f"the container did not embed '{fmu_path}' as Model "
                                          "Exchange")
            container.add_implicit_rule(auto_input=True, auto_output=True)
            container.make_fmu("host.fmu", step_size=solver_step or step_size)
        finally:
            logger.setLevel(level)
        table = np.array(list(zip(times, *series.values())),
                         dtype=[("time", float)] + [(name, float) for name in series])
        result = simulate_fmu(str(Path(directory) / "host.fmu"), fmi_type="CoSimulation",
                              stop_time=stop_time, step_size=step_size,
                              output_interval=step_size, input=table if series else None,
                              start_values={"container.solver": CONTAINER_SOLVERS[solver]},
                              output=list(outputs))
    return {name: np.array(result[name]) for name in ("time", *outputs)}


def _fmi_version(fmu: Path) -> int:
    """2 or 3: the FMI version of an FMU, from its ``modelDescription.xml``."""
    with zipfile.ZipFile(fmu) as archive:
        text = archive.read("modelDescription.xml").decode("utf-8")
    return 3 if re.search(r'fmiVersion="3\.', text) else 2
