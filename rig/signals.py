"""Excitation signals for the rig's two inputs: the linear motor [m] and the bellow pressure [bar].

The thesis' real-time unit offered, for both actuators, a constant (also the offset added to every
other signal), a sine, a chirp, an APRBS, ramps and steps, plus for the linear motor a replayed
catenary sequence (thesis section 3.1, Fig. 3.4). This module adds a replay of any file (e.g. an
optimal input from the design of experiments) and odd random-phase multisines with detection lines
(Pintelon & Schoukens, *System Identification: A Frequency Domain Approach*, 2nd ed., Wiley 2012,
ch. 3-4).

Every signal is a frozen dataclass of its settings, named in a registry by its ``kind`` so that a
profile file can name it (:data:`SIGNAL_TYPES`, :func:`signal_from_dict`). Random signals are made
reproducible by realising them once from a :class:`numpy.random.Generator` passed in
(:meth:`Signal.realise`); the realisation is a deterministic function of time, evaluated
element-wise, so a whole run at once and the same run chunk by chunk give identical samples.

Each signal is active on ``start <= t < stop`` (``stop=None``: to the end of the run) and
contributes zero outside; inside, its own clock is :math:`\\tau = t - t_\\mathrm{start}`.
"""
from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import MISSING, dataclass, fields
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

Evaluator = Callable[[np.ndarray], np.ndarray]
SIGNAL_TYPES: dict[str, type["Signal"]] = {}
_INDEX_TOLERANCE = 1e-6  # sample-index slack: t * fs within this of an integer is that integer


@dataclass(frozen=True, kw_only=True)
class RealiseContext:
    """What a signal needs to know about the run it is realised for.

    Parameters
    ----------
    duration : float
        Run duration [s].
    sample_rate : float
        Sample rate of the run [Hz] (random hold times and multisine periods are whole samples).
    bounds : tuple of float
        Room for the channel's dynamic part, ``(limit_min - offset, limit_max - offset)``, in the
        channel unit; an APRBS with ``clip`` clips its levels to it.
    unit : str
        The channel unit (``"m"`` or ``"bar"``); a replayed file is converted to it.
    base_dir : pathlib.Path or None
        Folder against which relative file names are resolved (the profile's folder).
    """

    duration: float
    sample_rate: float = 500.0
    bounds: tuple[float, float] = (-math.inf, math.inf)
    unit: str = "m"
    base_dir: Path | None = None


def register_signal(cls: type["Signal"]) -> type["Signal"]:
    """Class decorator: enter a signal type in :data:`SIGNAL_TYPES` under its ``kind``."""
    SIGNAL_TYPES[cls.kind] = cls
    return cls


def _require(condition: bool, field_name: str, value: Any, problem: str) -> None:
    if not condition:
        raise ValueError(f"{field_name} = {value!r}: {problem}")


def _below_nyquist(field_name: str, frequency: float, sample_rate: float) -> None:
    """Refuse a frequency [Hz] at or above the Nyquist frequency of `sample_rate` [Hz]: sampled,
    it would alias to a lower one."""
    _require(frequency < sample_rate / 2.0, field_name, frequency,
             f"must be below the Nyquist frequency {sample_rate / 2:g} Hz of the "
             f"{sample_rate:g} Hz sample rate (it would alias)")


@dataclass(frozen=True, kw_only=True)
class Signal:
    """Base of all signals: an active window ``[start, stop)`` and the registry plumbing.

    Subclasses set ``kind``, check their fields in :meth:`_check` and build the evaluator of
    :math:`\\tau = t - t_\\mathrm{start}` in :meth:`_build`.
    """

    kind: ClassVar[str] = ""
    start: float = 0.0
    stop: float | None = None

    def __post_init__(self) -> None:
        _require(math.isfinite(self.start) and self.start >= 0.0, "start", self.start,
                 "must be a finite time >= 0 s")
        if self.stop is not None:
            _require(math.isfinite(self.stop) and self.stop > self.start, "stop", self.stop,
                     f"must be finite and after start = {self.start} s")
        self._check()

    def _check(self) -> None:
        """Raise ``ValueError("field = value: problem")`` for an inadmissible setting."""

    def _build(self, rng: np.random.Generator, context: RealiseContext,
               window: float) -> Evaluator:
        raise NotImplementedError

    def window(self, context: RealiseContext) -> float:
        """Length of the active window in this run [s]."""
        end = context.duration if self.stop is None else min(self.stop, context.duration)
        return max(end - self.start, 0.0)

    def realise(self, rng: np.random.Generator, context: RealiseContext) -> Evaluator:
        """Draw the random parts (if any) and return the signal as a function of time.

        Parameters
        ----------
        rng : numpy.random.Generator
            Source of randomness; the same generator state gives the same realisation.
        context : RealiseContext
            Duration, sample rate, bounds and folder of the run.

        Returns
        -------
        callable
            ``evaluate(time) -> values``: element-wise in `time` [s] (absolute run time), zero
            outside ``[start, stop)``.
        """
        core = self._build(rng, context, self.window(context))
        start = self.start
        stop = math.inf if self.stop is None else self.stop

        def evaluate(time: np.ndarray) -> np.ndarray:
            time = np.asarray(time, dtype=float)
            values = np.zeros(time.shape)
            active = (time >= start) & (time < stop)
            if np.any(active):
                values[active] = core(time[active] - start)
            return values

        return evaluate

    def sample(self, time: np.ndarray, rng: np.random.Generator, *,
               sample_rate: float = 500.0) -> np.ndarray:
        """Samples at `time` of a realisation for a run ending with the last element of `time`."""
        time = np.asarray(time, dtype=float)
        duration = float(time[-1]) + 1.0 / sample_rate if time.size else 0.0
        return self.realise(rng, RealiseContext(duration=duration, sample_rate=sample_rate))(time)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready settings, ``{"kind": ..., field: value, ...}``."""
        return {"kind": self.kind, **{f.name: getattr(self, f.name) for f in fields(self)}}


def parse_field(type_text: str, value: Any, name: str) -> Any:
    """Convert a JSON value to a field of annotated type `type_text` or raise a ValueError."""
    optional = type_text.endswith("| None")
    if value is None:
        if optional:
            return None
        raise ValueError(f"{name} = None: a value is required")
    base = type_text.replace("| None", "").strip()
    if base == "bool":
        if not isinstance(value, bool):
            raise ValueError(f"{name} = {value!r}: must be true or false")
        return value
    if base == "str":
        if not isinstance(value, str):
            raise ValueError(f"{name} = {value!r}: must be a string")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{name} = {value!r}: must be a number")
    if base == "int":
        if float(value) != int(value):
            raise ValueError(f"{name} = {value!r}: must be a whole number")
        return int(value)
    return float(value)


def signal_from_dict(data: Mapping[str, Any]) -> Signal:
    """Build a signal from its settings, e.g. ``{"kind": "sine", "frequency": 2, "amplitude": 1}``.

    Raises
    ------
    ValueError
        Naming the unknown kind (and the known ones), an unknown or missing field, or a field
        whose value is of the wrong type or out of range.
    """
    if not isinstance(data, Mapping):
        raise ValueError(f"a signal must be an object with a 'kind', got {data!r}")
    kind = data.get("kind")
    if kind not in SIGNAL_TYPES:
        raise ValueError(f"kind = {kind!r}: unknown signal kind; known kinds are "
                         f"{sorted(SIGNAL_TYPES)}")
    cls = SIGNAL_TYPES[kind]
    known = {f.name: f for f in fields(cls)}
    unknown = sorted(set(data) - set(known) - {"kind"})
    if unknown:
        raise ValueError(f"{kind}: unknown field(s) {unknown}; fields are {sorted(known)}")
    missing = [name for name, f in known.items() if name not in data
               and f.default is MISSING and f.default_factory is MISSING]
    if missing:
        raise ValueError(f"{kind}: required field(s) {missing} missing")
    values = {name: parse_field(str(known[name].type), value, name)
              for name, value in data.items() if name != "kind"}
    return cls(**values)


def _sample_index(tau: np.ndarray, sample_rate: float) -> np.ndarray:
    """Whole-sample index of each time: ``floor(tau * fs)`` robust to rounding of ``t - start``."""
    return np.floor(tau * sample_rate + _INDEX_TOLERANCE).astype(np.int64)


@register_signal
@dataclass(frozen=True, kw_only=True)
class Constant(Signal):
    """A constant :math:`x(\\tau) = c` (the channel offset is one too, kept apart in profiles)."""

    kind: ClassVar[str] = "constant"
    value: float

    def _check(self) -> None:
        _require(math.isfinite(self.value), "value", self.value, "must be finite")

    def _build(self, rng, context, window):
        return lambda tau: np.full(tau.shape, self.value)


@register_signal
@dataclass(frozen=True, kw_only=True)
class Sine(Signal):
    """A sine :math:`x(\\tau) = A \\sin(2 \\pi f \\tau + \\varphi)` (f [Hz], phase [rad])."""

    kind: ClassVar[str] = "sine"
    frequency: float
    amplitude: float
    phase: float = 0.0

    def _check(self) -> None:
        _require(math.isfinite(self.frequency) and self.frequency > 0.0, "frequency",
                 self.frequency, "must be > 0 Hz")
        _require(math.isfinite(self.amplitude), "amplitude", self.amplitude, "must be finite")
        _require(math.isfinite(self.phase), "phase", self.phase, "must be finite")

    def _build(self, rng, context, window):
        _below_nyquist("frequency", self.frequency, context.sample_rate)
        return lambda tau: self.amplitude * np.sin(2.0 * np.pi * self.frequency * tau
                                                   + self.phase)


@register_signal
@dataclass(frozen=True, kw_only=True)
class Chirp(Signal):
    """A frequency sweep :math:`x = A \\sin(\\varphi(\\tau) + \\varphi_0)`, `f_start` to `f_stop`.

    The instantaneous frequency :math:`f(\\tau) = \\dot\\varphi / 2\\pi` over the sweep duration
    :math:`T` follows

    - ``"linear"``: :math:`f = f_0 + (f_1 - f_0) \\tau / T`,
      :math:`\\varphi = 2\\pi (f_0 \\tau + (f_1 - f_0) \\tau^2 / 2T)`;
    - ``"logarithmic"``: :math:`f = f_0 (f_1/f_0)^{\\tau/T}`,
      :math:`\\varphi = 2\\pi f_0 T ((f_1/f_0)^{\\tau/T} - 1) / \\ln(f_1/f_0)`.

    After the sweep the signal is zero, or the sweep starts again when ``repeat`` is true.
    """

    kind: ClassVar[str] = "chirp"
    f_start: float
    f_stop: float
    duration: float
    amplitude: float
    method: str = "linear"
    phase: float = 0.0
    repeat: bool = False

    def _check(self) -> None:
        for name in ("f_start", "f_stop", "duration"):
            value = getattr(self, name)
            _require(math.isfinite(value) and value > 0.0, name, value, "must be > 0")
        _require(math.isfinite(self.amplitude), "amplitude", self.amplitude, "must be finite")
        _require(self.method in ("linear", "logarithmic"), "method", self.method,
                 "must be 'linear' or 'logarithmic'")
        if self.method == "logarithmic":
            _require(self.f_stop != self.f_start, "f_stop", self.f_stop,
                     "must differ from f_start for a logarithmic sweep")

    def instantaneous_frequency(self, tau: np.ndarray) -> np.ndarray:
        """The law :math:`f(\\tau)` [Hz] within one sweep, ``0 <= tau < duration``."""
        ratio = np.asarray(tau, dtype=float) / self.duration
        if self.method == "linear":
            return self.f_start + (self.f_stop - self.f_start) * ratio
        return self.f_start * (self.f_stop / self.f_start) ** ratio

    def _phase(self, tau: np.ndarray) -> np.ndarray:
        f0, f1, length = self.f_start, self.f_stop, self.duration
        if self.method == "linear":
            return 2.0 * np.pi * (f0 * tau + (f1 - f0) * tau ** 2 / (2.0 * length))
        log_ratio = math.log(f1 / f0)
        return 2.0 * np.pi * f0 * length * np.expm1(log_ratio * tau / length) / log_ratio

    def _build(self, rng, context, window):
        for name in ("f_start", "f_stop"):
            _below_nyquist(name, getattr(self, name), context.sample_rate)

        def evaluate(tau: np.ndarray) -> np.ndarray:
            if self.repeat:
                tau = np.mod(tau, self.duration)
            values = self.amplitude * np.sin(self._phase(tau) + self.phase)
            return np.where(tau < self.duration, values, 0.0)
        return evaluate


@register_signal
@dataclass(frozen=True, kw_only=True)
class Aprbs(Signal):
    """Amplitude-modulated pseudo-random binary signal: piecewise constant random levels.

    Levels are independent draws :math:`a_j \\sim \\mathcal{N}(0, \\sigma^2)` (zero mean, standard
    deviation ``std``), each held for a whole number of samples drawn uniformly between
    ``ceil(hold_min * fs)`` and ``floor(hold_max * fs)`` (thesis section 3.1; Nelles,
    *Nonlinear System Identification*, Springer 2001, sec. 17.7). With ``clip`` the levels are
    clipped to the channel's room :attr:`RealiseContext.bounds`.
    """

    kind: ClassVar[str] = "aprbs"
    std: float
    hold_min: float
    hold_max: float
    clip: bool = True

    def _check(self) -> None:
        _require(math.isfinite(self.std) and self.std >= 0.0, "std", self.std, "must be >= 0")
        _require(math.isfinite(self.hold_min) and self.hold_min > 0.0, "hold_min",
                 self.hold_min, "must be a positive hold time [s]")
        _require(math.isfinite(self.hold_max) and self.hold_max >= self.hold_min, "hold_max",
                 self.hold_max, f"must be >= hold_min = {self.hold_min} s")

    def hold_samples(self, sample_rate: float) -> tuple[int, int]:
        """Shortest and longest hold in whole samples at `sample_rate`."""
        low = max(1, math.ceil(self.hold_min * sample_rate - _INDEX_TOLERANCE))
        high = math.floor(self.hold_max * sample_rate + _INDEX_TOLERANCE)
        _require(low <= high, "hold_max", self.hold_max,
                 f"no whole number of samples at {sample_rate} Hz lies in "
                 f"[hold_min, hold_max] = [{self.hold_min}, {self.hold_max}] s")
        return low, high

    def _build(self, rng, context, window):
        low, high = self.hold_samples(context.sample_rate)
        count = max(1, math.ceil(window * context.sample_rate / low) + 1)
        holds = rng.integers(low, high, size=count, endpoint=True)
        levels = rng.normal(0.0, self.std, size=count)
        if self.clip:
            levels = np.clip(levels, *context.bounds)
        switches = np.cumsum(holds)  # sample index at which level j + 1 begins
        sample_rate = context.sample_rate

        def evaluate(tau: np.ndarray) -> np.ndarray:
            index = np.searchsorted(switches, _sample_index(tau, sample_rate), side="right")
            return levels[np.minimum(index, count - 1)]
        return evaluate


@register_signal
@dataclass(frozen=True, kw_only=True)
class Ramps(Signal):
    """Triangular ramps: up by `height` at slope `gradient` [unit/s], hold, back down, hold.

    One cycle lasts :math:`2 |h| / g + 2 t_\\mathrm{hold}`; after `repetitions` cycles the signal
    stays at zero. A negative height ramps downwards first.
    """

    kind: ClassVar[str] = "ramps"
    repetitions: int
    height: float
    gradient: float
    hold_time: float = 0.0

    def _check(self) -> None:
        _require(self.repetitions >= 1, "repetitions", self.repetitions, "must be >= 1")
        _require(math.isfinite(self.height) and self.height != 0.0, "height", self.height,
                 "must be finite and non-zero")
        _require(math.isfinite(self.gradient) and self.gradient > 0.0, "gradient",
                 self.gradient, "must be > 0 (unit per second)")
        _require(math.isfinite(self.hold_time) and self.hold_time >= 0.0, "hold_time",
                 self.hold_time, "must be >= 0 s")

    def _build(self, rng, context, window):
        rise = abs(self.height) / self.gradient
        cycle = 2.0 * (rise + self.hold_time)
        # knots of one cycle: up, hold at the top, down, hold at the bottom
        knots = np.array([0.0, rise, rise + self.hold_time, 2.0 * rise + self.hold_time, cycle])
        heights = np.array([0.0, self.height, self.height, 0.0, 0.0])

        def evaluate(tau: np.ndarray) -> np.ndarray:
            values = np.interp(np.mod(tau, cycle), knots, heights)
            return np.where(tau < self.repetitions * cycle, values, 0.0)
        return evaluate


@register_signal
@dataclass(frozen=True, kw_only=True)
class Steps(Signal):
    """A staircase of `count` steps of `height`, each held `hold_time` [s].

    Level :math:`(j + 1) h` on :math:`j t_\\mathrm{hold} \\le \\tau < (j + 1) t_\\mathrm{hold}`;
    with ``descend`` the staircase then comes back down step by step to zero, otherwise it stays
    at the top level.
    """

    kind: ClassVar[str] = "steps"
    count: int
    height: float
    hold_time: float
    descend: bool = True

    def _check(self) -> None:
        _require(self.count >= 1, "count", self.count, "must be >= 1")
        _require(math.isfinite(self.height), "height", self.height, "must be finite")
        _require(math.isfinite(self.hold_time) and self.hold_time > 0.0, "hold_time",
                 self.hold_time, "must be > 0 s")

    def _build(self, rng, context, window):
        up = np.arange(1, self.count + 1)
        down = np.arange(self.count - 1, -1, -1) if self.descend else np.array([self.count])
        levels = self.height * np.concatenate([up, down]).astype(float)
        sample_rate = context.sample_rate
        hold_samples = self.hold_time * sample_rate

        def evaluate(tau: np.ndarray) -> np.ndarray:
            index = np.floor(_sample_index(tau, sample_rate) / hold_samples + _INDEX_TOLERANCE)
            return levels[np.minimum(index.astype(np.int64), levels.size - 1)]
        return evaluate


_UNIT_FACTORS: dict[str, dict[str, float]] = {  # file unit -> factor to the channel unit
    "m": {"m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6},
    "bar": {"bar": 1.0, "mbar": 1e-3, "Pa": 1e-5, "kPa": 1e-2, "MPa": 10.0},
}


@register_signal
@dataclass(frozen=True, kw_only=True)
class Replay(Signal):
    """Replay of a recorded or computed sequence from a CSV file, e.g. the catenary sequence.

    The file's first column is ``time [s]``, a further column named `column` holds the values
    (header ``name [unit]`` as written by :meth:`panto.fmu_src.response.TimeResponse.to_csv`, e.g.
    ``contact_wire_displacement [m]`` from the catenary co-simulation; thesis Fig. 3.4 shows its
    periodic 0.72 s sequence at 300 km/h). The unit comes from the header, from a JSON file beside
    the CSV (``<file>.csv.json`` or ``<file>.json`` with ``{"units": {column: unit}}``) or from
    the field `unit`; they must agree, and the values are converted to the channel unit (a length
    to metres, a pressure to bar) or refused. A relative `path` is taken from the profile's folder.

    Playback starts at the file's first sample, interpolated ``"linear"`` or held (``"previous"``)
    between samples, multiplied by `scale` after removing the mean when `remove_mean` is set.
    With `periodic` the sequence repeats with `period` [s] (default: from the JSON file's
    ``"period"``, else the number of samples times the uniform sample step, i.e. the file holds
    one period without repeating its first sample); otherwise the last value is held.
    """

    kind: ClassVar[str] = "replay"
    path: str
    column: str
    unit: str | None = None
    scale: float = 1.0
    periodic: bool = True
    period: float | None = None
    interpolation: str = "linear"
    remove_mean: bool = False

    def _check(self) -> None:
        _require(bool(self.path), "path", self.path, "must name a CSV file")
        _require(math.isfinite(self.scale), "scale", self.scale, "must be finite")
        _require(self.interpolation in ("linear", "previous"), "interpolation",
                 self.interpolation, "must be 'linear' or 'previous'")
        if self.period is not None:
            _require(math.isfinite(self.period) and self.period > 0.0, "period", self.period,
                     "must be > 0 s")

    def resolve(self, base_dir: Path | None) -> Path:
        """The file to read: `path`, relative to `base_dir` when it is relative."""
        path = Path(self.path).expanduser()
        return path if path.is_absolute() or base_dir is None else Path(base_dir) / path

    def read(self, context: RealiseContext) -> tuple[np.ndarray, np.ndarray, float | None]:
        """Times [s], values in the channel unit and the period [s] (None if not periodic)."""
        from panto.fmu_src.response import TimeResponse

        path = self.resolve(context.base_dir)
        if not path.is_file():
            raise ValueError(f"path = {self.path!r}: file {path} not found")
        response = TimeResponse.from_csv(path)  # ValueError naming the file on bad content
        if self.column not in response.names:
            raise ValueError(f"{path}: column = {self.column!r} not found; columns are "
                             f"{list(response.names)}")
        side = {}
        for candidate in (path.with_name(path.name + ".json"), path.with_suffix(".json")):
            if candidate.is_file():
                side = json.loads(candidate.read_text(encoding="utf-8"))
                break
        declared = {u for u in (response.units[self.column],
                                (side.get("units") or {}).get(self.column), self.unit) if u}
        if len(declared) > 1:
            raise ValueError(f"{path}: column {self.column!r} has conflicting units "
                             f"{sorted(declared)} (header, JSON file, field 'unit')")
        if not declared:
            raise ValueError(f"{path}: no unit for column {self.column!r}; give it in the "
                             "header ('name [unit]'), in the JSON file or in the field 'unit'")
        unit = declared.pop()
        factors = _UNIT_FACTORS.get(context.unit, {context.unit: 1.0})
        if unit not in factors:
            raise ValueError(f"{path}: column {self.column!r} is in {unit!r}, which cannot be "
                             f"converted to the channel unit {context.unit!r}")
        time, values = response.time, response[self.column] * factors[unit]
        if not np.all(np.isfinite(values)):
            raise ValueError(f"{path}: column {self.column!r} holds non-finite values")
        period = self.period if self.period is not None else side.get("period")
        if self.periodic and period is None:
            steps = np.diff(time)
            if steps.size == 0 or np.ptp(steps) > 1e-9 * max(1.0, float(time[-1])):
                raise ValueError(f"{path}: samples are not uniform; give the field 'period'")
            period = time.size * float(np.mean(steps))
        if self.periodic and time[-1] - time[0] > period + 1e-12:
            raise ValueError(f"{path}: period = {period} s is shorter than the file "
                             f"({time[-1] - time[0]} s)")
        return time, values, (float(period) if self.periodic else None)

    def _build(self, rng, context, window):
        time, values, period = self.read(context)
        if self.remove_mean:
            values = values - np.mean(values)
        values = self.scale * values
        if period is not None and time[-1] < time[0] + period:  # close the loop for wrapping
            time = np.append(time, time[0] + period)
            values = np.append(values, values[0])

        def evaluate(tau: np.ndarray) -> np.ndarray:
            local = time[0] + (np.mod(tau, period) if period is not None else tau)
            if self.interpolation == "linear":
                return np.interp(local, time, values)
            index = np.searchsorted(time, local + 1e-12, side="right") - 1
            return values[np.clip(index, 0, values.size - 1)]
        return evaluate


@register_signal
@dataclass(frozen=True, kw_only=True)
class Multisine(Signal):
    """Odd random-phase multisine with detection lines, scaled to an rms or a peak value.

    .. math:: x(\\tau) = A \\sum_{k \\in \\mathcal{K}} \\cos(2 \\pi k f_0 \\tau + \\varphi_k),
              \\quad f_0 = 1/P,

    with :math:`\\mathcal{K}` the odd harmonics :math:`k` with :math:`f_\\mathrm{min} \\le k f_0
    \\le f_\\mathrm{max}`, from which one line chosen at random in every group of
    `detection_group` consecutive odd harmonics is left out (a detection line for odd
    nonlinear distortions; the empty even lines detect even ones), independent phases
    :math:`\\varphi_k \\sim U[0, 2\\pi)`, and a flat amplitude :math:`A`. Given `rms`,
    :math:`A = x_\\mathrm{rms} \\sqrt{2/|\\mathcal{K}|}`; given `peak`, :math:`A` makes the largest
    sample of a period equal to it (Pintelon & Schoukens 2012, sec. 3.4 and 4.2). The period
    :math:`P` must be a whole number of samples and the active window a whole number of periods,
    so the run holds the multisine's spectrum without leakage; values are defined on the sample
    grid and held between samples.
    """

    kind: ClassVar[str] = "multisine"
    period: float
    f_max: float
    f_min: float = 0.0
    detection_group: int = 3
    rms: float | None = None
    peak: float | None = None

    def _check(self) -> None:
        _require(math.isfinite(self.period) and self.period > 0.0, "period", self.period,
                 "must be > 0 s")
        _require(math.isfinite(self.f_max) and self.f_max >= 1.0 / self.period, "f_max",
                 self.f_max, f"must be >= the base frequency 1/period = {1 / self.period} Hz")
        _require(0.0 <= self.f_min <= self.f_max, "f_min", self.f_min, "must be in [0, f_max]")
        _require(self.detection_group == 0 or self.detection_group >= 2, "detection_group",
                 self.detection_group, "must be 0 (no detection lines) or >= 2")
        _require((self.rms is None) != (self.peak is None), "rms", self.rms,
                 "give exactly one of rms and peak")
        scale = self.rms if self.rms is not None else self.peak
        _require(math.isfinite(scale) and scale > 0.0, "rms" if self.rms else "peak", scale,
                 "must be > 0")

    def harmonics(self, rng: np.random.Generator) -> np.ndarray:
        """The excited harmonic numbers :math:`\\mathcal{K}` (detection lines drawn from `rng`)."""
        base = 1.0 / self.period
        odd = np.arange(1, int(math.floor(self.f_max / base + 1e-9)) + 1, 2)
        odd = odd[odd * base >= self.f_min - 1e-12]
        group = self.detection_group
        if group == 0 or odd.size < group:
            return odd
        keep = np.ones(odd.size, dtype=bool)
        full = odd.size // group
        keep[np.arange(full) * group + rng.integers(0, group, size=full)] = False
        return odd[keep]

    def _build(self, rng, context, window):
        fs = context.sample_rate
        per_period = self.period * fs
        _require(abs(per_period - round(per_period)) < 1e-6, "period", self.period,
                 f"must be a whole number of samples at {fs} Hz")
        periods = window / self.period
        _require(abs(periods - round(periods)) < 1e-6 and round(periods) >= 1, "period",
                 self.period, f"the active window of {window} s must hold a whole number of "
                 "periods")
        _require(self.f_max < fs / 2.0, "f_max", self.f_max,
                 f"must be below the Nyquist frequency {fs / 2} Hz")
        lines = self.harmonics(rng)
        phases = rng.uniform(0.0, 2.0 * np.pi, size=lines.size)
        n = int(round(per_period))
        grid = np.arange(n) / n
        table = np.zeros(n)
        for line, phase in zip(lines, phases):
            table += np.cos(2.0 * np.pi * line * grid + phase)
        amplitude = (self.rms * math.sqrt(2.0 / lines.size) if self.rms is not None
                     else self.peak / float(np.max(np.abs(table))))
        table *= amplitude

        def evaluate(tau: np.ndarray) -> np.ndarray:
            return table[np.mod(_sample_index(tau, fs), n)]
        return evaluate
