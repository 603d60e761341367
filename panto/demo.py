"""The main job (``panto demo``): the whole story on the embedded defaults, into one folder.

1. Generate, compile, package and validate the FMUs (FMI 2.0 and 3.0, ME and CS) -> ``fmus/``.
2. Run the thesis' rig campaign on the virtual test bed (an APRBS training run and a ramp
   validation run, through the CAN driver and the drive emulator, imperfections on) ->
   ``runs/<label>_NNNN``; simulate the nominal FMUs on the measured inputs (the gap before any
   fitting); film a window of each run with the synthetic camera (reduced resolution), track the
   markers, synchronise the track with the 500 Hz data through the LED and write the merged
   dataset beside the run (``runs/<label>_NNNN/video_merged/run.csv``) -> ``video/``.
3. Identify the physical model (physical-linear, Levenberg-Marquardt) and the other fast
   structures on the training run, validate on the ramp run: the comparison table
   (thesis 4.8) -> ``comparison/``; the physical model's parameter file, an NSGA-II Pareto front
   (Fig. 4.7) and the eigenvalue sensitivity (Fig. 4.9) -> ``identification/``.
4. Diagnose the physical model's sim-to-real gap on the withheld validation run -> ``diagnosis/``.
5. Design the next rig run (D-optimal, covariance against the APRBS) -> ``doe/``.
6. Co-simulate the identified pantograph (its parameter file applied to ``Pantograph.fmu``) with
   the EN 50318 catenary at 300 km/h and set the statistics beside the targets -> ``cosim/``.

Everything ends in ``summary.json`` and ``report.html`` (:mod:`panto.report`). A step that fails
is recorded with its message (and the steps needing its results are marked skipped); the others
still run, and :func:`run_demo` raises :class:`DemoError` at the end, after writing both files.
"""
from __future__ import annotations

import json
import re
import time
import traceback
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

Progress = Callable[[str], None]

#: The structures the comparison fits in the full demo: the fast ones (seconds each on the
#: 180 s run). The FMU-in-the-loop ``physical`` and the friction oscillators take 1-5 minutes
#: each; their figures on the same runs are in docs/identification/comparison_full.md.
FAST_STRUCTURES = ("physical-linear", "two-mass", "three-mass", "blackbox-4", "blackbox-6")


class DemoError(RuntimeError):
    """Raised at the end of :func:`run_demo` when a step failed (everything else was written)."""


@dataclass(frozen=True)
class DemoSettings:
    """How much the demo does (:meth:`full` or :meth:`quick`).

    Parameters
    ----------
    run_duration : float or None
        Length of each rig run [s] (None: the profile's, 180 s and 200 s).
    fmu_names : tuple of str or None
        FMUs to build (None: all).
    fmi_versions : tuple of int
        FMI versions to build.
    video_window : float
        Seconds of each run filmed by the synthetic camera.
    video_scale : float
        Camera resolution factor (1: 1920x1080).
    structures : tuple of str
        Structures of the comparison table.
    max_evaluations : int or None
        Model evaluations per least-squares fit (None: the estimators' defaults).
    pareto_population, pareto_generations : int
        NSGA-II for the Pareto front (thesis Fig. 4.7); population 0: no front.
    diagnosis_max_effects : int
        Effects the diagnosis may accept.
    diagnosis_light : bool
        A smoke-test diagnosis: the adequacy check's global refit with one data-driven start
        (from a small frequency-response search) and no perturbations, no discovery search and
        no challenge of the accepted effects (the quick demo; the full one searches fully).
    doe_duration : float
        Length of the designed rig run [s].
    doe_population, doe_generations : int
        GA of the experiment design.
    cosim_element_length, cosim_time_step : float or None
        Catenary discretisation (None: the line's defaults).
    cosim_speed : float
        Running speed [km/h].
    cosim_reference : bool
        Also run the EN 50318 reference pantograph (the line model's check).
    workers : int
        Processes for the independent parts, all with the same results as 1 (everything one
        after the other in this process): the FMUs are built in that many parts side by side,
        the two rig runs run side by side, and the video step (both runs, one after the other)
        runs in a worker process beside the identification and the diagnosis, whose fits
        leave a core free for most of their time (:class:`Step`).
    """

    run_duration: float | None = None
    fmu_names: tuple[str, ...] | None = None
    fmi_versions: tuple[int, ...] = (2, 3)
    video_window: float = 30.0
    video_scale: float = 0.5
    structures: tuple[str, ...] = FAST_STRUCTURES
    max_evaluations: int | None = None
    pareto_population: int = 24
    pareto_generations: int = 12
    diagnosis_max_effects: int = 2
    diagnosis_light: bool = False
    doe_duration: float = 60.0
    doe_population: int = 20
    doe_generations: int = 20
    cosim_element_length: float | None = None
    cosim_time_step: float | None = None
    cosim_speed: float = 300.0
    cosim_reference: bool = True
    workers: int = 2

    @classmethod
    def full(cls) -> DemoSettings:
        """The main job: the thesis' runs in full, fast structures, a small GA."""
        return cls()

    @classmethod
    def quick(cls) -> DemoSettings:
        """Every step on short runs, a tiny video and GA, a coarse catenary (seconds each)."""
        return cls(run_duration=10.0, fmu_names=("Pantograph", "PantographLinear"),
                   fmi_versions=(2,), video_window=7.0, video_scale=0.25,
                   structures=("physical-linear", "blackbox-4"), max_evaluations=300,
                   pareto_population=8, pareto_generations=3, diagnosis_max_effects=1,
                   diagnosis_light=True,
                   doe_duration=10.0, doe_population=6, doe_generations=2,
                   cosim_element_length=0.5, cosim_time_step=1e-3, cosim_reference=False)


@dataclass(frozen=True)
class Step:
    """One step of the demo: its name, title, function and what it needs from earlier steps.

    A step with `gives` (the state keys it adds) runs beside the following steps in a worker
    process when ``settings.workers`` > 1, with ``workers=1`` inside (its own parts one after
    the other): its lines follow when it ends, before the first step that needs what it gives,
    at the latest at the end. It must not need the state the following steps add.
    """

    name: str
    title: str
    function: Callable[..., dict]
    needs: tuple[str, ...] = ()
    gives: tuple[str, ...] = ()


def _steps() -> tuple[Step, ...]:
    from panto import demo_analysis as analysis
    from panto import demo_steps as steps

    return (
        Step("fmus", "build and validate the FMUs", steps.build_fmus),
        Step("rig", "rig campaign on the virtual test bed", steps.run_rig_campaign, ("fmus",)),
        Step("video", "camera video: render, track, synchronise, merge", steps.film_runs,
             ("runs",), gives=("merged",)),
        Step("identification", "identify the physical model and compare the structures",
             analysis.identify_models, ("runs",)),
        Step("diagnosis", "diagnose the physical model's gap on the validation run",
             analysis.diagnose_gap, ("data",)),
        Step("doe", "design the next rig run", analysis.design_next_run, ()),
        Step("cosim", "co-simulate the identified pantograph with the catenary",
             analysis.cosimulate_identified, ("fmus",)),
    )


def run_demo(out: Path, *, quick: bool = False, progress: Progress = print,
             settings: DemoSettings | None = None) -> dict:
    """Run the main job and write its results to `out` (module notes).

    Parameters
    ----------
    out : pathlib.Path
        Output folder (created; a rerun adds new rig runs and overwrites the rest).
    quick : bool
        :meth:`DemoSettings.quick` instead of :meth:`DemoSettings.full`.
    progress : callable
        Receives one line per step and the steps' own progress lines.
    settings : DemoSettings, optional
        Overrides `quick`.

    Returns
    -------
    dict
        The summary also written to ``out/summary.json``.

    Raises
    ------
    DemoError
        After writing the summary and the report, when any step failed.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    settings = settings or (DemoSettings.quick() if quick else DemoSettings.full())
    started = time.perf_counter()
    state: dict[str, Any] = {"out": out, "settings": settings}
    summary: dict[str, Any] = {"quick": quick, "settings": asdict(settings), "steps": []}
    steps = _steps()
    beside: dict[str, Beside] = {}
    for number, step in enumerate(steps, 1):
        label = f"[{number}/{len(steps)}] {step.title}"
        for name in [n for n, job in beside.items() if set(job.step.gives) & set(step.needs)]:
            _join(beside.pop(name), state, summary, progress)
        if step.gives and settings.workers > 1 and all(key in state for key in step.needs):
            beside[step.name] = _start_beside(step, state, label, progress)
            summary["steps"].append({"name": step.name})  # filled in when it ends
            continue
        _record(summary, _run_step(step, state, label, progress))
    for job in beside.values():
        _join(job, state, summary, progress)
    summary["wall_time_s"] = time.perf_counter() - started
    summary["failed_steps"] = [s["name"] for s in summary["steps"] if s["status"] != "ok"]
    return _finish(out, summary, progress)


def _record(summary: dict[str, Any], record: dict) -> None:
    """Put a step's record in its place in ``summary["steps"]`` and its result beside it."""
    places = [i for i, s in enumerate(summary["steps"]) if s == {"name": record["name"]}]
    if places:
        summary["steps"][places[0]] = record
    else:
        summary["steps"].append(record)
    if record["status"] == "ok":
        summary[record["name"]] = record.pop("result")


@dataclass(frozen=True)
class Beside:
    """A step running in a worker process (:func:`_start_beside`)."""

    step: Step
    pool: Any
    future: Any


def _start_beside(step: Step, state: dict[str, Any], label: str, progress: Progress) -> Beside:
    """Start `step` in a worker process on a copy of `state` (its parts one after the other)."""
    from concurrent.futures import ProcessPoolExecutor
    from dataclasses import replace

    progress(f"{label}: beside the next steps in a worker process (its lines follow when it "
             "ends)")
    copy = {**state, "settings": replace(state["settings"], workers=1)}
    pool = ProcessPoolExecutor(max_workers=1)
    return Beside(step, pool, pool.submit(_step_in_worker, step, copy, label))


def _step_in_worker(step: Step, state: dict[str, Any], label: str
                    ) -> tuple[dict, dict[str, Any], list[str]]:
    """Run `step` here: its record, the state it gave and its progress lines."""
    lines: list[str] = []
    record = _run_step(step, state, label, lines.append)
    return record, {key: state[key] for key in step.gives if key in state}, lines


def _join(job: Beside, state: dict[str, Any], summary: dict[str, Any],
          progress: Progress) -> None:
    """Wait for a step started by :func:`_start_beside`; print its lines, record it."""
    try:
        record, given, lines = job.future.result()
    except Exception as error:  # noqa: BLE001 - the worker itself died: recorded like a failure
        message = f"{type(error).__name__}: {error}"
        record, given, lines = ({"name": job.step.name, "title": job.step.title,
                                 "status": "failed", "seconds": 0.0, "message": message,
                                 "traceback": traceback.format_exc(limit=6)}, {},
                                [f"[{job.step.name}] FAILED: {message}"])
    finally:
        job.pool.shutdown()
    for line in lines:
        progress(line)
    state.update(given)
    _record(summary, record)


def _run_step(step: Step, state: dict[str, Any], label: str, progress: Progress) -> dict:
    """Run one step; a failure becomes a record with its message, never an exception."""
    missing = [key for key in step.needs if key not in state]
    if missing:
        message = f"skipped: needs {missing} from a step that failed"
        progress(f"{label}: {message}")
        return {"name": step.name, "title": step.title, "status": "skipped", "seconds": 0.0,
                "message": message}
    progress(label)
    clock = time.perf_counter()
    try:
        result = step.function(state, lambda line: _say(progress, line))
    except Exception as error:  # noqa: BLE001 - every failure is recorded, the rest goes on
        seconds = time.perf_counter() - clock
        message = f"{type(error).__name__}: {error}"
        progress(f"      FAILED after {seconds:.1f} s: {message}")
        return {"name": step.name, "title": step.title, "status": "failed", "seconds": seconds,
                "message": message, "traceback": traceback.format_exc(limit=6)}
    seconds = time.perf_counter() - clock
    progress(f"      done in {seconds:.1f} s")
    return {"name": step.name, "title": step.title, "status": "ok", "seconds": seconds,
            "message": "", "result": result}


def _say(progress: Progress, line: str) -> None:
    """Pass a step's line on, indented; the estimators' per-iteration lines are left out."""
    if not _ITERATION.search(line):
        progress("      " + line)


_ITERATION = re.compile(r"\b(iteration|generation) \d+\b")


def _finish(out: Path, summary: dict, progress: Progress) -> dict:
    from panto.report import write_report

    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=_plain) + "\n")
    try:
        report = write_report(summary, out)
        progress(f"wrote {report}")
    except Exception as error:  # noqa: BLE001 - the summary is already on disk
        summary["failed_steps"].append("report")
        summary["report_error"] = f"{type(error).__name__}: {error}"
        (out / "summary.json").write_text(json.dumps(summary, indent=2, default=_plain) + "\n")
    progress(f"done in {summary['wall_time_s']:.1f} s: {out / 'summary.json'}")
    if summary["failed_steps"]:
        raise DemoError(f"step(s) {summary['failed_steps']} failed (see {out / 'summary.json'} "
                        f"and {out / 'report.html'}); the other results are written")
    return summary


def _plain(value: Any) -> Any:
    """JSON fallback: numpy scalars and arrays, paths, mappings."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, Mapping):
        return dict(value)
    return str(value)
