"""What every identification piece shares: the data, the fit metric, the structures, the results.

- :class:`IdentificationData` is one experiment on a uniform time grid: inputs and outputs as
  named columns (SI units; pressures in bar as in the thesis).
- :func:`fit_percent` is the thesis' fit metric (section 4.1.3, MATLAB ``compare``):
  ``100 (1 - ||y - y_hat|| / ||y - mean(y)||)`` per output.
- :class:`ModelStructure` is a parametric model that simulates its outputs from the inputs of a
  data set for given parameter values (free run, initial state from the structure's rule).
- :class:`IdentificationResult` is what an estimator returns, whatever the structure: the
  parameters, their uncertainty, the fit on the data it was fitted to, and a way to simulate on
  other data (validation).
- :class:`Identifier` is a named structure's fitting function, as
  :mod:`panto.identification.structures.registry` (the table of structures) hands it out.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np

class IdentificationError(ValueError):
    """Bad data or options for an identification; the message names what and where."""


@dataclass(frozen=True, eq=False)
class IdentificationData:
    """One experiment on a uniform time grid.

    Parameters
    ----------
    time : ndarray, shape (n,)
        Uniformly spaced sample times [s].
    inputs : ndarray, shape (n, n_inputs)
    outputs : ndarray, shape (n, n_outputs)
        May hold NaN where a sample is missing (it is left out of fits and metrics).
    input_names, output_names : tuple of str
    units : mapping of str to str
        Unit per input/output name.
    source : str
        Where the data came from (file, run folder), for messages and reports.
    metadata : mapping
        Anything else (the original dataset's metadata, preprocessing applied).
    """

    time: np.ndarray
    inputs: np.ndarray
    outputs: np.ndarray
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    units: Mapping[str, str] = field(default_factory=dict)
    source: str = ""
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        time = np.asarray(self.time, float)
        inputs = np.asarray(self.inputs, float).reshape(len(time), -1)
        outputs = np.asarray(self.outputs, float).reshape(len(time), -1)
        where = self.source or "identification data"
        if time.ndim != 1 or len(time) < 2:
            raise IdentificationError(f"{where}: need at least two time samples")
        steps = np.diff(time)
        if not np.all(np.isfinite(time)) or np.any(steps <= 0) or \
                np.max(np.abs(steps - steps.mean())) > 1e-6 * steps.mean():
            raise IdentificationError(f"{where}: time must be finite and uniformly increasing")
        if inputs.shape[1] != len(self.input_names) or outputs.shape[1] != len(self.output_names):
            raise IdentificationError(
                f"{where}: {inputs.shape[1]} input and {outputs.shape[1]} output columns for "
                f"names {self.input_names} and {self.output_names}")
        if not np.all(np.isfinite(inputs)):
            bad = self.input_names[int(np.argmax(~np.all(np.isfinite(inputs), axis=0)))]
            raise IdentificationError(f"{where}: input {bad!r} holds NaN or inf (fill or crop first)")
        for array in (time, inputs, outputs):
            array.setflags(write=False)
        object.__setattr__(self, "time", time)
        object.__setattr__(self, "inputs", inputs)
        object.__setattr__(self, "outputs", outputs)
        object.__setattr__(self, "input_names", tuple(self.input_names))
        object.__setattr__(self, "output_names", tuple(self.output_names))

    @property
    def sample_period(self) -> float:
        """Sample period [s]."""
        return float((self.time[-1] - self.time[0]) / (len(self.time) - 1))

    def __len__(self) -> int:
        return len(self.time)

    def input(self, name: str) -> np.ndarray:
        """One input column by name."""
        return self.inputs[:, self._index(self.input_names, name, "input")]

    def output(self, name: str) -> np.ndarray:
        """One output column by name."""
        return self.outputs[:, self._index(self.output_names, name, "output")]

    def _index(self, names: Sequence[str], name: str, role: str) -> int:
        if name not in names:
            raise IdentificationError(f"{self.source or 'data'}: no {role} {name!r} (has {list(names)})")
        return list(names).index(name)

    def segment(self, start: float, stop: float) -> "IdentificationData":
        """The samples with ``start <= t < stop``, same names and metadata."""
        keep = (self.time >= start) & (self.time < stop)
        return IdentificationData(self.time[keep], self.inputs[keep], self.outputs[keep],
                                  self.input_names, self.output_names, self.units, self.source,
                                  self.metadata)

    def to_response(self) -> Any:
        """The inputs and outputs as a :class:`panto.fmu_src.response.TimeResponse` (units from
        :attr:`units`, metadata with the :attr:`source`), e.g. ``data.to_response().plot()``."""
        from panto.fmu_src.response import TimeResponse

        names = self.input_names + self.output_names
        signals = dict(zip(names, np.column_stack([self.inputs, self.outputs]).T))
        return TimeResponse(self.time, signals,
                            units={n: self.units[n] for n in names if n in self.units},
                            metadata={**dict(self.metadata), "source": self.source})

    def select_outputs(self, names: Sequence[str]) -> "IdentificationData":
        """The same experiment with only the named outputs (in that order)."""
        columns = [self._index(self.output_names, n, "output") for n in names]
        return IdentificationData(self.time, self.inputs, self.outputs[:, columns],
                                  self.input_names, tuple(names), self.units, self.source,
                                  self.metadata)


def fit_percent(measured: np.ndarray, simulated: np.ndarray) -> np.ndarray | float:
    """Fit [%] per output: ``100 (1 - ||y - y_hat|| / ||y - mean(y)||)`` (thesis eq. 4.1.3).

    Samples where either is NaN are left out. 100 is perfect, 0 is as good as the mean, and it
    is negative when worse than the mean. Columns of 2-D arrays are outputs.
    """
    y = np.asarray(measured, float)
    y_hat = np.asarray(simulated, float)
    if y.shape != y_hat.shape:
        raise ValueError(f"measured {y.shape} and simulated {y_hat.shape} differ in shape")
    if y.ndim == 1:
        return float(fit_percent(y[:, None], y_hat[:, None])[0])
    fits = np.empty(y.shape[1])
    for j in range(y.shape[1]):
        ok = np.isfinite(y[:, j]) & np.isfinite(y_hat[:, j])
        spread = np.linalg.norm(y[ok, j] - y[ok, j].mean())
        fits[j] = 100.0 * (1.0 - np.linalg.norm(y[ok, j] - y_hat[ok, j]) / spread) \
            if ok.any() and spread > 0 else math.nan
    return fits


class ModelStructure(ABC):
    """A parametric model structure that simulates outputs from a data set's inputs.

    Subclasses set :attr:`name`, :attr:`input_names`, :attr:`output_names`,
    :attr:`parameter_names` and implement :meth:`nominal`, :meth:`bounds` and :meth:`simulate`.
    A structure must be picklable (it is sent to process-pool or Dask workers).
    """

    name: str = ""
    input_names: tuple[str, ...] = ()
    output_names: tuple[str, ...] = ()
    parameter_names: tuple[str, ...] = ()

    @property
    def input_refinement(self) -> bool:
        """Whether the structure simulates in continuous time with its inputs linear between
        samples, cheaply enough that a record resampled on a finer grid is simulated equally
        (every k-th sample the same): a transformed input may then be given between the samples.
        False unless a subclass says so (a discrete-time model is not)."""
        return False

    @abstractmethod
    def nominal(self) -> dict[str, float]:
        """Nominal (prior, default) value of every parameter."""

    @abstractmethod
    def bounds(self) -> dict[str, tuple[float, float]]:
        """Admissible (lower, upper) range of every parameter."""

    @abstractmethod
    def simulate(self, parameters: Mapping[str, float], data: IdentificationData) -> np.ndarray:
        """Free-run simulated outputs, shape ``(len(data), len(self.output_names))``.

        `parameters` holds values for any subset of :attr:`parameter_names`; the rest keep
        their nominal values. Raises :class:`IdentificationError` (or a subclass of
        ``ValueError``/``ArithmeticError``) for parameters that make the model invalid, so that an
        estimator can treat the candidate as infeasible.
        """


@dataclass(frozen=True, eq=False)
class IdentificationResult:
    """What an estimator returns.

    Parameters
    ----------
    structure : str
        Structure name (as in :mod:`panto.identification.structures.registry`).
    method : str
        Estimator (``"levenberg-marquardt"``, ``"nsga2"``, ``"n4sid+pem"``, ...).
    parameters : mapping of str to float
        All parameter values of the structure (free and fixed).
    free : tuple of str
        The parameters that were estimated.
    std : mapping of str to float
        Standard deviation of each free parameter (NaN when not available).
    covariance : ndarray, shape (n_free, n_free)
    fit : mapping of str to float
        Fit [%] per output on the data fitted (free run).
    success : bool
    message : str
        Why it stopped; for a failure, why it failed.
    wall_time : float
        Seconds taken.
    n_evaluations : int
        Model simulations used.
    simulator : callable
        ``simulator(data) -> ndarray (n, n_outputs)``: the identified model on other data.
    details : mapping
        Anything else worth reporting (Pareto front, poles, matrices, identifiability).
    estimates : mapping of str to ParameterEstimate
        Per parameter: value, unit, standard deviation, 95 % interval, verdict (identifiable /
        weakly / not, at a bound, fixed at prior), correlated group
        (:class:`panto.identification.estimation.uncertainty.ParameterEstimate`); empty when
        the estimator gives none.
    """

    structure: str
    method: str
    parameters: Mapping[str, float]
    free: tuple[str, ...]
    std: Mapping[str, float]
    covariance: np.ndarray
    fit: Mapping[str, float]
    success: bool
    message: str
    wall_time: float
    n_evaluations: int
    simulator: Callable[[IdentificationData], np.ndarray] = field(repr=False)
    details: Mapping[str, Any] = field(default_factory=dict)
    estimates: Mapping[str, Any] = field(default_factory=dict)

    @property
    def n_free(self) -> int:
        """Number of estimated parameters."""
        return len(self.free)

    def simulate(self, data: IdentificationData) -> np.ndarray:
        """Free-run outputs of the identified model on `data`."""
        return self.simulator(data)

    def fit_on(self, data: IdentificationData, output_names: Sequence[str]) -> dict[str, float]:
        """Fit [%] per output of the identified model on other data (validation)."""
        simulated = self.simulate(data)
        measured = data.select_outputs(output_names).outputs
        return dict(zip(output_names, np.atleast_1d(fit_percent(measured, simulated)).tolist()))

    def response(self, data: IdentificationData) -> Any:
        """The identified model's free run on `data` as a :class:`panto.fmu_src.response.TimeResponse`
        (the outputs named as in `data`, with its units), to plot over ``data.to_response()``."""
        from panto.fmu_src.response import TimeResponse

        simulated = np.asarray(self.simulate(data), float).reshape(len(data), -1)
        names = data.output_names[:simulated.shape[1]]
        return TimeResponse(data.time, dict(zip(names, simulated.T)),
                            units={n: data.units[n] for n in names if n in data.units},
                            metadata={"model": self.structure, "interface": self.method})

    def _repr_html_(self) -> str:
        """A notebook's view: fits, then the parameters with unit, standard deviation, 95 %
        interval and the marks of the verdict (at a bound, not identifiable, fixed)."""
        from panto.fmu_src.display import html_block, html_table

        intervals = self.details.get("intervals_95", {})
        rows = []
        for name, value in self.parameters.items():
            estimate = self.estimates.get(name)
            if estimate is not None:
                rows.append([name, estimate.value, estimate.unit, estimate.std,
                             _interval(estimate.interval_95), estimate.status, estimate.verdict])
            else:
                free = name in self.free
                rows.append([name, value, "", self.std.get(name) if free else None,
                             _interval(intervals.get(name)) if free else None,
                             "estimated" if free else "fixed", None])
        fits = ", ".join(f"{o} {f:.2f} %" for o, f in self.fit.items())
        lines = [f"{'success' if self.success else 'FAILED'}: {self.message}",
                 f"fit on the data fitted: {fits}" if fits else "",
                 f"{self.n_evaluations} evaluations, {self.wall_time:.3g} s"]
        table = html_table(["parameter", "value", "unit", "std (1 σ)", "95 % interval",
                            "status", "verdict"], rows)
        return html_block(f"{self.structure} ({self.method})", table, lines=lines)


def _interval(bounds: Sequence[float] | None) -> str | None:
    """``[low, high]`` for a table cell; None when missing or not finite."""
    if bounds is None or not all(math.isfinite(float(b)) for b in bounds):
        return None
    return f"[{float(bounds[0]):.4g}, {float(bounds[1]):.4g}]"


@dataclass(frozen=True)
class Identifier:
    """A named structure's fitting function for ``panto identify`` and ``panto compare``
    (:func:`panto.identification.structures.registry.identifier` makes them from its table)."""

    name: str
    description: str
    identify: Callable[..., IdentificationResult]
    """``identify(data, *, executor=None, progress=None, **options) -> IdentificationResult``"""
    in_comparison: bool = True
    """Whether ``panto compare`` fits it (the thesis' Table of section 4.8)."""

