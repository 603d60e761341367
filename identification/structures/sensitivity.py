"""Eigenvalue sensitivity of the linearised physical model to its parameters (thesis Fig. 4.9).

Each parameter ``theta_i`` is multiplied in turn by each factor (0.9 and 1.1 in the thesis), the
model is linearised about its static equilibrium at the operating point ``(eta, p)`` (thesis eqs.
2.27-2.30; :func:`linearised_eigenvalues`) and the eigenvalues of ``A`` are compared with
the nominal ones. Eigenvalues are matched to the nominal modes by a minimum-cost assignment on
``|lambda_j' - lambda_i|``. Per parameter three measures of influence are reported, each the
largest over the modes and factors:

- relative eigenvalue shift ``|lambda' - lambda| / |lambda|`` (the ranking),
- relative natural-frequency shift ``(|lambda'| - |lambda|) / |lambda|`` (signed, largest magnitude),
- damping-ratio shift ``zeta' - zeta`` with ``zeta = -Re(lambda) / |lambda|``.

The thesis found the eigenvalues robust to +-10 % changes, with the collector-head mass ``m_c``
and the carbon-contact stiffness ``k_ph`` the most influential (section 4.5). With Table 4.1 the
ranking over all modes puts the upper-arm mass ``m4`` first (4.5 %): its shift is in the
rod-elastic mode (15.4 Hz, the coupling-rod spring ``k`` on ``delta``; found by
:func:`elastic_rod_modes`, its frequency grows as ``sqrt(k)`` when the rod is stiffened). Over the
other modes (:meth:`EigenvalueSensitivity.ranking_over`) ``m_c`` (3.9 %) and ``k_ph`` (3.8 %)
lead, as in the thesis (docs/thesis.md, Fig. 4.9).
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment

#: The 13 parameters of thesis Table 4.1 (with the bellow gain k_p), as in Fig. 4.9.
TABLE_4_1 = ("m1", "m2", "m3", "m4", "m_c", "c1", "c2", "c3", "c_c", "k", "k_c", "k_ph", "k_p")
MODEL = "Pantograph"


def linearised_eigenvalues(parameters: Mapping[str, float] | None, eta: float, p: float, *,
                           path: str = "compiled") -> np.ndarray:
    """Eigenvalues [1/s] of the pantograph linearised about its equilibrium at (eta, p).

    Parameters
    ----------
    parameters : mapping, optional
        Values of any model parameters (the rest at their defaults).
    eta : float
        Contact-wire (linear-motor) height [m].
    p : float
        Bellow pressure [bar].
    path : {"compiled", "model"}
        ``"compiled"``: the static equilibrium and exact linearisation compiled for
        identification (:func:`panto.identification.structures.physical.linearise`, milliseconds per call);
        ``"model"``: :meth:`panto.fmu_src.models.Model.linearise` (the same equations through the
        general model evaluation; its first use compiles the full model, about a minute).
        Both give the same eigenvalues.
    """
    from panto.fmu_src.models import Model, default_parameters

    if path == "model":
        return Model(MODEL, dict(parameters or {})).linearise(eta, p).eigenvalues
    if path != "compiled":
        raise ValueError(f"path {path!r}: choose 'compiled' or 'model'")
    from panto.identification.structures.physical import linearise

    params = default_parameters(MODEL).with_values(dict(parameters or {}))
    a = linearise(params.vector(), [float(eta), float(p)])[0]
    return np.linalg.eigvals(a)


def match_modes(nominal: np.ndarray, changed: np.ndarray) -> np.ndarray:
    """`changed` reordered so that entry i is the eigenvalue closest to ``nominal[i]``
    (minimum total distance over all pairings)."""
    cost = np.abs(nominal[:, None] - changed[None, :])
    rows, columns = linear_sum_assignment(cost)
    matched = np.empty_like(changed)
    matched[rows] = changed[columns]
    return matched


def elastic_rod_modes(parameters: Mapping[str, float] | None = None, *, eta: float = 2.0,
                      p: float = 4.0, stiffening: float = 100.0) -> np.ndarray:
    """Indices (into :func:`linearised_eigenvalues`) of the coupling rod's elastic mode.

    The rod's flexibility ``delta`` with spring ``k`` (thesis Fig. 2.3) is the mode that leaves
    for infinite frequency as the rod is made rigid: ``k`` is multiplied by `stiffening`, the
    eigenvalues are matched to the nominal ones, and the conjugate pair whose magnitude grows
    the most is returned (two indices).
    """
    values = _parameter_values(parameters)
    nominal = linearised_eigenvalues(values, eta, p)
    rigid = match_modes(nominal, linearised_eigenvalues(
        {**values, "k": values["k"] * stiffening}, eta, p))
    growth = np.abs(rigid) / np.where(np.abs(nominal) > 0, np.abs(nominal), 1.0)
    top = int(np.argmax(growth))
    if nominal[top].imag == 0:
        return np.array([top])
    distance = np.abs(nominal - np.conj(nominal[top]))
    distance[top] = np.inf
    return np.array(sorted({top, int(np.argmin(distance))}))


def damping_ratio(eigenvalues: np.ndarray) -> np.ndarray:
    """``zeta = -Re(lambda) / |lambda|`` (1 for a real negative eigenvalue)."""
    magnitude = np.abs(eigenvalues)
    return np.where(magnitude > 0, -eigenvalues.real / np.where(magnitude > 0, magnitude, 1), 0)


@dataclass(frozen=True, eq=False)
class ParameterShift:
    """How the eigenvalues move when one parameter is scaled.

    Attributes
    ----------
    name : str
    value : float
        Nominal value of the parameter.
    factors : tuple of float
    eigenvalues : ndarray, shape (n_factors, n_states)
        Eigenvalues for each factor, matched to the nominal order (NaN where the model failed).
    relative_shift, frequency_shift, damping_shift : float
        Influence measures (module notes); NaN if every factor failed.
    message : str
        Why a factor failed (no equilibrium, inadmissible value), else "".
    """

    name: str
    value: float
    factors: tuple[float, ...]
    eigenvalues: np.ndarray
    relative_shift: float
    frequency_shift: float
    damping_shift: float
    message: str = ""


@dataclass(frozen=True, eq=False)
class EigenvalueSensitivity:
    """Eigenvalues of the linearised model for each parameter scaled by each factor.

    Attributes
    ----------
    eta, p : float
        Operating point [m], [bar].
    parameters : dict
        The parameter values varied about (defaults where not given).
    nominal : ndarray
        Nominal eigenvalues [1/s].
    shifts : tuple of ParameterShift
        One per parameter, in the order asked for.
    """

    eta: float
    p: float
    parameters: Mapping[str, float]
    nominal: np.ndarray
    shifts: tuple[ParameterShift, ...]

    @property
    def ranking(self) -> list[str]:
        """Parameter names from the most to the least influential (relative eigenvalue shift)."""
        ordered = sorted(self.shifts, key=lambda s: -s.relative_shift
                         if math.isfinite(s.relative_shift) else math.inf)
        return [s.name for s in ordered]

    def ranking_over(self, modes: Sequence[int]) -> list[str]:
        """Parameter names ranked by their largest relative shift of the nominal eigenvalues
        ``nominal[modes]`` only (e.g. all but :func:`elastic_rod_modes`)."""
        index = np.asarray(list(modes), int)
        if index.size == 0:
            raise ValueError("ranking_over needs at least one mode index")
        scale = np.abs(self.nominal[index])

        def measure(s: ParameterShift) -> float:
            ok = np.all(np.isfinite(s.eigenvalues), axis=1)
            if not ok.any():
                return -math.inf
            return float(np.max(np.abs(s.eigenvalues[ok][:, index] - self.nominal[index]) / scale))

        return [s.name for s in sorted(self.shifts, key=lambda s: -measure(s))]

    def shift(self, name: str) -> ParameterShift:
        """The :class:`ParameterShift` of one parameter."""
        for item in self.shifts:
            if item.name == name:
                return item
        raise KeyError(f"{name!r} was not varied (varied: {[s.name for s in self.shifts]})")

    @property
    def natural_frequencies_hz(self) -> np.ndarray:
        """Nominal undamped natural frequencies of the oscillatory modes, ascending [Hz]."""
        return np.sort(np.abs(self.nominal[self.nominal.imag > 0]) / (2 * np.pi))

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready summary (eigenvalues as [real, imaginary] pairs)."""
        def pairs(values):
            return [[float(v.real), float(v.imag)] for v in values]

        return {
            "model": MODEL, "eta": self.eta, "p": self.p,
            "nominal_eigenvalues": pairs(self.nominal),
            "natural_frequencies_hz": self.natural_frequencies_hz.tolist(),
            "ranking": self.ranking,
            "parameters": {
                s.name: {"value": s.value, "relative_shift": _finite(s.relative_shift),
                         "frequency_shift": _finite(s.frequency_shift),
                         "damping_shift": _finite(s.damping_shift), "message": s.message,
                         "eigenvalues": {str(f): pairs(ev) for f, ev in
                                         zip(s.factors, s.eigenvalues)}}
                for s in self.shifts},
        }

    def write_json(self, path: str | os.PathLike) -> str | os.PathLike:
        """Write :meth:`to_dict` as JSON; returns the path."""
        with open(path, "w") as handle:
            json.dump(self.to_dict(), handle, indent=2)
        return path

    def to_markdown(self) -> str:
        """The ranking as a Markdown table."""
        lines = ["| rank | parameter | value | max eigenvalue shift [%] | max frequency shift [%] "
                 "| max damping-ratio shift |", "|---|---|---|---|---|---|"]
        for rank, name in enumerate(self.ranking, 1):
            s = self.shift(name)
            lines.append(f"| {rank} | {name} | {s.value:.6g} | {100 * s.relative_shift:.2f} | "
                         f"{100 * s.frequency_shift:+.2f} | {s.damping_shift:+.4f} |")
        return "\n".join(lines)


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _parameter_values(parameters: Any) -> dict[str, float]:
    """All model parameter values from None, a ParameterSet, a mapping or an
    IdentificationResult (its ``parameters``)."""
    from panto.fmu_src.models import default_parameters
    from panto.fmu_src.parameters import ParameterSet

    defaults = default_parameters(MODEL)
    if parameters is None:
        chosen: Mapping[str, float] = {}
    elif isinstance(parameters, ParameterSet):
        chosen = dict(zip(parameters.names, parameters.vector().tolist()))
    elif hasattr(parameters, "parameters") and isinstance(parameters.parameters, Mapping):
        chosen = parameters.parameters
    else:
        chosen = parameters
    known = set(defaults.names)
    values = dict(zip(defaults.names, defaults.vector().tolist()))
    values.update({k: float(v) for k, v in chosen.items() if k in known})
    return values


def _measures(nominal: np.ndarray, eigenvalues: np.ndarray) -> tuple[float, float, float]:
    ok = np.all(np.isfinite(eigenvalues), axis=1)
    if not ok.any():
        return math.nan, math.nan, math.nan
    changed = eigenvalues[ok]
    scale = np.where(np.abs(nominal) > 0, np.abs(nominal), 1.0)
    relative = np.max(np.abs(changed - nominal) / scale)
    frequency = (np.abs(changed) - np.abs(nominal)) / scale
    damping = damping_ratio(changed) - damping_ratio(nominal)
    return (float(relative), float(frequency.flat[np.argmax(np.abs(frequency))]),
            float(damping.flat[np.argmax(np.abs(damping))]))


def eigenvalue_sensitivity(parameters: Any = None, *, eta: float = 2.0, p: float = 4.0,
                           names: Sequence[str] = TABLE_4_1,
                           factors: Sequence[float] = (0.9, 1.1),
                           progress: Callable[[str], None] | None = None
                           ) -> EigenvalueSensitivity:
    """Eigenvalues of the linearised pantograph with each parameter scaled (thesis Fig. 4.9).

    Parameters
    ----------
    parameters : ParameterSet, mapping, IdentificationResult or None
        The parameter set varied about (an identified one, or the defaults = Table 4.1).
    eta : float
        Operating point: wire height [m].
    p : float
        Operating point: bellow pressure [bar].
    names : sequence of str
        Parameters to scale, one at a time (default the 13 of Table 4.1).
    factors : sequence of float
        Multipliers (thesis: 0.9 and 1.1).
    progress : callable, optional
        Called with one line per parameter.

    Returns
    -------
    EigenvalueSensitivity
    """
    values = _parameter_values(parameters)
    unknown = [n for n in names if n not in values]
    if unknown:
        raise ValueError(f"unknown pantograph parameter(s) {unknown}; known: {sorted(values)}")
    if not factors or any(not (math.isfinite(f) and f > 0) for f in factors):
        raise ValueError(f"factors must be positive numbers, got {list(factors)}")
    nominal = linearised_eigenvalues(values, eta, p)
    shifts = []
    for name in names:
        shifts.append(_scale_one(values, name, tuple(float(f) for f in factors), nominal,
                                 eta, p))
        if progress:
            s = shifts[-1]
            progress(f"{name}: max eigenvalue shift {100 * s.relative_shift:.2f} %"
                     + (f" ({s.message})" if s.message else ""))
    return EigenvalueSensitivity(eta=float(eta), p=float(p), parameters=values, nominal=nominal,
                                 shifts=tuple(shifts))


def _scale_one(values: Mapping[str, float], name: str, factors: tuple[float, ...],
               nominal: np.ndarray, eta: float, p: float) -> ParameterShift:
    rows, messages = [], []
    for factor in factors:
        try:
            changed = linearised_eigenvalues({**values, name: values[name] * factor}, eta, p)
            rows.append(match_modes(nominal, changed))
        except (ValueError, ArithmeticError, RuntimeError) as error:
            rows.append(np.full(len(nominal), np.nan + 1j * np.nan))
            messages.append(f"x{factor}: {error}")
    eigenvalues = np.array(rows)
    relative, frequency, damping = _measures(nominal, eigenvalues)
    return ParameterShift(name, float(values[name]), factors, eigenvalues, relative, frequency,
                          damping, "; ".join(messages))
