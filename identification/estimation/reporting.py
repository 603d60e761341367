"""Files a person opens after an identification: parameters, result summary, plots.

:func:`write_identification` writes into one folder

- ``parameters.json``: for a structure of an fmu_src model (``parameter_set``, which the table of
  structures, :func:`panto.identification.structures.registry.parameter_set`, names) that model's
  parameter file (every model parameter, the identified ones with their provenance) that
  ``panto linearise --parameters`` and the FMU build accept; for other structures the plain values;
- ``result.json``: structure, method, fit per output (training and validation), parameters with
  unit, standard deviation, 95 % interval, verdict (identifiable / weakly / not, at a bound, fixed
  at prior), correlated group and nominal value, identifiability (with the rule and its
  thresholds), wall time, evaluations, success and message;
- ``summary.md``: the same as a table a person reads (:func:`parameter_table`), with the fits and
  what was fixed or hit a bound, and why;
- ``fit.png``: measured against simulated (free run) per output, training and validation;
  ``fit_training.csv`` and ``fit_validation.csv`` hold the same series as numbers;
- ``report.html``: the fits, the parameter table and the plot as a page
  (:mod:`panto.templating`). Intervals respect the sign (:func:`sign_respecting_interval`):
  log-normal for a parameter optimised on its logarithm, clipped at a lower bound of zero with
  a note, and a mark on every parameter at a bound, fixed at its prior or not identifiable.

On request (``correlations=True``, ``panto identify --correlations``) the correlation matrix of
the estimates (:func:`~panto.identification.estimation.correlations.parameter_correlations`)
joins ``result.json`` (``correlations``), ``summary.md`` and ``report.html``.
"""
from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from panto.identification.estimation.base import IdentificationData, IdentificationResult
from panto.identification.estimation.correlations import (correlation_blocks, correlation_table,
                                                          parameter_correlations)
from panto.identification.estimation.plots import plot_fit

def write_identification(result: IdentificationResult, folder: str | Path, *,
                         data: IdentificationData,
                         validation: IdentificationData | None = None,
                         nominal: Mapping[str, float] | None = None,
                         parameter_set: str | None = None,
                         correlations: bool = False) -> dict[str, Path]:
    """Write the parameter file, the result summary and the plot; returns their paths.

    `parameter_set` is the fmu_src model whose parameter file the result fills (``"Pantograph"``;
    :func:`panto.identification.structures.registry.parameter_set` of the structure), None for
    plain JSON. `correlations` adds the estimates' correlation matrix
    (:func:`parameter_correlations`) to ``result.json``, ``summary.md`` and ``report.html``.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = {"parameters": write_parameters(result, folder / "parameters.json",
                                            parameter_set=parameter_set),
             "result": folder / "result.json", "plot": folder / "fit.png",
             "summary": folder / "summary.md", "html": folder / "report.html"}
    summary = result_summary(result, data=data, validation=validation, nominal=nominal,
                             correlations=correlations)
    paths["result"].write_text(json.dumps(summary, indent=2, default=_plain) + "\n")
    paths["summary"].write_text(markdown_summary(result, summary))
    result = replace(result, simulator=_SimulateOnce(result.simulator))  # plot and table
    plot_fit(result, data, paths["plot"], validation=validation)
    for label, run in (("training", data), ("validation", validation)):
        if run is not None and write_fit_series(result, run, folder / f"fit_{label}.csv"):
            paths[f"series_{label}"] = folder / f"fit_{label}.csv"
    paths["html"].write_text(html_report(result, summary, paths["plot"]), encoding="utf-8")
    return paths


class _SimulateOnce:
    """A simulator that runs once per data set (the plot and the CSV table share the run)."""

    def __init__(self, simulator: Any) -> None:
        self.simulator, self.runs = simulator, {}

    def __call__(self, data: IdentificationData) -> np.ndarray:
        if id(data) not in self.runs:
            self.runs[id(data)] = (data, self.simulator(data))  # data kept: its id stays unique
        return self.runs[id(data)][1]


def write_fit_series(result: IdentificationResult, data: IdentificationData,
                     path: str | Path) -> bool:
    """Measured and simulated (free run) outputs of `data` over time as a CSV table
    (``time [s]``, ``<output>_measured [unit]``, ``<output>_simulated [unit]``); False (and
    no file) when the identified model cannot be simulated on `data`."""
    import pandas as pd

    names = [o for o in result.fit if o in data.output_names]
    try:
        simulated = np.asarray(result.simulate(data), float)
    except (ValueError, ArithmeticError, RuntimeError):
        return False
    columns = {"time [s]": np.asarray(data.time, float)}
    for j, name in enumerate(names):
        unit = data.units.get(name, "-") or "-"
        columns[f"{name}_measured [{unit}]"] = data.output(name)
        columns[f"{name}_simulated [{unit}]"] = simulated[:, j]
    pd.DataFrame(columns).to_csv(path, index=False)
    return True


def html_report(result: IdentificationResult, summary: Mapping[str, Any],
                plot: Path | None = None) -> str:
    """``report.html``: fits, the parameter table with marks and honest intervals, the notes
    and the plot (the one look of :mod:`panto.templating`)."""
    from panto import templating as t

    fits = "; ".join(f"{k} {v:.1f} %" for k, v in result.fit.items())
    blocks = [t.paragraph(result.message), t.paragraph(f"Fit on training: {fits}.")]
    validation = (summary.get("validation") or {}).get("fit_percent") or {}
    if validation and "error" not in validation:
        blocks.append(t.paragraph("Fit on validation: " + "; ".join(
            f"{k} {v:.1f} %" for k, v in validation.items()) + "."))
    records = parameter_records(result)
    blocks += parameter_blocks(records, (result.details.get("identifiability") or {}).get("rule"))
    if summary.get("correlations"):
        blocks += correlation_blocks(summary["correlations"])
    if plot is not None:
        blocks.append(t.figure(plot, "measured (grey) and simulated (black), free run"))
    return t.render("sections.html.j2", title=f"Identification: {result.structure} "
                    f"({result.method})", written="", head=[],
                    sections=[{"title": "Result", "blocks": blocks}])


def parameter_blocks(records: list[Mapping[str, Any]], rule: str | None = None) -> list[dict]:
    """Report blocks (:mod:`panto.templating`) of :func:`parameter_records`: the table (value,
    unit, standard deviation, the sign-respecting 95 % interval, mark) and its notes."""
    from panto import templating as t

    rows, notes = [], []
    for r in records:
        if "interval_shown" in r:
            (low, high), note = r["interval_shown"], r.get("interval_note") or ""
        else:  # a record of ParameterEstimate.to_dict
            low, high, note = sign_respecting_interval(
                r["value"], r.get("interval_95"), logarithmic=bool(r.get("logarithmic")),
                lower_bound=r.get("lower_bound"))
        interval = interval_text(math.nan if low is None else low,
                                 math.nan if high is None else high)
        if note and not r.get("logarithmic"):
            notes.append(f"{r['name']}: {note}")
            interval += f" ({len(notes)})"
        mark = r.get("mark", parameter_mark(r))
        rows.append([r["name"], t.format_number(r["value"], 5), r.get("unit") or "-",
                     t.format_number(r.get("std"), 3), interval,
                     t.cell(mark or "identifiable", "mark" if mark else "ok"),
                     ", ".join(r.get("group") or ()) or "–"])
    blocks = [t.table(("parameter", "value", "unit", "± (1 σ)", "95 % interval", "verdict",
                       "correlated group"), rows)]
    blocks += [t.paragraph(f"({k}) {note}", "note") for k, note in enumerate(notes, 1)]
    reasons = [f"{r['name']}: {r['reason']}" for r in records if r.get("reason")]
    if reasons:
        blocks.append(t.paragraph("Why: " + "; ".join(reasons) + ".", "note"))
    blocks.append(t.paragraph("95 % intervals: log-normal for parameters optimised as "
                              "logarithms (positive), normal otherwise, never below a lower "
                              "bound of zero." + (f" Verdicts: {rule}." if rule else ""), "note"))
    return blocks


def write_parameters(result: IdentificationResult, path: str | Path, *,
                     parameter_set: str | None = None) -> Path:
    """The identified parameters as the parameter file of fmu_src model `parameter_set` (which
    the FMUs accept), or plain JSON when it is None."""
    path = Path(path)
    if parameter_set is not None:
        from panto.fmu_src.models import default_parameters

        defaults = default_parameters(parameter_set)
        values = {k: v for k, v in result.parameters.items() if k in defaults.names}
        content = defaults.with_values(values).to_dict()
        for name in result.free:
            entry = content["parameters"][name]
            entry["provenance"] = (f"identified ({result.structure}, {result.method}); std "
                                   f"{result.std.get(name, math.nan):.4g} {entry['unit']}")
        for name, estimate in result.estimates.items():
            if name in content["parameters"] and (estimate.fixed or estimate.at_bound):
                content["parameters"][name]["provenance"] = (
                    f"{estimate.status} ({result.structure}, {result.method}): {estimate.reason}")
        content["identification"] = {"structure": result.structure, "fit": dict(result.fit)}
    else:
        content = {"model": result.structure,
                   "parameters": {k: {"value": v} for k, v in result.parameters.items()}}
    path.write_text(json.dumps(content, indent=2, default=_plain) + "\n")
    return path


def result_summary(result: IdentificationResult, *, data: IdentificationData,
                   validation: IdentificationData | None = None,
                   nominal: Mapping[str, float] | None = None,
                   correlations: bool = False) -> dict[str, Any]:
    """The machine-readable summary of `result` (what ``result.json`` holds); `correlations`
    adds ``correlations`` (:func:`parameter_correlations`)."""
    intervals = result.details.get("intervals_95", {})
    records = {r["name"]: r for r in parameter_records(result)}
    rows = {}
    for name, value in result.parameters.items():
        row: dict[str, Any] = {"value": value, "free": name in result.free}
        if name in result.free:
            row.update(std=result.std.get(name), interval_95=intervals.get(name))
        if name in records:
            row.update({k: v for k, v in records[name].items() if k != "name"})
        if nominal and name in nominal:
            row["nominal"] = nominal[name]
        rows[name] = row
    summary: dict[str, Any] = {
        "structure": result.structure, "method": result.method, "success": result.success,
        "message": result.message, "wall_time_s": result.wall_time,
        "evaluations": result.n_evaluations, "n_free": result.n_free,
        "training": {"source": data.source, "samples": len(data), "fit_percent": dict(result.fit)},
        "parameters": rows,
        "identifiability": result.details.get("identifiability"),
        "fixed_at_prior": result.details.get("fixed_at_prior", {}),
        "first_fit": _first_fit(result),
        "residual_std": result.details.get("residual_std"),
    }
    if "global_fit" in result.details:  # fit_global's verdict and its starts
        summary["global_fit"] = result.details["global_fit"]
    if "adequacy" in result.details:  # the nominal beside a black box of its order
        summary["adequacy"] = result.details["adequacy"]
    if validation is not None:
        summary["validation"] = {"source": validation.source, "samples": len(validation),
                                 "fit_percent": _validation_fit(result, validation)}
    if correlations:
        summary["correlations"] = parameter_correlations(result)
    return summary


def sign_respecting_interval(value: float, interval: Any, *, logarithmic: bool = False,
                             lower_bound: float | None = None) -> tuple[float, float, str]:
    """The 95 % interval a report shows: never below a parameter's lower bound of zero.

    Parameters
    ----------
    value : float
        The estimate.
    interval : pair of float or None
        The estimator's interval (:attr:`ParameterEstimate.interval_95`): log-normal,
        ``theta exp(+-1.96 sigma_z)``, for a log-parameterised (positive) parameter, else
        ``theta +- 1.96 sigma``; None or NaN when there is none (at a bound, fixed).
    logarithmic : bool
        The parameter was optimised as ``ln theta`` (positive lower bound).
    lower_bound : float, optional
        The parameter's lower bound in the fit (None: unknown).

    Returns
    -------
    low, high : float
        The interval shown (NaN when there is none).
    note : str
        Empty for an interval shown as estimated; otherwise what was done to it: a normal
        interval of a parameter that cannot be negative (lower bound 0) is clipped at 0 with
        the note naming where it reached; a normal interval of a positive estimate that
        reaches below zero without a known bound says that the sign is not established.
    """
    low, high = (math.nan, math.nan) if interval is None else (
        math.nan if v is None else float(v) for v in interval)
    if not (math.isfinite(low) and math.isfinite(high)):
        return math.nan, math.nan, ""
    if logarithmic:
        return low, high, "log-normal (the parameter is positive)"
    if lower_bound is not None and math.isfinite(lower_bound) and lower_bound >= 0.0 \
            and low < lower_bound:
        return (float(lower_bound), high, f"clipped at its lower bound {lower_bound:g} (the "
                f"normal interval reaches {low:.3g}; the parameter cannot be negative)")
    if value > 0.0 > low:
        return low, high, "reaches below zero: the sign is not established by the data"
    return low, high, ""


def parameter_records(result: IdentificationResult) -> list[dict[str, Any]]:
    """Per estimated parameter, what a report shows (JSON-ready, NaN as None).

    The fields of :meth:`ParameterEstimate.to_dict` plus ``lower_bound`` (the fit's),
    ``interval_shown`` (:func:`sign_respecting_interval`), ``interval_note`` and ``mark``: empty
    for an identifiable estimate, else ``at lower bound``, ``at upper bound``, ``fixed at
    prior``, ``not identifiable`` or ``weakly identifiable``.
    """
    bounds = result.details.get("bounds") or {}
    records = []
    for name, estimate in result.estimates.items():
        record = estimate.to_dict()
        lower = (bounds.get(name) or (None, None))[0]
        low, high, note = sign_respecting_interval(estimate.value, estimate.interval_95,
                                                   logarithmic=estimate.logarithmic,
                                                   lower_bound=lower)
        record.update(lower_bound=lower, interval_note=note, mark=parameter_mark(record),
                      interval_shown=[v if math.isfinite(v) else None for v in (low, high)])
        records.append(record)
    return records


def parameter_mark(record: Mapping[str, Any]) -> str:
    """The mark of a parameter record (:meth:`ParameterEstimate.to_dict`): empty when
    identifiable and estimated, else its status or verdict."""
    if record.get("fixed"):
        return "fixed at prior"
    if record.get("at_bound"):
        return f"at {record['at_bound']} bound"
    verdict = record.get("verdict", "identifiable")
    return "" if verdict == "identifiable" else verdict


def interval_text(low: Any, high: Any, digits: int = 4) -> str:
    """``low … high`` with `digits` significant digits, ``—`` without an interval."""
    if low is None or high is None or not (math.isfinite(low) and math.isfinite(high)):
        return "—"
    return f"{low:.{digits}g} … {high:.{digits}g}"


def parameter_table(result: IdentificationResult) -> str:
    """The fitted parameters as a markdown table: value, unit, +- (1 sigma), 95 % interval
    (:func:`sign_respecting_interval`, its note below the table), verdict and status
    (estimated, at a bound, fixed at prior), correlated group."""
    lines = ["| parameter | value | unit | ± (1 σ) | 95 % interval | verdict | status | group |",
             "|---|---|---|---|---|---|---|---|"]
    notes = []
    for record in parameter_records(result):
        interval = interval_text(*[math.nan if v is None else v
                                   for v in record["interval_shown"]])
        if record["interval_note"] and not record["logarithmic"]:
            notes.append(f"{record['name']}: {record['interval_note']}")
            interval += f" ({len(notes)})"
        std = f"{record['std']:.3g}" if record["std"] is not None else "—"
        lines.append(f"| {record['name']} | {record['value']:.5g} | {record['unit']} | {std} | "
                     f"{interval} | {record['verdict']} | {record['status']} | "
                     f"{', '.join(record['group']) or '—'} |")
    lines += [""] + [f"({k}) {note}" for k, note in enumerate(notes, 1)] if notes else []
    return "\n".join(lines) + "\n"


def markdown_summary(result: IdentificationResult, summary: Mapping[str, Any]) -> str:
    """``summary.md``: fits, the parameter table, why parameters were fixed or sit at a bound,
    and the rule of the verdicts."""
    fits = ", ".join(f"{k} {v:.2f} %" for k, v in result.fit.items())
    parts = [f"# {result.structure} ({result.method})", "", f"{result.message}", "",
             f"Fit on training: {fits}"]
    validation = (summary.get("validation") or {}).get("fit_percent") or {}
    if validation and "error" not in validation:
        parts.append("Fit on validation: " + ", ".join(f"{k} {v:.2f} %"
                                                        for k, v in validation.items()))
    adequacy = result.details.get("adequacy")
    if adequacy:
        parts.append(f"Adequacy ({adequacy['verdict']}): {adequacy['message']}")
    parts += ["", parameter_table(result) if result.estimates else "(no per-parameter estimates)"]
    notes = [f"- {n}: {e.status if e.fixed or e.at_bound else e.verdict}: {e.reason}"
             for n, e in result.estimates.items()
             if e.verdict != "identifiable" and e.reason]
    if notes:
        parts += ["Why:", ""] + notes + [""]
    rule = (result.details.get("identifiability") or {}).get("rule")
    if rule:
        parts += [f"Verdicts: {rule}.", ""]
    if summary.get("correlations"):
        parts += ["## Correlations of the estimates", "", correlation_table(
            summary["correlations"]), ""]
    return "\n".join(parts)


def _first_fit(result: IdentificationResult) -> dict[str, Any] | None:
    first = result.details.get("first_fit")
    if not first:
        return None
    return {"parameters": first["parameters"], "fit_percent": first["fit"],
            "message": first["message"]}


def _validation_fit(result: IdentificationResult, validation: IdentificationData) -> dict:
    names = [o for o in result.fit if o in validation.output_names]
    try:
        return result.fit_on(validation, names)
    except (ValueError, ArithmeticError, RuntimeError) as error:
        return {"error": str(error)}


def _plain(value: Any) -> Any:
    if hasattr(value, "to_dict"):
        return value.to_dict()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, tuple):
        return list(value)
    return str(value)
