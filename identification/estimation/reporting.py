"""Files a person opens after an identification: parameters, result summary, plots.

:func:`write_identification` writes into one folder

- ``parameters.json``: for the pantograph structures a :mod:`fmu_src` parameter file (every model
  parameter, the identified ones with their provenance) that ``panto linearise --parameters`` and
  the FMU build accept; for other structures the plain values;
- ``result.json``: structure, method, fit per output (training and validation), parameters with
  standard deviation, 95 % interval and nominal value, identifiability, wall time, evaluations,
  success and message;
- ``fit.png``: measured against simulated (free run) per output, training and validation.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from panto.identification.estimation.base import IdentificationData, IdentificationResult, fit_percent

#: Structures whose parameters are pantograph model parameters (fmu_src "Pantograph").
PANTOGRAPH_STRUCTURES = ("physical", "physical-linear")


def write_identification(result: IdentificationResult, folder: str | Path, *,
                         data: IdentificationData,
                         validation: IdentificationData | None = None,
                         nominal: Mapping[str, float] | None = None) -> dict[str, Path]:
    """Write the parameter file, the result summary and the plot; returns their paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = {"parameters": write_parameters(result, folder / "parameters.json"),
             "result": folder / "result.json", "plot": folder / "fit.png"}
    summary = result_summary(result, data=data, validation=validation, nominal=nominal)
    paths["result"].write_text(json.dumps(summary, indent=2, default=_plain) + "\n")
    plot_fit(result, data, paths["plot"], validation=validation)
    return paths


def write_parameters(result: IdentificationResult, path: str | Path) -> Path:
    """The identified parameters as a file the FMUs accept (pantograph) or plain JSON."""
    path = Path(path)
    if result.structure in PANTOGRAPH_STRUCTURES:
        from panto.fmu_src.models import default_parameters

        defaults = default_parameters("Pantograph")
        values = {k: v for k, v in result.parameters.items() if k in defaults.names}
        content = defaults.with_values(values).to_dict()
        for name in result.free:
            entry = content["parameters"][name]
            entry["provenance"] = (f"identified ({result.structure}, {result.method}); std "
                                   f"{result.std.get(name, math.nan):.4g} {entry['unit']}")
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
        "residual_std": result.details.get("residual_std"),
    }
    if validation is not None:
        summary["validation"] = {"source": validation.source, "samples": len(validation),
                                 "fit_percent": _validation_fit(result, validation)}
    return summary


def _validation_fit(result: IdentificationResult, validation: IdentificationData) -> dict:
    names = [o for o in result.fit if o in validation.output_names]
    try:
        return result.fit_on(validation, names)
    except (ValueError, ArithmeticError, RuntimeError) as error:
        return {"error": str(error)}


def plot_fit(result: IdentificationResult, data: IdentificationData, path: str | Path, *,
             validation: IdentificationData | None = None) -> Path:
    """Measured (grey) and simulated (black) free run per output; a column per data set."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sets = [("training", data)] + ([("validation", validation)] if validation is not None else [])
    outputs = [o for o in result.fit]
    fig, axes = plt.subplots(len(outputs), len(sets), figsize=(7 * len(sets), 2.6 * len(outputs)),
                             squeeze=False, sharex="col")
    for column, (label, d) in enumerate(sets):
        try:
            simulated = result.simulate(d)
        except (ValueError, ArithmeticError, RuntimeError):
            simulated = np.full((len(d), len(outputs)), np.nan)
        for row, name in enumerate(outputs):
            ax = axes[row, column]
            measured = d.output(name)
            fit = fit_percent(measured, simulated[:, row])
            ax.plot(d.time, measured, color="0.6", lw=0.8, label="measured")
            ax.plot(d.time, simulated[:, row], color="k", lw=0.8, label="simulated")
            ax.set_ylabel(f"{name} [{d.units.get(name, '')}]")
            ax.set_title(f"{label}: {name}, fit {fit:.1f} %", fontsize=9)
        axes[-1, column].set_xlabel("time [s]")
    axes[0, 0].legend(loc="upper right", fontsize=8)
    fig.suptitle(f"{result.structure} ({result.method}), free run", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def _plain(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, tuple):
        return list(value)
    return str(value)
