"""Run profiles: what the rig does in one run, as a JSON file a user can write.

A profile holds both inputs of the rig (thesis section 3.1): the linear-motor position demand [m]
and the bellow pressure demand [bar], each an offset plus a list of signals
(:mod:`panto.rig.signals`) that are summed; the sample rate (500 Hz, the thesis' real-time unit), the
duration, the safety limits, the conditioning options of the motor command
(:mod:`panto.rig.conditioning`), the LED sequence (:mod:`panto.rig.sync_led`), a seed and notes::

    {"format": "panto-rig-profile", "version": 1, "name": "aprbs", "duration": 120,
     "sample_rate": 500, "seed": 7,
     "limits": {"motor_min": 0.02, "motor_max": 0.28, "safe_pressure": 3.0},
     "motor": {"offset": 0.15, "signals": [{"kind": "aprbs", "std": 0.02,
                                            "hold_min": 0.2, "hold_max": 2.0}]},
     "pressure": {"offset": 4.0, "signals": []}}

:func:`load_profile` checks everything and renders the run once to make sure no demand leaves the
limits; errors name the file, the field and the value. :func:`render_profile` gives the run as
arrays, :class:`ProfileStream` sample by sample; both give identical values.

Randomness: the seed makes a :class:`numpy.random.SeedSequence`; the motor's signals, the
pressure's signals and the LED each get their own child stream, so editing one channel does not
change the others.
"""
from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import MISSING, dataclass, field, fields
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from panto.rig.conditioning import ConditioningOptions, MotorLimits
from panto.rig.signals import RealiseContext, Signal, parse_field, signal_from_dict
from panto.rig.sync_led import LedOptions, generate_led_bits

FORMAT = "panto-rig-profile"
VERSION = 1
CHANNEL_UNITS = {"motor": "m", "pressure": "bar"}


class ProfileError(ValueError):
    """A profile is malformed or unsafe; the message names the file, field and value."""


@dataclass(frozen=True, kw_only=True)
class SafetyLimits:
    """Limits every demand must respect.

    Parameters
    ----------
    motor_min, motor_max : float
        Motor position range [m] (required: the stroke is about 0.3 m, thesis chapter 3).
    motor_max_step : float
        Largest position change per 250 Hz stream sample [m] (5 mm, thesis Fig. 3.6).
    pressure_min, pressure_max : float
        Bellow pressure range [bar] (the valve delivers 0-7.5 bar).
    safe_pressure : float
        Pressure the bellow returns to when a run stops or faults [bar] (required).
    """

    motor_min: float
    motor_max: float
    safe_pressure: float
    motor_max_step: float = 0.005
    pressure_min: float = 0.0
    pressure_max: float = 7.5

    def __post_init__(self) -> None:
        if not (math.isfinite(self.motor_min) and math.isfinite(self.motor_max)
                and self.motor_min < self.motor_max):
            raise ValueError(f"motor_max = {self.motor_max!r}: must be finite and above "
                             f"motor_min = {self.motor_min!r}")
        if not (math.isfinite(self.motor_max_step) and self.motor_max_step > 0.0):
            raise ValueError(f"motor_max_step = {self.motor_max_step!r}: must be > 0 m")
        if not (0.0 <= self.pressure_min < self.pressure_max <= 10.0):
            raise ValueError(f"pressure_max = {self.pressure_max!r}: need 0 <= pressure_min "
                             f"({self.pressure_min!r}) < pressure_max <= 10 bar (supply)")
        if not self.pressure_min <= self.safe_pressure <= self.pressure_max:
            raise ValueError(f"safe_pressure = {self.safe_pressure!r}: must lie in "
                             f"[{self.pressure_min}, {self.pressure_max}] bar")

    def motor_limits(self) -> MotorLimits:
        """The limits in the form :class:`panto.rig.conditioning.MotorConditioner` takes."""
        return MotorLimits(position_min=self.motor_min, position_max=self.motor_max,
                           max_step=self.motor_max_step)


@dataclass(frozen=True, kw_only=True)
class ChannelProfile:
    """One input channel: a constant offset plus the sum of `signals` (channel unit)."""

    offset: float
    signals: tuple[Signal, ...] = ()


@dataclass(frozen=True, kw_only=True)
class Profile:
    """One rig run. See the module docstring for the file layout; `base_dir` (the profile's
    folder, for relative replay files) is not written to the file."""

    name: str
    duration: float
    limits: SafetyLimits
    motor: ChannelProfile
    pressure: ChannelProfile
    sample_rate: float = 500.0
    seed: int = 0
    conditioning: ConditioningOptions = field(default_factory=ConditioningOptions)
    led: LedOptions = field(default_factory=LedOptions)
    notes: str = ""
    base_dir: Path | None = field(default=None, compare=False)

    @property
    def sample_count(self) -> int:
        """Number of samples :math:`n = T f_s` (time :math:`k / f_s`, :math:`k = 0..n-1`)."""
        return int(round(self.duration * self.sample_rate))

    def context(self, channel: str) -> RealiseContext:
        """The realisation context of `channel` (``"motor"`` or ``"pressure"``)."""
        low, high = ((self.limits.motor_min, self.limits.motor_max) if channel == "motor"
                     else (self.limits.pressure_min, self.limits.pressure_max))
        offset = getattr(self, channel).offset
        return RealiseContext(duration=self.duration, sample_rate=self.sample_rate,
                              bounds=(low - offset, high - offset), unit=CHANNEL_UNITS[channel],
                              base_dir=self.base_dir)


# --- reading and writing -------------------------------------------------------------------


def _parse_options(cls: type, data: Any, where: str) -> Any:
    """Build the frozen dataclass `cls` from a JSON object, naming `where` on any error."""
    if not isinstance(data, Mapping):
        raise ProfileError(f"{where}: must be an object, got {data!r}")
    known = {f.name: f for f in fields(cls) if f.init and f.name not in ("base_dir",)}
    unknown = sorted(set(data) - set(known))
    if unknown:
        raise ProfileError(f"{where}: unknown field(s) {unknown}; fields are {sorted(known)}")
    missing = [name for name, f in known.items()
               if f.default is MISSING and f.default_factory is MISSING and name not in data]
    if missing:
        raise ProfileError(f"{where}: required field(s) {missing} missing")
    try:
        values = {name: parse_field(str(known[name].type), value, name)
                  for name, value in data.items()}
        return cls(**values)
    except ValueError as error:
        raise ProfileError(f"{where}: {error}") from None


def _parse_channel(data: Any, where: str) -> ChannelProfile:
    if not isinstance(data, Mapping):
        raise ProfileError(f"{where}: must be an object with 'offset' and 'signals'")
    unknown = sorted(set(data) - {"offset", "signals"})
    if unknown:
        raise ProfileError(f"{where}: unknown field(s) {unknown}; fields are "
                           "['offset', 'signals']")
    try:
        offset = parse_field("float", data.get("offset"), "offset")
    except ValueError as error:
        raise ProfileError(f"{where}: {error}") from None
    items = data.get("signals", [])
    if not isinstance(items, list):
        raise ProfileError(f"{where}.signals: must be a list, got {items!r}")
    signals = []
    for index, item in enumerate(items):
        try:
            signals.append(signal_from_dict(item))
        except ValueError as error:
            raise ProfileError(f"{where}.signals[{index}]: {error}") from None
    return ChannelProfile(offset=offset, signals=tuple(signals))


def profile_from_dict(data: Mapping[str, Any], *, source: str = "profile",
                      base_dir: Path | None = None, check: bool = True) -> Profile:
    """Build (and by default :func:`check_profile`) a profile from its JSON object."""
    if not isinstance(data, Mapping):
        raise ProfileError(f"{source}: a profile must be a JSON object")
    if data.get("format", FORMAT) != FORMAT or data.get("version", VERSION) != VERSION:
        raise ProfileError(f"{source}: format/version = {data.get('format')!r}/"
                           f"{data.get('version')!r}: expected {FORMAT!r}/{VERSION}")
    top = {"format", "version", "name", "notes", "duration", "sample_rate", "seed", "limits",
           "conditioning", "led", "motor", "pressure"}
    unknown = sorted(set(data) - top)
    if unknown:
        raise ProfileError(f"{source}: unknown field(s) {unknown}; fields are {sorted(top)}")
    for required in ("duration", "limits", "motor", "pressure"):
        if required not in data:
            raise ProfileError(f"{source}: field {required!r} is missing")
    try:
        scalars = {"name": parse_field("str", data.get("name", source), "name"),
                   "notes": parse_field("str", data.get("notes", ""), "notes"),
                   "duration": parse_field("float", data["duration"], "duration"),
                   "sample_rate": parse_field("float", data.get("sample_rate", 500.0),
                                               "sample_rate"),
                   "seed": parse_field("int", data.get("seed", 0), "seed")}
    except ValueError as error:
        raise ProfileError(f"{source}: {error}") from None
    profile = Profile(
        **scalars, base_dir=base_dir,
        limits=_parse_options(SafetyLimits, data["limits"], f"{source}: limits"),
        conditioning=_parse_options(ConditioningOptions, data.get("conditioning", {}),
                                    f"{source}: conditioning"),
        led=_parse_options(LedOptions, data.get("led", {}), f"{source}: led"),
        motor=_parse_channel(data["motor"], f"{source}: motor"),
        pressure=_parse_channel(data["pressure"], f"{source}: pressure"))
    if check:
        check_profile(profile, source=source)
    return profile


def profile_to_dict(profile: Profile) -> dict[str, Any]:
    """The JSON object of a profile (inverse of :func:`profile_from_dict`)."""
    def options(value: Any) -> dict[str, Any]:
        return {f.name: getattr(value, f.name) for f in fields(value)}

    def channel(value: ChannelProfile) -> dict[str, Any]:
        return {"offset": value.offset, "signals": [s.to_dict() for s in value.signals]}

    return {"format": FORMAT, "version": VERSION, "name": profile.name, "notes": profile.notes,
            "duration": profile.duration, "sample_rate": profile.sample_rate,
            "seed": profile.seed, "limits": options(profile.limits),
            "conditioning": options(profile.conditioning), "led": options(profile.led),
            "motor": channel(profile.motor), "pressure": channel(profile.pressure)}


def load_profile(path: str | Path) -> Profile:
    """Read, validate and safety-check a profile file.

    Raises
    ------
    ProfileError
        Naming the file, the field and the value (unknown signal kind, negative hold time, a
        demand outside the limits, ...). OSError if the file cannot be read.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as error:
        raise ProfileError(f"{path}: not valid JSON ({error})") from None
    return profile_from_dict(data, source=str(path), base_dir=path.resolve().parent)


def save_profile(profile: Profile, path: str | Path, *, overwrite: bool = False) -> Path:
    """Write a profile as JSON; refuses to replace an existing file unless `overwrite`."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path}: exists; pass overwrite=True to replace it")
    path.write_text(json.dumps(profile_to_dict(profile), indent=2) + "\n", encoding="utf-8")
    return path


# --- rendering ------------------------------------------------------------------------------


Evaluator = Callable[[np.ndarray], np.ndarray]


class _Realised(NamedTuple):
    motor: list[Evaluator]
    pressure: list[Evaluator]
    led_rng: np.random.Generator


def _realise(profile: Profile) -> _Realised:
    motor_seed, pressure_seed, led_seed = np.random.SeedSequence(profile.seed).spawn(3)
    realised = []
    for channel, seed in (("motor", motor_seed), ("pressure", pressure_seed)):
        signals = getattr(profile, channel).signals
        context = profile.context(channel)
        evaluators = []
        for index, (signal, child) in enumerate(zip(signals, seed.spawn(len(signals)))):
            try:
                evaluators.append(signal.realise(np.random.default_rng(child), context))
            except ValueError as error:
                raise ValueError(f"{channel}.signals[{index}] ({signal.kind}): {error}") from None
        realised.append(evaluators)
    return _Realised(realised[0], realised[1], np.random.default_rng(led_seed))


def _channel_parts(evaluators: list[Evaluator], time: np.ndarray) -> np.ndarray:
    """Each signal's contribution, shape (signals, samples)."""
    return np.array([evaluate(time) for evaluate in evaluators]).reshape(-1, time.size)


def _motor_and_pressure(profile: Profile, realised: _Realised,
                        time: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Dynamic motor part (clipped into the limits) and pressure demand at `time`."""
    lim, motor = profile.limits, profile.motor
    dynamic = _channel_parts(realised.motor, time).sum(axis=0)
    dynamic = np.clip(dynamic, lim.motor_min - motor.offset, lim.motor_max - motor.offset)
    pressure = profile.pressure.offset + _channel_parts(realised.pressure, time).sum(axis=0)
    return dynamic, np.clip(pressure, lim.pressure_min, lim.pressure_max)


@dataclass(frozen=True)
class RenderedProfile:
    """A run as arrays at the profile's sample rate: time [s], motor offset and dynamic part [m],
    pressure demand [bar] and LED bits."""

    time: np.ndarray
    motor_offset: np.ndarray
    motor_dynamic: np.ndarray
    pressure_demand: np.ndarray
    led: np.ndarray

    @property
    def motor_demand(self) -> np.ndarray:
        """Offset plus dynamic part [m]."""
        return self.motor_offset + self.motor_dynamic

    def to_response(self):
        """As a :class:`panto.fmu_src.response.TimeResponse`: ``motor_demand`` and its two parts
        [m], ``pressure_demand`` [bar] and ``led`` [1]."""
        from panto.fmu_src.response import TimeResponse

        return TimeResponse(self.time, {
            "motor_demand": self.motor_demand, "motor_offset": self.motor_offset,
            "motor_dynamic": self.motor_dynamic, "pressure_demand": self.pressure_demand,
            "led": self.led}, units={"motor_demand": "m", "motor_offset": "m",
                                     "motor_dynamic": "m", "pressure_demand": "bar", "led": "1"})


def render_profile(profile: Profile) -> RenderedProfile:
    """The whole run at once (for offline use: the emulator, plots, design of experiments)."""
    realised = _realise(profile)
    count = profile.sample_count
    time = np.arange(count) / profile.sample_rate
    dynamic, pressure = _motor_and_pressure(profile, realised, time)
    led = generate_led_bits(count, realised.led_rng, profile.led,
                            sample_rate=profile.sample_rate)
    return RenderedProfile(time, np.full(count, profile.motor.offset), dynamic, pressure, led)


class ProfileSample(NamedTuple):
    """One sample of a run (same quantities as :class:`RenderedProfile`)."""

    index: int
    time: float
    motor_offset: float
    motor_dynamic: float
    pressure_demand: float
    led: int


class ProfileStream:
    """The run one sample per :meth:`next`, for the real-time loop; equal to :func:`render_profile`.

    Values are computed ahead in chunks of `chunk` samples (1 s at 500 Hz by default), so the
    real-time loop only reads them out.
    """

    def __init__(self, profile: Profile, *, chunk: int = 500) -> None:
        from panto.rig.sync_led import LedStream

        self.profile = profile
        self._realised = _realise(profile)
        self._led = LedStream(self._realised.led_rng, profile.led,
                              sample_rate=profile.sample_rate)
        self._chunk = max(1, int(chunk))
        self._index = 0
        self._buffer: list[tuple[float, float, float]] = []
        self._buffer_start = 0

    def __len__(self) -> int:
        return self.profile.sample_count

    def _fill(self) -> None:
        start = self._index
        stop = min(start + self._chunk, self.profile.sample_count)
        time = np.arange(start, stop) / self.profile.sample_rate
        dynamic, pressure = _motor_and_pressure(self.profile, self._realised, time)
        self._buffer = list(zip(time.tolist(), dynamic.tolist(), pressure.tolist()))
        self._buffer_start = start

    def next(self) -> ProfileSample:
        """The next sample; raises StopIteration after the last."""
        if self._index >= self.profile.sample_count:
            raise StopIteration
        if self._index - self._buffer_start >= len(self._buffer):
            self._fill()
        time, dynamic, pressure = self._buffer[self._index - self._buffer_start]
        sample = ProfileSample(self._index, time, self.profile.motor.offset, dynamic, pressure,
                               self._led.next())
        self._index += 1
        return sample

    def __iter__(self) -> Iterator[ProfileSample]:
        return self

    __next__ = next


# --- checks ---------------------------------------------------------------------------------


def _check_channel(profile: Profile, channel: str, parts: np.ndarray, time: np.ndarray,
                   source: str) -> None:
    """Refuse a channel whose demand leaves its limits, naming the largest contribution."""
    spec: ChannelProfile = getattr(profile, channel)
    low, high = ((profile.limits.motor_min, profile.limits.motor_max) if channel == "motor"
                 else (profile.limits.pressure_min, profile.limits.pressure_max))
    unit = CHANNEL_UNITS[channel]
    if not low <= spec.offset <= high:
        raise ProfileError(f"{source}: {channel}.offset = {spec.offset!r} {unit}: outside the "
                           f"limits [{low}, {high}] {unit}")
    demand = spec.offset + parts.sum(axis=0)
    outside = np.flatnonzero((demand < low - 1e-12) | (demand > high + 1e-12))
    if outside.size == 0:
        return
    k = int(outside[0])
    culprit = int(np.argmax(np.abs(parts[:, k])))
    signal = spec.signals[culprit]
    settings = {n: v for n, v in signal.to_dict().items() if n not in ("kind", "start", "stop")}
    raise ProfileError(
        f"{source}: {channel}.signals[{culprit}] ({signal.kind}, {settings}): the {channel} "
        f"demand reaches {demand[k]:.6g} {unit} at t = {time[k]:.6g} s, outside the limits "
        f"[{low}, {high}] {unit}; reduce the amplitude or the offset")


def check_profile(profile: Profile, *, source: str = "profile") -> None:
    """Check the run as a whole: whole samples, stream rate, and every demand inside the limits.

    The check renders the run with its seed (the realisation the rig will play), so random
    signals are judged by their actual values.
    """
    fs, stream = profile.sample_rate, profile.conditioning.sample_rate
    if not (math.isfinite(fs) and fs > 0.0):
        raise ProfileError(f"{source}: sample_rate = {fs!r}: must be > 0 Hz")
    if not (math.isfinite(profile.duration) and profile.duration > 0.0):
        raise ProfileError(f"{source}: duration = {profile.duration!r}: must be > 0 s")
    if abs(profile.duration * fs - profile.sample_count) > 1e-6:
        raise ProfileError(f"{source}: duration = {profile.duration!r}: must be a whole number "
                           f"of samples at {fs} Hz")
    ratio = fs / stream
    if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
        raise ProfileError(f"{source}: sample_rate = {fs!r}: must be a whole multiple of the "
                           f"motor stream rate conditioning.sample_rate = {stream} Hz")
    if profile.seed < 0:
        raise ProfileError(f"{source}: seed = {profile.seed!r}: must be >= 0")
    try:
        realised = _realise(profile)
        time = np.arange(profile.sample_count) / fs
        for channel in ("motor", "pressure"):
            parts = _channel_parts(getattr(realised, channel), time)
            _check_channel(profile, channel, parts, time, source)
    except ProfileError:
        raise
    except ValueError as error:
        raise ProfileError(f"{source}: {error}") from None
