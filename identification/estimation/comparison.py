"""The comparison of model structures (thesis section 4.8, its table).

Every structure is fitted on the training run (thesis: APRBS on both inputs) by its
:class:`~panto.identification.estimation.base.Identifier` (the caller takes them from the table of
structures, :func:`panto.identification.structures.registry.comparison_identifiers`) and then simulated in free run on the validation run
(thesis: ramps). The table holds, per structure: the number of free parameters, the fit [%] per
output on training and on validation, the time taken, and whether it succeeded. A structure that
fails is a row with its message; the others are not lost.

Thesis Table (section 4.8), fit on the force: physical (linearised) 13 parameters, 44.7 / 84.0 %;
black box 6 states 35.9 / 69 %; black box 4 states 45.8 / 63.1 %; three-mass with friction 13.0 /
83.7 %; three-mass 15.1 / 76.8 %; two-mass with friction 11.4 / 21.1 %; two-mass 10.6 / -76 %.

Examples
--------
>>> chosen = comparison_identifiers()                                       # doctest: +SKIP
>>> table = compare_structures(train, validation, structures=chosen, executor=pool)  # doctest: +SKIP
>>> print(table.to_markdown())                                              # doctest: +SKIP
>>> from panto.identification.estimation.plots import plot_comparison        # doctest: +SKIP
>>> plot_comparison(table, "comparison.png")                                # doctest: +SKIP
"""
from __future__ import annotations

import csv
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from panto.identification.estimation.base import (IdentificationData, IdentificationError, IdentificationResult,
                                 Identifier, fit_percent)

Progress = Callable[[str], None]


@dataclass(frozen=True, eq=False)
class ComparisonRow:
    """One structure's line of the table.

    Attributes
    ----------
    structure : str
    n_free : int or None
        Number of estimated parameters (None when the fit failed before saying).
    fit_training, fit_validation : dict of str to float
        Fit [%] per output (free run); NaN where not available.
    wall_time : float
        Seconds for the identification (validation run excluded).
    success : bool
    message : str
    method : str
    result : IdentificationResult or None
        The identified model (for plots and parameter files); None on failure.
    """

    structure: str
    n_free: int | None
    fit_training: Mapping[str, float]
    fit_validation: Mapping[str, float]
    wall_time: float
    success: bool
    message: str
    method: str = ""
    result: IdentificationResult | None = field(default=None, repr=False)

    def score(self, output: str | None = None, on: str = "validation") -> float:
        """The fit on one output, or the mean over the outputs, on "validation" or "training"."""
        fits = self.fit_validation if on == "validation" else self.fit_training
        values = [fits.get(output, math.nan)] if output else list(fits.values())
        values = [v for v in values if math.isfinite(v)]
        return float(np.mean(values)) if values and (output is None or len(values) == 1) \
            else math.nan


@dataclass(frozen=True, eq=False)
class ComparisonTable:
    """The structures' comparison (thesis section 4.8).

    Attributes
    ----------
    rows : tuple of ComparisonRow
        In the order the structures were fitted.
    outputs : tuple of str
        Outputs whose fit is reported.
    training, validation : str
        Where the two data sets came from.
    """

    rows: tuple[ComparisonRow, ...]
    outputs: tuple[str, ...]
    training: str = ""
    validation: str = ""

    def row(self, structure: str) -> ComparisonRow:
        """The row of one structure."""
        for row in self.rows:
            if row.structure == structure:
                return row
        raise KeyError(f"{structure!r} is not in the table ({[r.structure for r in self.rows]})")

    def ranking(self, output: str | None = None, on: str = "validation") -> list[str]:
        """Structures from the best to the worst fit (mean over outputs unless `output`);
        failed or unscored ones last."""
        def key(row: ComparisonRow) -> float:
            score = row.score(output, on)
            return -score if math.isfinite(score) else math.inf
        return [row.structure for row in sorted(self.rows, key=key)]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: one entry per row (no models), plus the data sources and the ranking."""
        return {"training": self.training, "validation": self.validation,
                "outputs": list(self.outputs), "ranking_validation": self.ranking(),
                "rows": [{"structure": r.structure, "n_free": r.n_free, "method": r.method,
                          "fit_training": _clean(r.fit_training),
                          "fit_validation": _clean(r.fit_validation),
                          "wall_time_s": r.wall_time, "success": r.success,
                          "message": r.message} for r in self.rows]}

    def write_json(self, path: str | os.PathLike) -> str | os.PathLike:
        """Write :meth:`to_dict` to `path`."""
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")
        return path

    def to_csv(self, path: str | os.PathLike) -> str | os.PathLike:
        """One line per structure: fits per output on training and validation, time, status."""
        columns = (["structure", "n_free"] + [f"fit_training_{o}_percent" for o in self.outputs]
                   + [f"fit_validation_{o}_percent" for o in self.outputs]
                   + ["wall_time_s", "success", "method", "message"])
        with open(path, "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(columns)
            for r in self.rows:
                writer.writerow([r.structure, "" if r.n_free is None else r.n_free]
                                + [_cell(r.fit_training.get(o)) for o in self.outputs]
                                + [_cell(r.fit_validation.get(o)) for o in self.outputs]
                                + [f"{r.wall_time:.3f}", r.success, r.method, r.message])
        return path

    def to_markdown(self) -> str:
        """The thesis-style table: structure, free parameters, fit training, fit validation, time."""
        header = (["structure", "free"] + [f"fit training {o} [%]" for o in self.outputs]
                  + [f"fit validation {o} [%]" for o in self.outputs] + ["time [s]", "status"])
        lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        for r in self.rows:
            status = "ok" if r.success else f"failed: {r.message}".replace("|", "/")[:120]
            cells = ([r.structure, "-" if r.n_free is None else str(r.n_free)]
                     + [_cell(r.fit_training.get(o), "-") for o in self.outputs]
                     + [_cell(r.fit_validation.get(o), "-") for o in self.outputs]
                     + [f"{r.wall_time:.1f}", status])
            lines.append("| " + " | ".join(cells) + " |")
        return "\n".join(lines)


def _clean(fits: Mapping[str, float]) -> dict[str, float | None]:
    return {k: (float(v) if math.isfinite(v) else None) for k, v in fits.items()}


def _cell(value: float | None, missing: str = "") -> str:
    return f"{value:.1f}" if value is not None and math.isfinite(value) else missing


def compare_structures(train: IdentificationData, validation: IdentificationData, *,
                       structures: Sequence[Identifier],
                       executor: Any = None, progress: Progress | None = None,
                       options: Mapping[str, Mapping[str, Any]] | None = None,
                       outputs: Sequence[str] | None = None) -> ComparisonTable:
    """Fit every structure on `train`, validate it on `validation`: the thesis' table (4.8).

    Parameters
    ----------
    train, validation : IdentificationData
        Training run (APRBS) and validation run (ramps), same inputs and outputs.
    structures : sequence of Identifier
        The structures to fit, e.g.
        :func:`panto.identification.structures.registry.comparison_identifiers` (the thesis' table).
    executor : concurrent.futures.Executor or dask.distributed.Client, optional
        Passed to each identifier (its populations, Jacobian columns, multistarts).
    progress : callable, optional
        Lines from this function and, prefixed with the structure, from the identifiers.
    options : mapping of structure name to mapping, optional
        Keyword options per structure for its ``identify`` (``free``, ``method``, ...).
    outputs : sequence of str, optional
        Outputs to report (default those of the training data also in the validation data).

    Returns
    -------
    ComparisonTable
        A failing structure is a row with ``success`` False and the reason.
    """
    outputs = tuple(outputs or [o for o in train.output_names if o in validation.output_names])
    if not outputs:
        raise IdentificationError(f"{train.source or 'training'} and "
                                  f"{validation.source or 'validation'} share no output")
    chosen = list(structures)
    strays = [s for s in chosen if not isinstance(s, Identifier)]
    if strays:
        raise IdentificationError(f"structures {strays} are not Identifier records (name them "
                                  "through panto.identification.structures.registry)")
    known = {i.name for i in chosen}
    stray = sorted(set(options or {}) - known)
    if stray:
        raise IdentificationError(f"options for structures not compared: {stray} "
                                  f"(compared: {sorted(known)})")
    rows = []
    for number, ident in enumerate(chosen, 1):
        if progress:
            progress(f"[{number}/{len(chosen)}] {ident.name}: identifying")
        rows.append(compare_one(ident, train, validation, outputs, executor, progress,
                                dict((options or {}).get(ident.name, {}))))
        if progress:
            progress(f"[{number}/{len(chosen)}] {ident.name}: " + _summary(rows[-1]))
    return ComparisonTable(tuple(rows), outputs, train.source, validation.source)


def _summary(row: ComparisonRow) -> str:
    if row.result is None:
        return f"failed after {row.wall_time:.1f} s: {row.message}"
    fits = ", ".join(f"{o} {_cell(row.fit_training.get(o), '-')} / "
                     f"{_cell(row.fit_validation.get(o), '-')} %" for o in row.fit_training)
    return f"fit training / validation {fits}, {row.wall_time:.1f} s"


def compare_one(ident: Identifier, train: IdentificationData, validation: IdentificationData,
                outputs: Sequence[str], executor: Any = None, progress: Progress | None = None,
                options: Mapping[str, Any] | None = None) -> ComparisonRow:
    """One row: identify on `train`, free-run fit on `validation`; failures become the message."""
    inner = (lambda line: progress(f"  {ident.name}: {line}")) if progress else None
    start = time.perf_counter()
    try:
        result = ident.identify(train, executor=executor, progress=inner, **dict(options or {}))
    except Exception as error:  # noqa: BLE001 - a failing structure is reported, not fatal
        return ComparisonRow(ident.name, None, dict.fromkeys(outputs, math.nan),
                             dict.fromkeys(outputs, math.nan), time.perf_counter() - start,
                             False, f"{type(error).__name__}: {error}")
    elapsed = time.perf_counter() - start
    training = {o: float(result.fit.get(o, math.nan)) for o in outputs}
    message = result.message
    try:
        validated = validation_fits(result, validation, outputs)
    except Exception as error:  # noqa: BLE001
        validated = dict.fromkeys(outputs, math.nan)
        message = f"{message}; validation run failed: {type(error).__name__}: {error}"
    return ComparisonRow(ident.name, result.n_free, training, validated, elapsed,
                         bool(result.success), message, result.method, result)


def validation_fits(result: IdentificationResult, validation: IdentificationData,
                    outputs: Sequence[str]) -> dict[str, float]:
    """Free-run fit [%] per output of an identified model on other data.

    The simulator's columns are the outputs of ``result.fit`` in that order.
    """
    simulated = np.asarray(result.simulate(validation), float)
    fitted = list(result.fit)
    if simulated.ndim != 2 or simulated.shape != (len(validation), len(fitted)):
        raise IdentificationError(f"{result.structure}: simulated shape {simulated.shape} does "
                                  f"not match {len(validation)} samples x outputs {fitted}")
    return {o: float(fit_percent(validation.output(o), simulated[:, fitted.index(o)]))
            if o in fitted and o in validation.output_names else math.nan for o in outputs}
