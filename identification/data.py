"""From recorded runs to :class:`~identification.base.IdentificationData` (thesis section 4.2).

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
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from identification.base import IdentificationData, IdentificationError

Channel = str | Callable[[Any], np.ndarray]
#: Units of the pantograph's identification signals.
PANTOGRAPH_UNITS = {"eta": "m", "p": "bar", "F_c": "N", "y_cb": "m", "xi": "m"}


def data_from_dataset(dataset: Any, *, inputs: Mapping[str, Channel],
                      outputs: Mapping[str, Channel], rate: float | None = 50.0,
                      source: str | None = None, units: Mapping[str, str] | None = None,
                      start: float | None = None, stop: float | None = None,
                      fill_inputs: bool = True,
                      fill_channels: Sequence[str] = ()) -> IdentificationData:
    """Identification data from a :class:`rig.dataset.Dataset` (or a path to one).

    Parameters
    ----------
    dataset : rig.dataset.Dataset or path
    inputs, outputs : mapping of name to channel name or callable
        A callable receives the (resampled) dataset and returns the signal.
    rate : float or None
        Resample to this rate first (:func:`identification.preprocessing.resample_dataset`, zero-
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
        from identification.preprocessing import resample_dataset

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
    keep = np.ones(len(time), bool)
    if start is not None:
        keep &= time >= start
    if stop is not None:
        keep &= time < stop
    if keep.sum() < 2:
        raise IdentificationError(f"{source}: fewer than two samples in [{start}, {stop}) s")
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


def pantograph_data(dataset: Any, *, rate: float | None = 50.0,
                    outputs: Sequence[str] = ("F_c", "y_cb"), eta_offset: float | None = None,
                    start: float | None = None, stop: float | None = None,
                    cross_bar: str = "laser") -> IdentificationData:
    """The rig run's identification data: inputs (eta, p), outputs among (F_c, y_cb).

    Parameters
    ----------
    dataset : rig.dataset.Dataset, or a run folder / dataset file
    rate : float or None
        Identification rate [Hz] (thesis: 50 Hz).
    outputs : sequence of str
        Any of ``"F_c"``, ``"y_cb"``.
    eta_offset : float, optional
        Height [m] of the motor's zero; default ``metadata.extra["rig_setup"]["motor_zero_height"]``.
    start, stop : float, optional
        Time window [s].
    cross_bar : {"laser", "video"}
        Source of ``y_cb``: the two lasers (mean of the valid ones) or ``video_cross_bar_y``.

    Raises
    ------
    IdentificationError
        Without an eta offset, with unknown outputs or a missing channel.
    """
    source = str(dataset) if isinstance(dataset, (str, Path)) else "dataset"
    dataset = _read(dataset)
    offset = eta_offset if eta_offset is not None else motor_zero_height(dataset, source)
    if cross_bar not in ("laser", "video"):
        raise IdentificationError(f"cross_bar {cross_bar!r}: choose 'laser' or 'video'")
    makers: dict[str, Channel] = {"F_c": "force", "y_cb": _cross_bar_laser
                                  if cross_bar == "laser" else "video_cross_bar_y"}
    unknown = [o for o in outputs if o not in makers]
    if unknown or not outputs:
        raise IdentificationError(f"{source}: outputs {list(outputs)}: choose from {list(makers)}")
    return data_from_dataset(
        dataset, inputs={"eta": lambda d: offset + np.asarray(d["motor_position"], float),
                         "p": "pressure"},
        outputs={o: makers[o] for o in outputs}, rate=rate, source=source,
        units=PANTOGRAPH_UNITS, start=start, stop=stop, fill_channels=("motor_position",))


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
        from rig.dataset import read_dataset

        return read_dataset(dataset, required=())
    return dataset
