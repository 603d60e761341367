"""Benchmark: do the fits recover known parameters? (issue 19, "Recovery proven").

Run by hand; writes benchmarks/identification_recovery.json and .md.

    .venv/bin/python benchmarks/identification_recovery.py [--quick] [--fit default global
        global-reference]
        [--seeds 2] [--pantograph-seeds 1] [--snr 30] [--workers 1] [--quiet]

Data with known truth (``benchmarks/plants.py``): two- and three-mass oscillator plants written
apart from the code under test (force balance integrated by ``solve_ivp``), truth drawn per seed
within +-30 % around EN 50318 / Bruni values, three excitations (APRBS with pressure steps,
multisine, chirp at constant pressure), white noise at a stated SNR; and the physical pantograph
on the virtual test bed without imperfections (truth: Table 4.1 drawn per seed, given to the
FMU), which is *not* independent of the model (same symbolic source).

Per family x excitation x seed, the matching structure (``two-mass``, ``three-mass``,
``physical-linear``, built by :func:`panto.identification.structures.registry.build_structure`)
is fitted with its default free parameters by each estimator asked for:

- ``default``: :func:`panto.identification.estimation.least_squares.fit_least_squares` from the
  structure's nominal values (what the diagnosis does);
- ``global``: ``panto.identification.estimation.global_fit.fit_global`` (data-driven starts and
  perturbations), when that module exists.
- ``global-reference``: the same, its data-driven starts matching the response of the black box
  of the adequacy check fitted to the record first (as ``panto identify`` with ``--initial data``
  and its adequacy check on).

and once more from the truth (the "truth-started fit", the reference optimum). Recorded: the
training fit beside the truth's own fit (the noise floor), each parameter's relative error
against the truth, whether the estimator says it reached the global optimum (when it says so),
whether it really did (cost within 0.1 % of the truth-started fit's cost), and the wall time.
Parameters the data cannot hold (the truth-started fit's per-parameter verdict other than
"identifiable": weakly / not identifiable, at a bound; ``result.estimates``) are marked and
listed, not counted as recovery failures (the unfiltered maximum is reported beside);
``y_cb_offset`` (true value near zero) is judged by its absolute error in millimetres.
"""
from __future__ import annotations

import argparse
import inspect
import json
import math
import os
import platform
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

#: Relative cost excess over the truth-started fit that still counts as the global optimum.
GLOBAL_TOLERANCE = 1e-3
#: Parameters judged by absolute error [m] (true value near zero).
ABSOLUTE = ("y_cb_offset",)


@dataclass(frozen=True)
class Case:
    """One family x excitation x seed of the grid (`duration`: override of the record length [s])."""

    family: str
    excitation: str
    seed: int
    snr_db: float = 30.0
    duration: float | None = None

    @property
    def label(self) -> str:
        """``family/excitation/seed``."""
        return f"{self.family}/{self.excitation}/{self.seed}"


def say(message: str, quiet: bool = False) -> None:
    """Progress on stderr."""
    if not quiet:
        print(message, file=sys.stderr, flush=True)


# --- estimators -------------------------------------------------------------------------------

def fit_default(structure, data, free):
    """The default-start fit: bounded LM from the structure's nominal values."""
    from panto.identification.estimation.least_squares import fit_least_squares

    return fit_least_squares(structure, data, free=free)


def fit_global_estimator(structure, data, free):
    """``fit_global`` of ``panto.identification.estimation.global_fit`` with its default options."""
    from panto.identification.estimation import global_fit

    parameters = inspect.signature(global_fit.fit_global).parameters
    options = parameters.get("options")
    if options is not None and options.default is inspect.Parameter.empty:
        option_types = [v for k, v in vars(global_fit).items()
                        if k.endswith("Options") and isinstance(v, type)]
        return global_fit.fit_global(structure, data, free=free, options=option_types[0]())
    return global_fit.fit_global(structure, data, free=free)


def fit_global_reference(structure, data, free):
    """``fit_global`` whose data-driven starts match the frequency response of the adequacy's
    black box fitted to the same record (``reference``), as ``panto identify`` fits globally
    with its adequacy check on."""
    from panto.identification.estimation import global_fit
    from panto.identification.structures.adequacy import best_black_box

    box = best_black_box(structure, structure.nominal(), data)[0]
    return global_fit.fit_global(structure, data, free=free, reference=box)


ESTIMATORS = {"default": fit_default, "global": fit_global_estimator,
              "global-reference": fit_global_reference}


def global_fit_available() -> bool:
    """Whether ``global_fit.py`` exists yet."""
    return (HERE.parent / "identification" / "estimation" / "global_fit.py").exists()


# --- one case ---------------------------------------------------------------------------------

def case_data(case: Case):
    """``(data, truth, notes)`` of `case` from :mod:`plants`."""
    import plants
    from panto.identification.estimation.base import IdentificationData

    if case.family == "pantograph":
        return plants.pantograph_case(case.excitation, case.seed)
    record = plants.oscillator_case(case.family, case.excitation, case.seed, snr_db=case.snr_db,
                                    duration=case.duration)
    return plants.record_to_data(record, IdentificationData), record.truth, record.notes


def claimed_global(result) -> Any:
    """What the estimator says about reaching the global optimum (None when it says nothing)."""
    details = dict(result.details or {})
    for key in ("global_fit", "global_optimum", "global", "starts_agree", "agree"):
        value = details.get(key)
        if isinstance(value, (bool, np.bool_)):
            return bool(value)
        if isinstance(value, Mapping):
            for inner in ("found", "global_optimum", "agree", "reached"):
                if isinstance(value.get(inner), (bool, np.bool_)):
                    return bool(value[inner])
    return None


def not_identifiable(result) -> dict[str, str]:
    """The parameters whose verdict is not "identifiable", with the verdict: the per-parameter
    verdicts of ``result.estimates`` (weakly / not identifiable, at bound) when the estimator
    gives them, else the ``not_identifiable`` list of ``details["identifiability"]``."""
    estimates = dict(getattr(result, "estimates", None) or {})
    if estimates:
        return {name: estimate.verdict for name, estimate in estimates.items()
                if estimate.verdict != "identifiable"}
    info = dict(result.details.get("identifiability") or {})
    return {k: "not identifiable: " + str(v) for k, v in dict(info.get("not_identifiable")
                                                             or {}).items()}


def _errors(parameters: Mapping[str, float], truth: Mapping[str, float], free) -> dict:
    out = {}
    for name in free:
        error = parameters[name] - truth[name]
        out[name] = abs(error) if name in ABSOLUTE else abs(error) / abs(truth[name])
    return out


def _fit_record(result, truth, free, reference_cost: float, started: float) -> dict:
    cost = float(result.details.get("cost", math.nan))
    return {
        "fit_percent": {k: float(v) for k, v in result.fit.items()},
        "cost": cost,
        "parameters": {n: float(result.parameters[n]) for n in free},
        "errors": _errors(result.parameters, truth, free),
        "claims_global": claimed_global(result),
        "reached_global": bool(cost <= reference_cost * (1.0 + GLOBAL_TOLERANCE)),
        "cost_excess": cost / reference_cost - 1.0 if reference_cost > 0 else math.nan,
        "at_bounds": list(result.details.get("at_bounds", [])),
        "not_identifiable": not_identifiable(result),
        "success": bool(result.success), "message": result.message,
        "evaluations": int(result.n_evaluations),
        "wall_time_s": time.perf_counter() - started,
    }


def run_case(case: Case, estimators: tuple[str, ...]) -> dict:
    """Every fit of one case; the record written to the JSON."""
    from panto.identification.estimation.base import fit_percent
    from panto.identification.estimation.least_squares import fit_least_squares
    from panto.identification.structures.registry import build_structure
    import plants

    started = time.perf_counter()
    data, truth, notes = case_data(case)
    structure = build_structure(plants.STRUCTURE_OF_FAMILY[case.family], data, {})
    free = tuple(structure.default_free())
    truth = {n: float(truth[n]) for n in structure.parameter_names if n in truth}
    truth_fit = fit_percent(data.outputs, structure.simulate(truth, data)[
        :, [structure.output_names.index(o) for o in data.output_names]])
    record: dict[str, Any] = {
        "case": case.label, "family": case.family, "excitation": case.excitation,
        "seed": case.seed, "structure": structure.name, "notes": notes, "truth": truth,
        "free": list(free), "samples": len(data), "data_time_s": time.perf_counter() - started,
        "truth_fit_percent": dict(zip(data.output_names, np.atleast_1d(truth_fit).tolist()))}
    clock = time.perf_counter()
    reference = fit_least_squares(structure, data, free=free, initial={n: truth[n] for n in free})
    reference_cost = float(reference.details.get("cost", math.nan))
    record["truth_started"] = _fit_record(reference, truth, free, reference_cost, clock)
    record["cannot_hold"] = record["truth_started"]["not_identifiable"]
    for name in estimators:
        clock = time.perf_counter()
        try:
            result = ESTIMATORS[name](structure, data, free)
            record[name] = _fit_record(result, truth, free, reference_cost, clock)
        except Exception as error:  # a failed fit is a result of the benchmark, listed
            record[name] = {"error": f"{type(error).__name__}: {error}",
                            "wall_time_s": time.perf_counter() - clock, "reached_global": False}
    record["wall_time_s"] = time.perf_counter() - started
    return record


# --- the grid and the summary -----------------------------------------------------------------

def grid(arguments: argparse.Namespace) -> list[Case]:
    """The cases to run (`--quick`: one per family, shortened)."""
    import plants

    if arguments.quick:
        return [Case("two-mass", "aprbs", 0, arguments.snr, 20.0),
                Case("three-mass", "multisine", 0, arguments.snr, 20.0),
                Case("pantograph", "aprbs", 0)]
    cases = []
    first = arguments.first_seed
    for k in range(max(arguments.seeds, arguments.pantograph_seeds)):  # every family early
        seed = first + k
        for excitation in plants.EXCITATIONS:
            if k < arguments.seeds:
                cases += [Case(family, excitation, seed, arguments.snr)
                          for family in ("two-mass", "three-mass")]
            if k < arguments.pantograph_seeds:
                cases.append(Case("pantograph", excitation, seed))
    return cases


def summarise(records: list[dict], estimators: tuple[str, ...]) -> dict:
    """Per structure and estimator: fraction at the global optimum, recovery errors of the
    parameters the data holds (median, max) and of all free parameters (the unfiltered max)."""
    summary: dict[str, Any] = {}
    for structure in sorted({r["structure"] for r in records}):
        rows = [r for r in records if r["structure"] == structure]
        for name in ("truth_started",) + estimators:
            fits = [(r, r[name]) for r in rows if name in r and "errors" in r[name]]
            held, every, absolute = [], [], []
            for r, fit in fits:
                for p, e in fit["errors"].items():
                    if p in ABSOLUTE:
                        absolute.append(e)
                        continue
                    every.append(e)
                    if p not in r["cannot_hold"]:
                        held.append(e)
            claims = [fit["claims_global"] for _, fit in fits if fit["claims_global"] is not None]
            summary[f"{structure} / {name}"] = {
                "runs": len(rows), "failed": len(rows) - len(fits),
                "fraction_global": (sum(f["reached_global"] for _, f in fits) / len(rows)
                                    if rows else math.nan),
                "fraction_claimed_global": sum(claims) / len(claims) if claims else None,
                "claims_right": (sum(c == f["reached_global"] for _, f in fits
                                     if (c := f["claims_global"]) is not None) / len(claims)
                                 if claims else None),
                "median_error_identifiable": float(np.median(held)) if held else math.nan,
                "max_error_identifiable": float(np.max(held)) if held else math.nan,
                "fraction_within_10pct_identifiable": (float(np.mean(np.array(held) <= 0.1))
                                                       if held else math.nan),
                "max_error_all": float(np.max(every)) if every else math.nan,
                "max_abs_error_y_cb_offset_mm": 1e3 * max(absolute) if absolute else None,
                "median_wall_time_s": float(np.median([f["wall_time_s"] for _, f in fits]))
                if fits else math.nan,
            }
    return summary


# --- output -----------------------------------------------------------------------------------

def _pct(value: float) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{100 * value:.1f} %"


def markdown(report: dict) -> str:
    """The report as a page: summary, then every case."""
    estimators = report["estimators"]
    lines = ["# Identification recovery benchmark", "",
             f"Run {report['date']} on {report['machine']} (load {report['load']}), "
             f"{report['wall_time_s']:.0f} s in all"
             f"{'' if report['complete'] else ' (INCOMPLETE: still running or stopped)'}. "
             f"Estimators: {', '.join(estimators)}"
             f"{'' if report['global_fit_available'] else ' (global_fit.py not available yet)'}. "
             f"Oscillator SNR {report['snr_db']:g} dB. Seeds from {report.get('first_seed', 0)}"
             f"{' (a held-out split: never looked at while tuning)' if report.get('first_seed') else ''}"
             ". Generated by "
             "`benchmarks/identification_recovery.py`; the plants are in `benchmarks/plants.py` "
             "(the pantograph family comes from the virtual test bed and is not independent of "
             "the model).", "",
             "Global optimum: cost within 0.1 % of the fit started at the truth. Identifiable: "
             "verdict \"identifiable\" in the truth-started fit (`result.estimates`); the "
             "others (weakly / not identifiable) are listed per case and counted only in "
             "\"max error, all\".", "",
             "## Summary", "",
             "| structure / fit | runs | failed | at global optimum | says global (right) | "
             "median error, identifiable | max error, identifiable | within 10 % | "
             "max error, all | y_cb_offset max abs [mm] | median time [s] |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for key, s in report["summary"].items():
        said = "-" if s["fraction_claimed_global"] is None else \
            f"{_pct(s['fraction_claimed_global'])} ({_pct(s['claims_right'])})"
        offset = "-" if s["max_abs_error_y_cb_offset_mm"] is None else \
            f"{s['max_abs_error_y_cb_offset_mm']:.3f}"
        lines.append(f"| {key} | {s['runs']} | {s['failed']} | {_pct(s['fraction_global'])} | "
                     f"{said} | {_pct(s['median_error_identifiable'])} | "
                     f"{_pct(s['max_error_identifiable'])} | "
                     f"{_pct(s['fraction_within_10pct_identifiable'])} | "
                     f"{_pct(s['max_error_all'])} | {offset} | {s['median_wall_time_s']:.1f} |")
    lines += ["", "## Every case", ""]
    for r in report["cases"]:
        floor = ", ".join(f"{k} {v:.2f}" for k, v in r["truth_fit_percent"].items())
        lines += [f"### {r['case']} ({r['structure']}, {r['samples']} samples, "
                  f"{r['wall_time_s']:.1f} s)", "",
                  f"Truth's fit [%]: {floor}. Not held by the data (truth-started fit's verdicts): "
                  f"{', '.join(f'{k} ({v})' for k, v in sorted(r['cannot_hold'].items())) or 'none'}"
                  ".", "",
                  "| fit | fit [%] | cost / truth-started - 1 | global | says | "
                  "max error, identifiable | at bounds | time [s] | message |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for name in ("truth_started",) + tuple(estimators):
            f = r.get(name)
            if f is None:
                continue
            if "error" in f:
                lines.append(f"| {name} | failed | | no | | | | {f['wall_time_s']:.1f} | "
                             f"{f['error']} |")
                continue
            held = [e for p, e in f["errors"].items()
                    if p not in r["cannot_hold"] and p not in ABSOLUTE]
            fits = ", ".join(f"{v:.2f}" for v in f["fit_percent"].values())
            lines.append(f"| {name} | {fits} | {f['cost_excess']:.2e} | "
                         f"{'yes' if f['reached_global'] else 'no'} | "
                         f"{'-' if f['claims_global'] is None else f['claims_global']} | "
                         f"{_pct(max(held) if held else math.nan)} | "
                         f"{', '.join(f['at_bounds']) or '-'} | {f['wall_time_s']:.1f} | "
                         f"{f['message']} |")
        names = r["free"]
        lines += ["", "| parameter | truth | " + " | ".join(
            n for n in ("truth_started",) + tuple(estimators) if "errors" in r.get(n, {}))
            + " |", "|---|---|" + "---|" * sum("errors" in r.get(n, {}) for n in
                                               ("truth_started",) + tuple(estimators))]
        for p in names:
            cells = []
            for name in ("truth_started",) + tuple(estimators):
                f = r.get(name, {})
                if "errors" not in f:
                    continue
                e = f["errors"][p]
                cells.append(f"{f['parameters'][p]:.5g} ({1e3 * e:.3f} mm)" if p in ABSOLUTE
                             else f"{f['parameters'][p]:.5g} ({100 * e:.1f} %)")
            mark = " (not held)" if p in r["cannot_hold"] else ""
            lines.append(f"| {p}{mark} | {r['truth'][p]:.5g} | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Run the grid, write the JSON and the page."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="one short case per family (smoke)")
    parser.add_argument("--fit", nargs="+", choices=sorted(ESTIMATORS), default=["default"])
    parser.add_argument("--seeds", type=int, default=2, help="oscillator seeds per excitation")
    parser.add_argument("--pantograph-seeds", type=int, default=1)
    parser.add_argument("--first-seed", type=int, default=0,
                        help="first seed (a held-out split: seeds never looked at while tuning, "
                             "e.g. 1000)")
    parser.add_argument("--snr", type=float, default=30.0, help="oscillator outputs' SNR [dB]")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--out", default=str(HERE / "identification_recovery"),
                        help="output path without suffix")
    parser.add_argument("--resume", action="store_true",
                        help="keep the cases already in the output JSON (same estimators)")
    parser.add_argument("--quiet", action="store_true")
    arguments = parser.parse_args(argv)
    estimators = tuple(arguments.fit)
    if "global" in estimators and not global_fit_available():
        say("global_fit.py does not exist yet: the 'global' estimator is left out")
        estimators = tuple(e for e in estimators if e != "global")
    cases = grid(arguments)
    started = time.perf_counter()
    records = previous_records(Path(arguments.out), cases, estimators) if arguments.resume else []
    done = {r["case"] for r in records}
    cases = [case for case in cases if case.label not in done]
    if arguments.workers > 1:
        pool = ProcessPoolExecutor(arguments.workers)
        results = (f.result() for f in [pool.submit(run_case, case, estimators) for case in cases])
    else:
        pool, results = None, (run_case(case, estimators) for case in cases)
    out = Path(arguments.out)
    for i, record in enumerate(results, 1):
        records.append(record)
        verdicts = ", ".join(f"{n}: {'global' if record[n].get('reached_global') else 'LOCAL'}"
                             for n in estimators)
        say(f"[{len(records)}/{len(cases) + len(done)}] {record['case']}: {verdicts} "
            f"({record['wall_time_s']:.1f} s)", arguments.quiet)
        write_report(out, records, estimators, arguments, started, complete=i == len(cases))
    if pool is not None:
        pool.shutdown()
    say(f"wrote {out.with_suffix('.json')} and {out.with_suffix('.md')}", arguments.quiet)
    return 0


def previous_records(out: Path, cases: list[Case], estimators: tuple[str, ...]) -> list[dict]:
    """The records of `cases` already in ``out.json`` with every estimator asked for."""
    path = out.with_suffix(".json")
    if not path.exists():
        return []
    labels = {case.label for case in cases}
    kept = [r for r in json.loads(path.read_text())["cases"]
            if r["case"] in labels and all(e in r for e in estimators)]
    say(f"resuming: {len(kept)} case(s) kept from {path}")
    return kept


def write_report(out: Path, records: list[dict], estimators: tuple[str, ...],
                 arguments: argparse.Namespace, started: float, complete: bool) -> None:
    """Write the JSON and the page for the cases run so far (after every case)."""
    report = {
        "date": time.strftime("%Y-%m-%d %H:%M"), "machine": platform.platform(),
        "cpus": os.cpu_count(), "load": [round(x, 2) for x in os.getloadavg()],
        "estimators": list(estimators), "global_fit_available": global_fit_available(),
        "snr_db": arguments.snr, "quick": arguments.quick, "complete": complete,
        "first_seed": getattr(arguments, "first_seed", 0),
        "global_tolerance": GLOBAL_TOLERANCE, "wall_time_s": time.perf_counter() - started,
        "summary": summarise(records, estimators), "cases": records}
    out.with_suffix(".json").write_text(json.dumps(report, indent=1, default=_plain))
    out.with_suffix(".md").write_text(markdown(report))


def _plain(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


if __name__ == "__main__":
    raise SystemExit(main())
