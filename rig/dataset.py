"""Datasets: one rig run as a time column, named channels with units, and metadata.

The rig records at 500 Hz (thesis section 4.2); a run is written as CSV (+ a JSON side file for
units and metadata), as Parquet (metadata in the schema) or as a MATLAB .mat file (the thesis'
format). All three round-trip bit-exactly (floats in CSV are written with ``repr``, the shortest
text that reads back to the same double). The file format shared with simulation results (headers,
side file, CSV rows, suffixes) is :mod:`panto.fmu_src.dataformat`.

:data:`STANDARD_CHANNELS` fixes the rig's channel names, units and which may hold NaN (a missing
drive reply, a laser dropout). Every reader runs :func:`check_dataset`, which refuses a malformed
file with a :class:`DatasetError` naming the file, the channel and the problem: a missing required
channel, a duplicated channel, a non-monotonic or non-finite time, NaN where not allowed, a wrong
or unknown unit (converted only with ``convert_units=True``), mismatched lengths.
"""
from __future__ import annotations

import io
import json
import math
import re
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping, Sequence

import numpy as np

from panto.fmu_src.dataformat import (DataFormatError, csv_header, csv_read_options,
                                      data_suffix, format_csv_row, metadata_path_for, parse_header,
                                      read_side_file, read_text_file, write_side_file)

FORMAT = "panto-rig-dataset"
VERSION = 1


class DatasetError(DataFormatError):
    """A dataset or dataset file violates the schema; the message names file, channel, problem."""


@dataclass(frozen=True)
class ChannelSpec:
    """A standard channel: unit, whether NaN (missing sample) is allowed, meaning."""

    unit: str
    allow_nan: bool
    description: str


STANDARD_CHANNELS: Mapping[str, ChannelSpec] = MappingProxyType({
    "motor_demand": ChannelSpec("m", False, "position demand: profile offset + dynamic part"),
    "motor_command": ChannelSpec("m", False, "command streamed to the drive after conditioning"),
    "motor_position": ChannelSpec("m", True, "actual slider position from the drive (NaN: no "
                                             "reply)"),
    "motor_current": ChannelSpec("A", True, "demand current from the drive (NaN: no reply)"),
    "force": ChannelSpec("N", False, "force sensor between slider and aluminium bar"),
    "pressure_demand": ChannelSpec("bar", False, "bellow pressure demand"),
    "pressure": ChannelSpec("bar", False, "measured bellow pressure"),
    "valve_voltage": ChannelSpec("V", False, "valve control voltage from the PI loop"),
    "laser_1": ChannelSpec("m", True, "laser distance sensor 1 on the cross bar (NaN: dropout)"),
    "laser_2": ChannelSpec("m", True, "laser distance sensor 2 on the cross bar (NaN: dropout)"),
    "led": ChannelSpec("1", False, "synchronisation LED bit"),
    "dynamic_gain": ChannelSpec("1", False, "low-pass filtered 'dynamic values' switch"),
    "drive_state": ChannelSpec("1", True, "drive main state (state variable high byte)"),
    "drive_error": ChannelSpec("1", True, "drive logged error code (0: none)"),
})
REQUIRED_CHANNELS = ("motor_demand", "motor_command", "motor_position", "force",
                     "pressure_demand", "pressure", "led")
# unit -> (base unit, factor to it); a channel's unit must be one of these
UNIT_FACTORS: Mapping[str, tuple[str, float]] = MappingProxyType({
    "m": ("m", 1.0), "mm": ("m", 1e-3), "um": ("m", 1e-6), "N": ("N", 1.0), "kN": ("N", 1e3),
    "bar": ("bar", 1.0), "mbar": ("bar", 1e-3), "Pa": ("bar", 1e-5), "kPa": ("bar", 1e-2),
    "MPa": ("bar", 10.0), "A": ("A", 1.0), "mA": ("A", 1e-3), "V": ("V", 1.0),
    "mV": ("V", 1e-3), "1": ("1", 1.0), "s": ("s", 1.0), "ms": ("s", 1e-3),
    "m/s": ("m/s", 1.0), "m/s^2": ("m/s^2", 1.0), "rad": ("rad", 1.0), "Hz": ("Hz", 1.0),
    "degC": ("degC", 1.0),
})
_STATUS = re.compile(r"^(running|complete|aborted: .+)$", re.DOTALL)
_MAT_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,62}$")
_MAT_RESERVED = ("time", "channel_names", "channel_units", "metadata_json")


def software_version() -> str:
    """The installed ``panto`` version (``"unknown"`` when not installed)."""
    from importlib import metadata

    try:
        return metadata.version("panto")
    except metadata.PackageNotFoundError:
        return "unknown"


def _json_ready(value: Any) -> Any:
    """Plain JSON types from mappings, sequences and numpy values."""
    if isinstance(value, Mapping):
        return {str(k): _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v) for v in value]
    if isinstance(value, np.ndarray):
        return _json_ready(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    return value


@dataclass(frozen=True, kw_only=True)
class RunMetadata:
    """What a run is: rate, origin, outcome and context.

    Parameters
    ----------
    sample_rate : float
        Samples per second [Hz].
    source : str
        ``"rig"`` or ``"emulator"``.
    status : str
        ``"running"`` (being recorded), ``"complete"`` or ``"aborted: <reason>"``.
    seed : int or None
        Seed of the profile's random signals.
    profile : mapping or None
        The run's profile, embedded (its JSON object).
    software_version : str
        ``panto`` version that recorded it.
    start_time : str
        ISO 8601 instant the run started (UTC).
    notes : str
    truth : mapping
        What the emulator used to make the data (imperfections, parameters); empty on the rig.
        For tests of the diagnosis only: the diagnosis must never read it.
    extra : mapping
        Anything else.
    """

    sample_rate: float
    source: str
    status: str = "complete"
    seed: int | None = None
    profile: Mapping[str, Any] | None = None
    software_version: str = field(default_factory=software_version)
    start_time: str = field(
        default_factory=lambda: datetime.now(timezone.utc).isoformat(timespec="milliseconds"))
    notes: str = ""
    truth: Mapping[str, Any] = field(default_factory=dict)
    extra: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not (isinstance(self.sample_rate, (int, float)) and math.isfinite(self.sample_rate)
                and self.sample_rate > 0.0):
            raise DatasetError(f"metadata sample_rate = {self.sample_rate!r}: must be > 0 Hz")
        if self.source not in ("rig", "emulator"):
            raise DatasetError(f"metadata source = {self.source!r}: must be 'rig' or "
                               "'emulator'")
        if not (isinstance(self.status, str) and _STATUS.match(self.status)):
            raise DatasetError(f"metadata status = {self.status!r}: must be 'running', "
                               "'complete' or 'aborted: <reason>'")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return _json_ready({name: getattr(self, name) for name in self.__dataclass_fields__})

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "metadata") -> "RunMetadata":
        """Inverse of :meth:`to_dict`; unknown keys go to `extra`."""
        if not isinstance(data, Mapping):
            raise DatasetError(f"{where}: must be an object, got {type(data).__name__}")
        known = {k: v for k, v in data.items() if k in cls.__dataclass_fields__}
        extra = {**dict(known.pop("extra", {}) or {}),
                 **{k: v for k, v in data.items() if k not in cls.__dataclass_fields__}}
        for name in ("sample_rate", "source"):
            if name not in known:
                raise DatasetError(f"{where}: field {name!r} is missing")
        try:
            return cls(**known, extra=extra)
        except DatasetError as error:
            raise DatasetError(f"{where}: {error}") from None

    def with_status(self, status: str) -> "RunMetadata":
        """A copy with another status."""
        from dataclasses import replace

        return replace(self, status=status)


@dataclass(frozen=True, eq=False)
class Dataset:
    """One run: time [s], channels with units, metadata; checked on construction.

    Parameters
    ----------
    time : array_like, shape (n,)
    channels : mapping of str to array_like, shape (n,)
    units : mapping of str to str
        Channel units; a standard channel without an entry gets its standard unit.
    metadata : RunMetadata
    warnings : tuple of str
        What the reader noticed without refusing (a torn last line, an unfinished run).
    """

    time: np.ndarray
    channels: Mapping[str, np.ndarray]
    units: Mapping[str, str]
    metadata: RunMetadata
    warnings: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        units = dict(self.units)
        for name in self.channels:
            if name not in units and name in STANDARD_CHANNELS:
                units[name] = STANDARD_CHANNELS[name].unit
        time, channels, units = check_dataset(self.time, self.channels, units, required=())
        object.__setattr__(self, "time", time)
        object.__setattr__(self, "channels", MappingProxyType(channels))
        object.__setattr__(self, "units", MappingProxyType(units))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.channels)

    def __getitem__(self, name: str) -> np.ndarray:
        if name == "time":
            return self.time
        if name not in self.channels:
            raise KeyError(f"no channel {name!r}; channels are {list(self.channels)}")
        return self.channels[name]

    def __len__(self) -> int:
        return int(self.time.size)

    def to_time_response(self):
        """As a :class:`panto.fmu_src.response.TimeResponse` (metadata as a plain dictionary)."""
        from panto.fmu_src.response import TimeResponse

        return TimeResponse(self.time, dict(self.channels), units=dict(self.units),
                            metadata=self.metadata.to_dict())

    def to_response(self):
        """As a :class:`panto.fmu_src.response.TimeResponse`: :meth:`to_time_response` under the
        name every time series of the project shares (``.to_response().plot()``)."""
        return self.to_time_response()

    def write(self, path: str | Path) -> Path:
        """Write as ``.csv`` (+ ``.csv.json``), ``.parquet`` or ``.mat``, by the suffix."""
        path = Path(path)
        writers = {".csv": write_csv, ".parquet": write_parquet, ".mat": write_mat}
        return writers[_suffix(path)](self, path)


def _frozen(values: Any, what: str) -> np.ndarray:
    try:
        array = np.array(values, dtype=float)
    except (TypeError, ValueError) as error:
        raise DatasetError(f"{what}: not numeric ({error})") from None
    if array.ndim != 1:
        raise DatasetError(f"{what}: must be one-dimensional, got shape {array.shape}")
    array.setflags(write=False)
    return array


def check_dataset(time: Any, channels: Mapping[str, Any], units: Mapping[str, str], *,
                  required: Sequence[str] = REQUIRED_CHANNELS, source: str = "dataset",
                  convert_units: bool = False
                  ) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, str]]:
    """The schema check: return checked (and, if allowed, unit-converted) columns or raise.

    Raises
    ------
    DatasetError
        ``"<source>: channel 'force': unit 'kN', expected 'N' ..."`` and the like.
    """
    time = _frozen(time, f"{source}: time")
    if not np.all(np.isfinite(time)):
        index = int(np.flatnonzero(~np.isfinite(time))[0])
        raise DatasetError(f"{source}: time is not finite at row {index} ({time[index]})")
    steps = np.diff(time)
    if np.any(steps <= 0.0):
        index = int(np.flatnonzero(steps <= 0.0)[0])
        raise DatasetError(f"{source}: time is not strictly increasing at row {index + 1} "
                           f"({time[index]:.9g} s then {time[index + 1]:.9g} s)")
    missing = [name for name in required if name not in channels]
    if missing:
        raise DatasetError(f"{source}: required channel(s) {missing} missing; channels are "
                           f"{list(channels)}")
    checked: dict[str, np.ndarray] = {}
    checked_units: dict[str, str] = {}
    for name, values in channels.items():
        where = f"{source}: channel {name!r}"
        if not isinstance(name, str) or not name or name == "time":
            raise DatasetError(f"{where}: invalid channel name")
        array = _frozen(values, where)
        if array.size != time.size:
            raise DatasetError(f"{where}: {array.size} samples, time has {time.size}")
        unit = units.get(name)
        array, unit = _check_unit(array, unit, name, where, convert_units)
        spec = STANDARD_CHANNELS.get(name)
        if spec is not None and not spec.allow_nan and np.any(np.isnan(array)):
            row = int(np.flatnonzero(np.isnan(array))[0])
            raise DatasetError(f"{where}: NaN at row {row} (t = {time[row]:.9g} s), not allowed "
                               "in this channel")
        if np.any(np.isinf(array)):
            raise DatasetError(f"{where}: infinite value at row "
                               f"{int(np.flatnonzero(np.isinf(array))[0])}")
        checked[name], checked_units[name] = array, unit
    unknown = sorted(set(units) - set(channels) - {"time"})
    if unknown:
        raise DatasetError(f"{source}: units given for unknown channel(s) {unknown}")
    return time, checked, checked_units


#: Largest magnitude a measured value may have, in any unit of :data:`UNIT_FACTORS`: no signal
#: of the rig comes near 1e12 N, m, bar, A or V; a value beyond it is a corrupt cell (and its
#: square, near 1e154, overflows the least-squares sums). The storage keeps any double; the
#: users of the data (``rig check``, identification) refuse such values (:func:`check_plausible`).
PLAUSIBLE_MAGNITUDE = 1e12


def check_plausible(dataset: "Dataset", source: str, names: Sequence[str] | None = None) -> None:
    """Refuse a channel value beyond :data:`PLAUSIBLE_MAGNITUDE` in magnitude.

    Parameters
    ----------
    dataset : Dataset
        The data.
    source : str
        The file named in the message (with the channel, its unit, the value and its row).
    names : sequence of str, optional
        The channels to check (default: all).

    Raises
    ------
    DatasetError
        On the first channel with such a value.
    """
    for name in dataset.names if names is None else names:
        array = np.asarray(dataset[name])
        with np.errstate(invalid="ignore"):
            bad = np.flatnonzero(np.abs(array) > PLAUSIBLE_MAGNITUDE)
        if bad.size:
            raise DatasetError(
                f"{source}: channel {name!r} [{dataset.units.get(name, '')}]: "
                f"{array[bad[0]]:.6g} at row {int(bad[0])} is not a plausible measurement "
                f"(plausible range -{PLAUSIBLE_MAGNITUDE:g} to {PLAUSIBLE_MAGNITUDE:g}; "
                f"{bad.size} value(s) outside)")


def _check_rate(time: np.ndarray, meta: "RunMetadata", source: str) -> None:
    """The side file's sample period must be a typical step of the time column: inside the
    middle half of its steps (the quartiles), or within 1 % of the median step."""
    if time.size < 2:
        return
    steps = np.diff(time)
    step = float(np.median(steps))
    low, high = np.quantile(steps, [0.25, 0.75])
    if not min(low, 0.99 * step) <= 1.0 / meta.sample_rate <= max(high, 1.01 * step):
        side = (f"its side file {metadata_path_for(source).name}"
                if Path(source).suffix.lower() == ".csv" else "its metadata")
        raise DatasetError(f"{source}: {side} says sample_rate {meta.sample_rate:g} Hz but its "
                           f"time column steps by {step:.6g} s ({1.0 / step:.6g} Hz); correct "
                           "one of them")


def _check_unit(array: np.ndarray, unit: str | None, name: str, where: str,
                convert: bool) -> tuple[np.ndarray, str]:
    if not unit:
        raise DatasetError(f"{where}: no unit given")
    if unit not in UNIT_FACTORS:
        raise DatasetError(f"{where}: unknown unit {unit!r}; known units are "
                           f"{sorted(UNIT_FACTORS)}")
    spec = STANDARD_CHANNELS.get(name)
    if spec is None or unit == spec.unit:
        return array, unit
    base, factor = UNIT_FACTORS[unit]
    if base != UNIT_FACTORS[spec.unit][0]:
        raise DatasetError(f"{where}: unit {unit!r} is not a unit of {spec.unit!r}")
    if not convert:
        raise DatasetError(f"{where}: unit {unit!r}, expected {spec.unit!r} (pass "
                           "convert_units=True to convert)")
    converted = array * (factor / UNIT_FACTORS[spec.unit][1])
    converted.setflags(write=False)
    return converted, spec.unit


def _finish(time: Any, channels: Mapping[str, Any], units: Mapping[str, str],
            metadata: Mapping[str, Any], *, source: str, required: Sequence[str],
            convert_units: bool, warnings: Sequence[str] = ()) -> Dataset:
    """The readers' common end: schema check, metadata, status warnings."""
    time, channels, units = check_dataset(time, channels, units, required=required,
                                          source=source, convert_units=convert_units)
    meta = RunMetadata.from_dict(metadata, where=f"{source}: metadata")
    _check_rate(time, meta, source)
    warnings = list(warnings)
    if meta.status == "running":
        warnings.append(f"{source}: status 'running': the recording ended without being "
                        "finished (a crash?); rows up to the last flushed buffer are present")
    elif meta.status.startswith("aborted"):
        warnings.append(f"{source}: run {meta.status}")
    return Dataset(time, channels, units, meta, tuple(warnings))


# --- CSV --------------------------------------------------------------------------------------


def write_csv(dataset: Dataset, path: str | Path) -> Path:
    """Write `dataset` as CSV and its units + metadata as the side file ``<path>.json``."""
    path = Path(path)
    columns = np.column_stack([dataset.time, *dataset.channels.values()])
    with open(path, "w", encoding="utf-8", newline="") as stream:
        stream.write(csv_header(dataset.names, dataset.units))
        stream.writelines(format_csv_row(row) for row in columns.tolist())
    write_sidecar(path, dataset.names, dataset.units, dataset.metadata)
    return path


def write_sidecar(path: Path, names: Sequence[str], units: Mapping[str, str],
                  metadata: RunMetadata) -> Path:
    """Write (atomically: temporary file, fsync, rename) the CSV's JSON side file."""
    return write_side_file(path, {"format": FORMAT, "version": VERSION,
                                  "channels": [{"name": n, "unit": units[n]} for n in names],
                                  "metadata": metadata.to_dict()})


def read_csv(path: str | Path, *, required: Sequence[str] = REQUIRED_CHANNELS,
             convert_units: bool = False) -> Dataset:
    """Read a CSV dataset and its side file; a torn last line (a crash mid-write) is dropped
    and reported in :attr:`Dataset.warnings`."""
    import pandas as pd

    path = Path(path)
    try:
        text = read_text_file(path)
    except DataFormatError as error:
        raise DatasetError(str(error)) from None
    warnings = []
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
        warnings.append(f"{path}: last line torn (incomplete row dropped)")
    lines = text.splitlines()
    if not lines:
        raise DatasetError(f"{path}: file is empty")
    if len(lines) == 1:
        raise DatasetError(f"{path}: no data rows (only the header {lines[0][:60]!r})")
    headers = [parse_header(h) for h in lines[0].split(",")]
    if headers[0] not in (("time", "s"), ("time", "")):
        raise DatasetError(f"{path}: first column must be 'time [s]', got "
                           f"{lines[0].split(',')[0]!r}")
    names = [n for n, _ in headers[1:]]
    duplicated = sorted({n for n in names if names.count(n) > 1})
    if duplicated:
        raise DatasetError(f"{path}: channel(s) {duplicated} duplicated")
    for row, line in enumerate(lines[1:], start=1):
        if line.count(",") != len(headers) - 1:
            raise DatasetError(f"{path}: row {row} has {line.count(',') + 1} fields, the header "
                               f"has {len(headers)} (mismatched lengths)")
    side_units, metadata = _read_sidecar(path)
    units = {n: u for n, u in headers[1:]}
    for name, unit in side_units.items():
        if name in units and units[name] and unit != units[name]:
            raise DatasetError(f"{path}: channel {name!r}: unit {units[name]!r} in the header "
                               f"but {unit!r} in {metadata_path_for(path).name}")
        units[name] = units.get(name) or unit
    frame = pd.read_csv(io.StringIO(text), header=0, names=["time", *names],
                        na_values=[""], keep_default_na=False, **csv_read_options())
    columns = {}
    for name in ["time", *names]:
        column = frame[name]
        if column.dtype.kind not in "fiu":
            numbers = pd.to_numeric(column, errors="coerce")
            row = int(np.flatnonzero(numbers.isna() & column.notna())[0]) + 1
            raise DatasetError(f"{path}: channel {name!r}: row {row} is not a number "
                               f"({column.iloc[row - 1]!r})")
        columns[name] = column.to_numpy(dtype=float)
    return _finish(columns.pop("time"), columns, units, metadata, source=str(path),
                   required=required, convert_units=convert_units, warnings=warnings)


def _read_sidecar(path: Path) -> tuple[dict[str, str], dict[str, Any]]:
    side = metadata_path_for(path)
    try:
        data = read_side_file(path)
    except DataFormatError as error:
        raise DatasetError(str(error)) from None
    if data is None:
        raise DatasetError(f"{path}: metadata side file {side.name} is missing")
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise DatasetError(f"{side}: not a {FORMAT!r} side file")
    units = {c["name"]: c["unit"] for c in data.get("channels", [])}
    return units, data.get("metadata", {})


# --- Parquet ----------------------------------------------------------------------------------


def write_parquet(dataset: Dataset, path: str | Path) -> Path:
    """Write as Parquet: one float64 column per channel (``unit`` in each field's metadata),
    the side-file JSON in the schema metadata under ``panto``."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = Path(path)
    names = ["time", *dataset.names]
    units = {"time": "s", **dataset.units}
    schema = pa.schema([pa.field(n, pa.float64(), metadata={"unit": units[n]}) for n in names],
                       metadata={"panto": json.dumps({"format": FORMAT, "version": VERSION,
                                                      "metadata": dataset.metadata.to_dict()})})
    table = pa.Table.from_arrays([pa.array(dataset[n], type=pa.float64()) for n in names],
                                 schema=schema)
    pq.write_table(table, path)
    return path


def read_parquet(path: str | Path, *, required: Sequence[str] = REQUIRED_CHANNELS,
                 convert_units: bool = False) -> Dataset:
    """Read a Parquet dataset written by :func:`write_parquet` and check it."""
    import pyarrow.parquet as pq

    path = Path(path)
    try:
        table = pq.ParquetFile(path).read()
    except Exception as error:  # pyarrow raises its own types for a damaged file
        raise DatasetError(f"{path}: not a readable Parquet file ({error})") from None
    schema_meta = table.schema.metadata or {}
    if b"panto" not in schema_meta:
        raise DatasetError(f"{path}: no 'panto' metadata in the Parquet schema")
    info = json.loads(schema_meta[b"panto"])
    names = table.column_names
    duplicated = sorted({n for n in names if names.count(n) > 1})
    if duplicated:
        raise DatasetError(f"{path}: channel(s) {duplicated} duplicated")
    if not names or names[0] != "time":
        raise DatasetError(f"{path}: first column must be 'time', got {names[:1]}")
    units = {}
    columns = {}
    for index, name in enumerate(names):
        meta = table.schema.field(index).metadata or {}
        units[name] = meta.get(b"unit", b"").decode()
        columns[name] = table.column(index).to_numpy(zero_copy_only=False).astype(float)
    if units.pop("time") not in ("s", ""):
        raise DatasetError(f"{path}: time must be in 's'")
    return _finish(columns.pop("time"), columns, units, info.get("metadata", {}),
                   source=str(path), required=required, convert_units=convert_units)


# --- MATLAB -----------------------------------------------------------------------------------


def write_mat(dataset: Dataset, path: str | Path) -> Path:
    """Write a MATLAB .mat file (v5): ``time`` and one column vector per channel as top-level
    variables, ``channel_names`` and ``channel_units`` (cell arrays) and ``metadata_json``."""
    from scipy.io import savemat

    path = Path(path)
    for name in dataset.names:
        if not _MAT_NAME.match(name) or name in _MAT_RESERVED:
            raise DatasetError(f"{path}: channel {name!r} is not usable as a MATLAB variable "
                               "name")
    variables: dict[str, Any] = {"time": dataset.time.reshape(-1, 1)}
    variables.update({n: dataset[n].reshape(-1, 1) for n in dataset.names})
    variables["channel_names"] = np.array(dataset.names, dtype=object).reshape(-1, 1)
    variables["channel_units"] = np.array([dataset.units[n] for n in dataset.names],
                                          dtype=object).reshape(-1, 1)
    variables["metadata_json"] = json.dumps(dataset.metadata.to_dict())
    savemat(path, variables, do_compression=True, oned_as="column")
    return path


def read_mat(path: str | Path, *, required: Sequence[str] = REQUIRED_CHANNELS,
             convert_units: bool = False) -> Dataset:
    """Read a .mat dataset written by :func:`write_mat` and check it."""
    from scipy.io import loadmat

    path = Path(path)
    try:
        data = loadmat(path)
    except Exception as error:  # scipy raises several types for a damaged file
        raise DatasetError(f"{path}: not a readable .mat file ({error})") from None
    for name in _MAT_RESERVED:
        if name not in data:
            raise DatasetError(f"{path}: variable {name!r} is missing")
    names = [str(np.squeeze(c)) for c in np.ravel(data["channel_names"])]
    units = [str(np.squeeze(c)) if np.size(c) else "" for c in np.ravel(data["channel_units"])]
    duplicated = sorted({n for n in names if names.count(n) > 1})
    if duplicated:
        raise DatasetError(f"{path}: channel(s) {duplicated} duplicated")
    if len(units) != len(names):
        raise DatasetError(f"{path}: {len(names)} channel names but {len(units)} units")
    missing = [n for n in names if n not in data]
    if missing:
        raise DatasetError(f"{path}: channel(s) {missing} listed but not stored")
    metadata = json.loads(str(np.squeeze(data["metadata_json"])))
    return _finish(np.ravel(data["time"]), {n: np.ravel(data[n]) for n in names},
                   dict(zip(names, units)), metadata, source=str(path), required=required,
                   convert_units=convert_units)


def read_dataset(path: str | Path, *, required: Sequence[str] = REQUIRED_CHANNELS,
                 convert_units: bool = False) -> Dataset:
    """Read a dataset file (``.csv``, ``.parquet``, ``.mat``) or a run folder (its ``run.csv``).

    Parameters
    ----------
    path : str or pathlib.Path
    required : sequence of str
        Channels that must be present (the rig's by default; ``()`` for none).
    convert_units : bool
        Convert a standard channel given in another unit of the same quantity (``kN`` -> ``N``)
        instead of refusing it.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "run.csv"
    readers = {".csv": read_csv, ".parquet": read_parquet, ".mat": read_mat}
    if not path.is_file():
        raise DatasetError(f"{path}: no such "
                           f"{'dataset file' if path.suffix else 'file or run folder'}")
    suffix = _suffix(path)
    return readers[suffix](path, required=required, convert_units=convert_units)


def _suffix(path: Path) -> str:
    """The data file's suffix (:func:`panto.fmu_src.dataformat.data_suffix`) as a DatasetError."""
    try:
        return data_suffix(path)
    except DataFormatError as error:
        raise DatasetError(str(error)) from None
