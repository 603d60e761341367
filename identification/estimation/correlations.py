"""The correlation matrix of an identification's estimates, for the reports that ask for it.

The correlation of estimates i and j is ``rho_ij = C_ij / sqrt(C_ii C_jj)`` of the result's
covariance ``C`` (:attr:`IdentificationResult.covariance`, the sandwich covariance of
:mod:`panto.identification.estimation.uncertainty`). A pair near ``+-1`` is a valley of the cost:
the data see a combination of the two (a product, a ratio), not each (thesis section 4.1.3 and
the identifiability of section 4.5). Parameters without a finite, positive variance have no
correlation and are left out, named with the reason: held at a bound (the covariance is that
of the others given the bound), fixed at their prior, or with an unbounded or undefined variance.

Examples
--------
>>> import numpy as np
>>> rho = correlation_matrix(np.array([[4.0, -3.9], [-3.9, 4.0]]))
>>> round(float(rho[0, 1]), 3)
-0.975
"""
from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from panto.identification.estimation.base import IdentificationResult
from panto.identification.estimation.uncertainty import GROUP_CORRELATION


def correlation_matrix(covariance: np.ndarray) -> np.ndarray:
    """``C_ij / sqrt(C_ii C_jj)`` of a covariance matrix (NaN where a variance is not finite
    and positive; ones on the diagonal otherwise).

    Parameters
    ----------
    covariance : ndarray, shape (n, n)
        Covariance of the estimates (any consistent units).
    """
    covariance = np.asarray(covariance, float)
    variance = np.diag(covariance)
    usable = np.isfinite(variance) & (variance > 0.0)
    scale = np.where(usable, np.sqrt(np.where(usable, variance, 1.0)), np.nan)
    with np.errstate(invalid="ignore"):
        rho = np.clip(covariance / np.outer(scale, scale), -1.0, 1.0)
    rho[np.diag_indices_from(rho)] = np.where(usable, 1.0, np.nan)
    return rho


def parameter_correlations(result: IdentificationResult) -> dict[str, Any]:
    """The correlation matrix of `result`'s estimates, JSON-ready.

    Returns
    -------
    dict
        ``names``: the free parameters with a finite, positive variance (in the order of
        ``result.free``); ``matrix``: their correlations (row per name, -1 to 1); ``left_out``:
        name -> why it has no correlation (at a bound, fixed at its prior, unbounded or no
        variance); ``limit``: the |rho| above which parameters form a correlated group.
    """
    left_out = {name: f"fixed at its prior ({why})" if why else "fixed at its prior"
                for name, why in (result.details.get("fixed_at_prior") or {}).items()}
    covariance = np.asarray(result.covariance, float)
    if covariance.shape != (len(result.free), len(result.free)):
        left_out.update({name: "the estimator gives no covariance" for name in result.free})
        return {"names": [], "matrix": [], "left_out": left_out, "limit": GROUP_CORRELATION}
    variance = np.diag(covariance)
    kept = []
    for k, name in enumerate(result.free):
        estimate = result.estimates.get(name)
        if estimate is not None and estimate.at_bound:
            left_out[name] = f"at its {estimate.at_bound} bound"
        elif estimate is not None and estimate.fixed:
            left_out[name] = "fixed at its prior"
        elif np.isinf(variance[k]):
            left_out[name] = "unbounded variance (not identifiable: the outputs do not change " \
                             "along a direction it takes part in)"
        elif not (np.isfinite(variance[k]) and variance[k] > 0.0):
            left_out[name] = "no variance (no influence on the outputs, or not estimated)"
        else:
            kept.append(k)
    rho = correlation_matrix(covariance[np.ix_(kept, kept)])
    return {"names": [result.free[k] for k in kept],
            "matrix": [[None if math.isnan(v) else float(v) for v in row] for row in rho],
            "left_out": left_out, "limit": GROUP_CORRELATION}


def correlation_table(correlations: Mapping[str, Any]) -> str:
    """The matrix of :func:`parameter_correlations` as a markdown table (two decimals), the
    parameters left out named below it."""
    names = list(correlations["names"])
    lines = ["| | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"] if names else \
        ["(no parameter with a finite variance)"]
    for name, row in zip(names, correlations["matrix"]):
        lines.append(f"| {name} | " + " | ".join(_two_decimals(v) for v in row) + " |")
    lines += [""] + [f"- left out: {name}: {why}"
                     for name, why in correlations["left_out"].items()]
    return "\n".join(lines).rstrip() + "\n"


def correlation_lines(correlations: Mapping[str, Any]) -> list[str]:
    """The matrix of :func:`parameter_correlations` as aligned text lines (for a console)."""
    names = list(correlations["names"])
    width = max([len(n) for n in names] + [6])
    lines = ["correlations of the estimates:"]
    if names:
        lines.append(" " * width + "".join(f" {n:>{width}}" for n in names))
        lines += [f"{name:>{width}}" + "".join(f" {_two_decimals(v):>{width}}" for v in row)
                  for name, row in zip(names, correlations["matrix"])]
    else:
        lines.append("  (no parameter with a finite variance)")
    lines += [f"  left out: {name}: {why}" for name, why in correlations["left_out"].items()]
    return lines


def correlation_blocks(correlations: Mapping[str, Any]) -> list[dict]:
    """Report blocks (:mod:`panto.templating`) of :func:`parameter_correlations`: a heading, the
    matrix (|rho| above the group limit marked) and a note naming the parameters left out."""
    from panto import templating as t

    names = list(correlations["names"])
    limit = correlations.get("limit", GROUP_CORRELATION)
    rows = [[name] + [t.cell(_two_decimals(v), "mark" if v is not None and i != j
                             and abs(v) > limit else "")
                      for j, v in enumerate(row)]
            for i, (name, row) in enumerate(zip(names, correlations["matrix"]))]
    blocks = [t.heading("Correlations of the estimates")]
    blocks.append(t.table([""] + names, rows) if names else
                  t.paragraph("No parameter with a finite variance.", "note"))
    left_out = [f"{name}: {why}" for name, why in correlations["left_out"].items()]
    note = f"|correlation| > {limit:g} marked (a correlated group)."
    blocks.append(t.paragraph(note + (" Left out: " + "; ".join(left_out) + "."
                                      if left_out else ""), "note"))
    return blocks


def _two_decimals(value: float | None) -> str:
    return "—" if value is None or not math.isfinite(value) else f"{value:+.2f}"
