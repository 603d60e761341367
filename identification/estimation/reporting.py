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
- ``fit.png``: measured against simulated (free run) per output, training and validation.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from panto.identification.estimation.base import IdentificationData, IdentificationResult
from panto.identification.estimation.plots import plot_fit

def write_identification(result: IdentificationResult, folder: str | Path, *,
                         data: IdentificationData,
                         validation: IdentificationData | None = None,
                         nominal: Mapping[str, float] | None = None,
                         parameter_set: str | None = None) -> dict[str, Path]:
    """Write the parameter file, the result summary and the plot; returns their paths.

    `parameter_set` is the fmu_src model whose parameter file the result fills (``"Pantograph"``;
    :func:`panto.identification.structures.registry.parameter_set` of the structure), None for
    plain JSON.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = {"parameters": write_parameters(result, folder / "parameters.json",
                                            parameter_set=parameter_set),
             "result": folder / "result.json", "plot": folder / "fit.png",
             "summary": folder / "summary.md"}
    summary = result_summary(result, data=data, validation=validation, nominal=nominal)
    paths["result"].write_text(json.dumps(summary, indent=2, default=_plain) + "\n")
    paths["summary"].write_text(markdown_summary(result, summary))
    plot_fit(result, data, paths["plot"], validation=validation)
    return paths


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
                   nominal: Mapping[str, float] | None = None) -> dict[str, Any]:
    """The machine-readable summary of `result` (what ``result.json`` holds)."""
    intervals = result.details.get("intervals_95", {})
    rows = {}
    for name, value in result.parameters.items():
        row: dict[str, Any] = {"value": value, "free": name in result.free}
        if name in result.free:
            row.update(std=result.std.get(name), interval_95=intervals.get(name))
        if name in result.estimates:
            row.update({k: v for k, v in result.estimates[name].to_dict().items()
                        if k != "name"})
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
    return summary


def parameter_table(result: IdentificationResult) -> str:
    """The fitted parameters as a markdown table: value, unit, +- (1 sigma), 95 % interval,
    verdict and status (estimated, at a bound, fixed at prior), correlated group."""
    lines = ["| parameter | value | unit | ± (1 σ) | 95 % interval | verdict | status | group |",
             "|---|---|---|---|---|---|---|---|"]
    for name, e in result.estimates.items():
        low, high = e.interval_95
        interval = f"[{low:.4g}, {high:.4g}]" if math.isfinite(low) and math.isfinite(high) \
            else "—"
        std = f"{e.std:.3g}" if math.isfinite(e.std) else "—"
        lines.append(f"| {name} | {e.value:.5g} | {e.unit} | {std} | {interval} | {e.verdict} | "
                     f"{e.status} | {', '.join(e.group) or '—'} |")
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
