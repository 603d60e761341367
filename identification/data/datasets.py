"""From recorded runs to :class:`~panto.identification.estimation.base.IdentificationData` (thesis section 4.2).

:func:`data_from_dataset` maps any dataset's channels (or functions of them) to named inputs
and outputs, resampled to the identification rate; it works for any system (the sim-to-real
diagnosis uses it on other machines' data). :func:`pantograph_data` is the rig's mapping:

- ``eta = motor_zero_height + motor_position``: the slider position is relative to the height
  at which the drive's zero sits (``metadata.extra["rig_setup"]["motor_zero_height"]``, or
  ``eta_offset``); missing drive replies (NaN) are interpolated linearly and counted;
- ``p = pressure`` [bar];
- ``F_c = force`` [N];
- ``y_cb`` = the mean of the two lasers where both are valid, the one that is valid otherwise
  (``cross_bar="laser"``), or the video channel ``video_cross_bar_y`` (``cross_bar="video"``).

The drive reports the slider position late (the rig's drive answers each SYNC with the position
sampled at that SYNC, which the master reads one 250 Hz cycle later and the recorder holds for two
500 Hz samples: on average 5 ms). ``pantograph_data(position_latency=...)`` (or the set-up fact
``metadata.extra["rig_setup"]["position_latency"]``) advances ``motor_position`` by that latency with
:func:`delay_signal`, a band-limited fractional delay.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from panto.identification.estimation.base import IdentificationData, IdentificationError

Channel = str | Callable[[Any], np.ndarray]
#: Units of the pantograph's identification signals.
PANTOGRAPH_UNITS = {"eta": "m", "p": "bar", "F_c": "N", "y_cb": "m", "xi": "m"}


def data_from_dataset(dataset: Any, *, inputs: Mapping[str, Channel],
                      outputs: Mapping[str, Channel], rate: float | None = 50.0,
                      source: str | None = None, units: Mapping[str, str] | None = None,
                      start: float | None = None, stop: float | None = None,
                      fill_inputs: bool = True,
                      fill_channels: Sequence[str] = ()) -> IdentificationData:
    """Identification data from a :class:`panto.rig.dataset.Dataset` (or a path to one).

    Parameters
    ----------
    dataset : panto.rig.dataset.Dataset or path
    inputs, outputs : mapping of name to channel name or callable
        A callable receives the (resampled) dataset and returns the signal.
    rate : float or None
        Resample to this rate first (:func:`panto.identification.data.preprocessing.resample_dataset`, zero-
        phase low-pass and decimation); None keeps the recording rate.
    source : str, optional
        For messages (default: the dataset's path or "dataset").
    units : mapping, optional
        Units per signal name (default: the channel's unit for plain channels).
    start, stop : float, optional
        Keep ``start <= t < stop`` [s] (after resampling).
    fill_inputs : bool
        Interpolate NaN input samples linearly (their count goes to
        ``metadata["filled_input_samples"]``); otherwise NaN inputs are an error.
    fill_channels : sequence of str
        Channels whose NaN samples are interpolated at the recording rate, before resampling
        (counts in ``metadata["filled_channel_samples"]``).
    """
    source = source or str(getattr(dataset, "path", "") or "dataset")
    dataset = _read(dataset)
    dataset, filled_channels = _fill_channels(dataset, fill_channels, source)
    if rate is not None and not math.isclose(rate, dataset.metadata.sample_rate):
        from panto.identification.data.preprocessing import resample_dataset

        dataset = resample_dataset(dataset, float(rate))
    input_columns, filled = {}, {}
    for name, channel in inputs.items():
        values = _signal(dataset, channel, name, source)
        if fill_inputs:
            values, filled[name] = fill_gaps(values, dataset.time, name, source)
        input_columns[name] = values
    output_columns = {name: _signal(dataset, channel, name, source)
                      for name, channel in outputs.items()}
    time = np.asarray(dataset.time, float)
    keep = _window(time, start, stop, source)
    given = dict(units or {})
    unit_map = {name: given.get(name, dataset.units.get(ch, "") if isinstance(ch, str) else "")
                for name, ch in {**inputs, **outputs}.items()}
    metadata = {"dataset": dataset.metadata.to_dict(), "rate": float(dataset.metadata.sample_rate),
                "filled_input_samples": filled, "filled_channel_samples": filled_channels,
                "missing_output_samples": {n: int(np.isnan(v[keep]).sum())
                                           for n, v in output_columns.items()}}
    return IdentificationData(
        time[keep], np.column_stack([input_columns[n][keep] for n in inputs]),
        np.column_stack([output_columns[n][keep] for n in outputs]), tuple(inputs),
        tuple(outputs), unit_map, source, metadata)


def _window(time: np.ndarray, start: float | None, stop: float | None,
            source: str) -> np.ndarray:
    """The samples with ``start <= t < stop`` [s] (open ends where None); at least two."""
    keep = np.ones(len(time), bool)
    if start is not None:
        keep &= time >= start
    if stop is not None:
        keep &= time < stop
    if keep.sum() < 2:
        raise IdentificationError(f"{source}: fewer than two samples in [{start}, {stop}) s")
    return keep


def pantograph_data(dataset: Any, *, rate: float | None = 50.0,
                    outputs: Sequence[str] = ("F_c", "y_cb"), eta_offset: float | None = None,
                    start: float | None = None, stop: float | None = None,
                    cross_bar: str = "laser",
                    position_latency: float | None = None) -> IdentificationData:
    """The rig run's identification data: inputs (eta, p), outputs among (F_c, y_cb).

    Parameters
    ----------
    dataset : panto.rig.dataset.Dataset, or a run folder / dataset file
    rate : float or None
        Identification rate [Hz] (thesis: 50 Hz).
    outputs : sequence of str
        Any of ``"F_c"``, ``"y_cb"`` and ``"xi"`` (the head height: the merged video channel
        ``video_pan_head_y``, see :mod:`panto.video_sync.merge`).
    eta_offset : float, optional
        Height [m] of the motor's zero; default ``metadata.extra["rig_setup"]["motor_zero_height"]``.
    start, stop : float, optional
        Time window [s].
    cross_bar : {"laser", "video"}
        Source of ``y_cb``: the two lasers (mean of the valid ones) or ``video_cross_bar_y``.
    position_latency : float, optional
        How late [s] ``motor_position`` reports the slider (a rig set-up fact; default
        ``metadata.extra["rig_setup"]["position_latency"]``, else 0). The channel is advanced by
        it at the recording rate, ``eta(t) = offset + motor_position(t + latency)``
        (:func:`delay_signal`), and the last `latency` seconds, where that would need samples
        after the record, are dropped. Recorded in ``metadata["position_latency"]``.

    Raises
    ------
    IdentificationError
        Without an eta offset, with unknown outputs, a missing channel or a negative latency.
    """
    source = str(dataset) if isinstance(dataset, (str, Path)) else "dataset"
    dataset = _read(dataset)
    offset = eta_offset if eta_offset is not None else motor_zero_height(dataset, source)
    makers = _pantograph_outputs(outputs, cross_bar, source)
    latency = _position_latency(dataset, position_latency, source)
    dataset, filled = _fill_channels(dataset, ("motor_position",), source)
    if latency > 0.0:
        dataset = _advance_channel(dataset, "motor_position", latency)
        end = float(dataset.time[-1]) - latency
        stop = end if stop is None else min(stop, end)
    data = data_from_dataset(
        dataset, inputs={"eta": lambda d: offset + np.asarray(d["motor_position"], float),
                         "p": "pressure"},
        outputs={o: makers[o] for o in outputs}, rate=rate, source=source,
        units=PANTOGRAPH_UNITS, start=start, stop=stop)
    from dataclasses import replace

    return replace(data, metadata={**data.metadata, "filled_channel_samples": filled,
                                   "position_latency": float(latency)})


def _pantograph_outputs(outputs: Sequence[str], cross_bar: str,
                        source: str) -> dict[str, Channel]:
    """The channel (or function of channels) of each pantograph output; checks the names."""
    if cross_bar not in ("laser", "video"):
        raise IdentificationError(f"cross_bar {cross_bar!r}: choose 'laser' or 'video'")
    makers: dict[str, Channel] = {"F_c": "force", "y_cb": _cross_bar_laser
                                  if cross_bar == "laser" else "video_cross_bar_y",
                                  "xi": "video_pan_head_y"}
    unknown = [o for o in outputs if o not in makers]
    if unknown or not outputs:
        raise IdentificationError(f"{source}: outputs {list(outputs)}: choose from {list(makers)}")
    return makers


def _position_latency(dataset: Any, given: float | None, source: str) -> float:
    """The latency [s] of ``motor_position``: `given`, else the rig set-up fact, else 0."""
    latency = given if given is not None else \
        _setup_value(dataset, "position_latency", 0.0, source)
    if not (math.isfinite(latency) and latency >= 0.0):
        raise IdentificationError(f"{source}: position_latency {latency!r} s: give a finite "
                                  "latency >= 0 (how late motor_position reports the slider)")
    return latency


def delay_signal(values: np.ndarray, delay: float, *, half_width: int = 16,
                 beta: float = 8.0) -> np.ndarray:
    """`values` delayed by `delay` samples (any real number; negative advances).

    Band-limited interpolation: ``y[k] = sum_j h_j x[k - n - j]`` with ``n = floor(delay)``,
    ``f = delay - n`` and ``h_j = sinc(f - j) w(f - j)`` for ``j = 1 - L .. L`` (``L`` =
    `half_width`), ``w`` a Kaiser window of shape `beta` lowered to vanish at ``+-L`` (so ``y``
    is continuous in `delay`), the taps normalised to unit sum (constants pass exactly). Up to
    0.4 times the sample rate (the band the 50 Hz identification data keep) the error is about
    1e-4 of the amplitude, where linear interpolation loses 15 % at 0.2 times the rate for
    ``f = 0.3``. Samples outside the record are its end values held (the run starts and ends at
    rest). See Laakso et al., "Splitting the unit delay", IEEE Signal Processing Magazine 13(1),
    1996.
    """
    x = np.asarray(values, float)
    whole = int(math.floor(delay))
    fraction = float(delay) - whole
    taps = np.arange(1 - half_width, half_width + 1)
    s = fraction - taps
    window = (np.i0(beta * np.sqrt(np.clip(1.0 - (s / half_width) ** 2, 0.0, None))) - 1.0) / \
        (np.i0(beta) - 1.0)
    weights = np.sinc(s) * window
    weights /= weights.sum()
    pad = half_width + abs(whole) + 1
    extended = np.concatenate([np.full(pad, x[0]), x, np.full(pad, x[-1])])
    out = np.zeros(len(x))
    for tap, weight in zip(taps, weights):
        if weight != 0.0:
            begin = pad - whole - tap
            out += weight * extended[begin:begin + len(x)]
    return out


def _advance_channel(dataset: Any, name: str, latency: float) -> Any:
    from dataclasses import replace

    period = 1.0 / float(dataset.metadata.sample_rate)
    channels = dict(dataset.channels)
    channels[name] = delay_signal(np.asarray(channels[name], float), -latency / period)
    return replace(dataset, channels=channels)


def _setup_value(dataset: Any, key: str, default: float, source: str) -> float:
    """``metadata.extra["rig_setup"][key]`` as a float (`default` when absent)."""
    setup = dict(dataset.metadata.extra or {}).get("rig_setup") or {}
    value = setup.get(key, default) if isinstance(setup, Mapping) else default
    if not isinstance(value, (int, float)):
        raise IdentificationError(f"{source}: metadata extra.rig_setup.{key} = {value!r} is not "
                                  "a number")
    return float(value)


def motor_zero_height(dataset: Any, source: str = "dataset") -> float:
    """``metadata.extra["rig_setup"]["motor_zero_height"]`` [m], or a clear error."""
    setup = dict(dataset.metadata.extra or {}).get("rig_setup") or {}
    value = setup.get("motor_zero_height") if isinstance(setup, Mapping) else None
    if not isinstance(value, (int, float)) or not math.isfinite(value):
        raise IdentificationError(
            f"{source}: the motor's zero height is unknown (metadata extra.rig_setup."
            "motor_zero_height is missing); give it, e.g. eta_offset=2.0 (--eta-offset 2.0): "
            "the model input is eta = zero height + motor_position")
    return float(value)


def fill_gaps(values: np.ndarray, time: np.ndarray, name: str,
              source: str) -> tuple[np.ndarray, int]:
    """NaN samples replaced by linear interpolation (ends held); returns (values, count)."""
    values = np.array(values, float)
    bad = ~np.isfinite(values)
    if bad.all():
        raise IdentificationError(f"{source}: input {name!r} has no valid sample")
    if bad.any():
        values[bad] = np.interp(time[bad], time[~bad], values[~bad])
    return values, int(bad.sum())


def _fill_channels(dataset: Any, names: Sequence[str], source: str) -> tuple[Any, dict[str, int]]:
    if not names:
        return dataset, {}
    from dataclasses import replace

    channels, counts = dict(dataset.channels), {}
    for name in names:
        if name not in channels:
            raise IdentificationError(f"{source}: no channel {name!r}; channels are "
                                      f"{list(dataset.channels)}")
        channels[name], counts[name] = fill_gaps(channels[name], dataset.time, name, source)
    return replace(dataset, channels=channels), counts


def _cross_bar_laser(dataset: Any) -> np.ndarray:
    lasers = np.column_stack([np.asarray(dataset[n], float) for n in ("laser_1", "laser_2")])
    valid = np.isfinite(lasers)
    total = np.where(valid, lasers, 0.0).sum(axis=1)
    count = valid.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / np.maximum(count, 1), np.nan)


def _signal(dataset: Any, channel: Channel, name: str, source: str) -> np.ndarray:
    if callable(channel):
        try:
            return np.asarray(channel(dataset), float)
        except KeyError as error:
            raise IdentificationError(f"{source}: signal {name!r} needs channel {error}") from None
    if channel not in dataset.channels:
        raise IdentificationError(f"{source}: signal {name!r}: no channel {channel!r}; "
                                  f"channels are {list(dataset.channels)}")
    return np.asarray(dataset[channel], float)


def _read(dataset: Any) -> Any:
    if isinstance(dataset, (str, Path)):
        from panto.rig.dataset import read_dataset

        return read_dataset(dataset, required=())
    return dataset
