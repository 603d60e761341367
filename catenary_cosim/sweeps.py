"""Speed sweeps and parameter studies, spread over any ``concurrent.futures`` executor.

Each run is a :class:`CosimulationCase`: plain, picklable data (the line as a name, a file or
a definition turned into plain fields; the pantograph setup with its FMU file resolved; the
options of :func:`.master.cosimulate`), never an open FMU or a built catenary. A worker
process builds its own catenary and opens its own FMU instance, so runs are independent.

Executors
    * default: a local :class:`concurrent.futures.ProcessPoolExecutor` with 2 workers, made and
      shut down by the call;
    * any :class:`concurrent.futures.Executor` you pass (kept open: it is yours);
    * a Dask distributed ``Client`` (or ``client.get_executor()``): the client's executor is
      used, so the same call runs on a laptop's local cluster or on a cluster of machines. The
      workers need this package installed and the FMU file reachable at the same path (or
      give every worker a copy at that path).

A failing run does not lose the others: its :class:`CaseResult` has ``success=False`` and the
error message.

Examples
--------
>>> from panto.catenary_cosim.sweeps import speed_sweep
>>> results = speed_sweep("en50318-2002", "en50318-2002", [200, 250, 300])   # doctest: +SKIP
>>> from distributed import Client, LocalCluster                            # doctest: +SKIP
>>> with LocalCluster(n_workers=2, processes=True) as cluster, Client(cluster) as client:
...     results = speed_sweep("en50318-2002", "en50318-2002", [250, 300],
...                           executor=client)                            # doctest: +SKIP
"""
from __future__ import annotations

import dataclasses
import time as clock
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .pantographs import PantographSetup, pantograph_setup

#: Workers of the default local process pool.
DEFAULT_WORKERS = 2


@dataclass(frozen=True)
class CosimulationCase:
    """One co-simulation run as picklable data.

    Parameters
    ----------
    line : str or tuple
        Line name or JSON file, or a definition as ``(("field", value), ...)`` pairs
        (:func:`line_as_data`).
    pantograph : PantographSetup
        Setup with `fmu_path` set (resolved by the caller, so workers do not build FMUs).
    speed_kmh : float
    options : tuple of (str, value)
        Keyword options of :func:`.master.cosimulate` (time_step, element_length, ...).
    line_changes : tuple of (str, value)
        Fields of the line replaced for this run (a parameter study), e.g.
        ``(("steady_arm_stiffness", 2673.58),)``.
    label : str
        Free text identifying the run in reports.
    keep_series : bool
        Return this run's full :class:`.master.CosimulationResult` (time series: large).
    """

    line: str | tuple[tuple[str, Any], ...]
    pantograph: PantographSetup
    speed_kmh: float
    options: tuple[tuple[str, Any], ...] = ()
    line_changes: tuple[tuple[str, Any], ...] = ()
    label: str = ""
    keep_series: bool = False


@dataclass(frozen=True)
class CaseResult:
    """What a run returns to the caller (statistics and bookkeeping; series on request)."""

    case: CosimulationCase
    statistics: dict[str, float]
    settings: dict[str, Any]
    counters: dict[str, int]
    timing: dict[str, float]
    success: bool
    message: str
    result: Any = None  # the CosimulationResult when keep_series=True


def line_as_data(line: Any) -> tuple[tuple[str, Any], ...]:
    """A :class:`.lines.LineDefinition` as picklable ``(field, value)`` pairs."""
    pairs = []
    for item in dataclasses.fields(line):
        value = getattr(line, item.name)
        pairs.append((item.name, dict(value) if isinstance(value, Mapping) else value))
    return tuple(pairs)


def _line(case: CosimulationCase) -> Any:
    from .lines import LineDefinition, load_line

    line = load_line(case.line) if isinstance(case.line, (str, Path)) else \
        LineDefinition(**dict(case.line))
    if case.line_changes:
        line = dataclasses.replace(line, **dict(case.line_changes))
    return line


def run_case(case: CosimulationCase, keep_series: bool = False) -> CaseResult:
    """Run one case (in whichever process calls it); errors come back as ``success=False``."""
    from .master import cosimulate

    try:
        result = cosimulate(_line(case), case.pantograph, speed_kmh=case.speed_kmh,
                            **dict(case.options))
        statistics = result.statistics().to_dict()
    except Exception as error:  # a bad case must not lose the other runs of a sweep
        return CaseResult(case, {}, {}, {}, {}, False, f"{type(error).__name__}: {error}")
    keep = keep_series or case.keep_series
    return CaseResult(case, statistics, result.settings, result.counters, result.timing,
                      result.success, result.message, result if keep else None)


def _executor(executor: Any) -> tuple[Executor, bool]:
    """(executor, owned): a Dask client gives its executor; None makes a local pool."""
    if executor is None:
        return ProcessPoolExecutor(max_workers=DEFAULT_WORKERS), True
    if hasattr(executor, "get_executor"):  # dask.distributed.Client
        return executor.get_executor(), False
    if not hasattr(executor, "submit"):
        raise TypeError(f"expected a concurrent.futures.Executor or a Dask Client, got "
                        f"{type(executor).__name__}")
    return executor, False


def resolve_pantograph(pantograph: PantographSetup | str, *,
                       fmu_cache: str | Path | None = None,
                       progress: Callable[[str], None] | None = None) -> PantographSetup:
    """The setup with its FMU file resolved (built once here, not in every worker)."""
    setup = pantograph_setup(pantograph) if isinstance(pantograph, str) else pantograph
    return setup.with_fmu(setup.resolve_fmu(fmu_cache, progress=progress).resolve())


def run_cases(cases: Sequence[CosimulationCase], *, executor: Any = None,
              keep_series: bool = False,
              progress: Callable[[str], None] | None = None) -> list[CaseResult]:
    """Run cases on an executor; results in the order of `cases`.

    Parameters
    ----------
    cases : sequence of CosimulationCase
    executor : concurrent.futures.Executor or dask.distributed.Client, optional
        Default: a local process pool with :data:`DEFAULT_WORKERS` workers.
    keep_series : bool, optional
        Return the full :class:`.master.CosimulationResult` of each run (large).
    progress : callable, optional
        Called with one line per finished run.
    """
    pool, owned = _executor(executor)
    started = clock.perf_counter()
    try:
        futures = {pool.submit(run_case, case, keep_series): i for i, case in enumerate(cases)}
        results: list[CaseResult | None] = [None] * len(cases)
        for done, future in enumerate(as_completed(futures), start=1):
            index = futures[future]
            results[index] = future.result()
            if progress:
                r = results[index]
                verdict = (f"mean {r.statistics['mean']:.1f} N, std {r.statistics['std']:.1f} N"
                           if r.success else f"FAILED: {r.message}")
                progress(f"[{done}/{len(cases)}] {cases[index].label or index}: {verdict} "
                         f"({clock.perf_counter() - started:.0f} s)")
    finally:
        if owned:
            pool.shutdown()
    return [r for r in results if r is not None]


def _base(line: Any, pantograph: PantographSetup | str, fmu_cache: Any,
          progress: Callable[[str], None] | None) -> tuple[Any, PantographSetup]:
    data = line if isinstance(line, (str, Path)) else line_as_data(line)
    return (str(data) if isinstance(data, Path) else data,
            resolve_pantograph(pantograph, fmu_cache=fmu_cache, progress=progress))


def speed_sweep(line: Any, pantograph: PantographSetup | str, speeds_kmh: Iterable[float], *,
                executor: Any = None, fmu_cache: str | Path | None = None,
                keep_series: bool = False, progress: Callable[[str], None] | None = None,
                **options: Any) -> list[CaseResult]:
    """The same line and pantograph at several speeds (options: those of ``cosimulate``)."""
    data, setup = _base(line, pantograph, fmu_cache, progress)
    cases = [CosimulationCase(data, setup, float(v), tuple(options.items()),
                              label=f"{float(v):g} km/h") for v in speeds_kmh]
    return run_cases(cases, executor=executor, keep_series=keep_series, progress=progress)


def parameter_study(line: Any, pantograph: PantographSetup | str, speed_kmh: float, *,
                    values: Sequence[Any], line_field: str | None = None,
                    pantograph_parameter: str | None = None, option: str | None = None,
                    executor: Any = None, fmu_cache: str | Path | None = None,
                    progress: Callable[[str], None] | None = None,
                    **options: Any) -> list[CaseResult]:
    """One input varied over `values`: a line field, an FMU parameter or a run option.

    Exactly one of `line_field` (e.g. ``"steady_arm_stiffness"``), `pantograph_parameter`
    (e.g. ``"F_0"``) and `option` (e.g. ``"damping"``, ``"element_length"``) names the input.
    """
    chosen = [name for name in (line_field, pantograph_parameter, option) if name is not None]
    if len(chosen) != 1:
        raise ValueError("name exactly one of line_field, pantograph_parameter, option")
    data, setup = _base(line, pantograph, fmu_cache, progress)
    cases = []
    for value in values:
        run_setup = setup.with_parameters(**{pantograph_parameter: value}) \
            if pantograph_parameter else setup
        run_options = {**options, **({option: value} if option else {})}
        changes = ((line_field, value),) if line_field else ()
        cases.append(CosimulationCase(data, run_setup, float(speed_kmh),
                                      tuple(run_options.items()), changes,
                                      label=f"{chosen[0]} = {value}"))
    return run_cases(cases, executor=executor, progress=progress)


__all__ = ["CosimulationCase", "CaseResult", "run_case", "run_cases", "speed_sweep",
           "parameter_study", "resolve_pantograph", "line_as_data", "DEFAULT_WORKERS"]
