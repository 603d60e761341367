"""Load one run as :class:`~panto.identification.estimation.base.IdentificationData` from a file
or a table in memory.

:func:`load_identification_data` is what the command line (``panto identify``, ``panto compare``,
``panto diagnose``), the demo, notebooks and fitting scripts call; :class:`LoadOptions` says how:

- a rig run with no inputs or outputs named and ``rig_mapping=True``: the rig mapping
  (eta, p) -> (F_c, y_cb) of :func:`~panto.identification.data.datasets.pantograph_data` at
  ``rate`` (default 50 Hz);
- a dataset of this product (:func:`panto.rig.dataset.read_dataset`: CSV with its side file,
  Parquet, .mat): the named channels through
  :func:`~panto.identification.data.datasets.data_from_dataset`, resampled to ``rate``;
- any other table (:func:`read_table`: CSV, Parquet, .mat or HDF5 with named numeric columns,
  suffixes in any case; an HDF5 file's table named by ``key`` or ``FILE.h5:KEY``
  (:mod:`~panto.identification.data.hdf5`); or in memory, a :class:`pandas.DataFrame` or a mapping of column name to
  array): the time base is the median step of a ``time``/``t`` column (printed times carry
  rounding), else a DataFrame's float index, else ``1 / sample_rate``; ``rate`` decimates with
  :func:`~panto.identification.data.preprocessing.decimate_zero_phase`.

``rows`` then keeps a slice of the samples (two parts of one file can train and validate), and
``start``/``stop`` a time window [s]. Constant levels (an input at 5.3 m, a force about 120 N) are
left in the data: each structure says how it handles them (its result's ``details["levels"]``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from panto.identification.estimation.base import IdentificationData


@dataclass(frozen=True)
class LoadOptions:
    """How to turn a file into identification data (module notes).

    Attributes
    ----------
    inputs, outputs : mapping of str to str
        Signal name -> column (channel) name.
    rate : float or None
        Identification rate [Hz]: resample (datasets) or decimate (tables); None keeps the
        recording rate (the rig mapping then uses 50 Hz).
    sample_rate : float or None
        Rate [Hz] of a plain table; overrides its time column, needed without one.
    rows : slice
        Samples kept (after resampling for datasets, before decimation for tables).
    eta_offset : float or None
        Rig mapping: height [m] of the motor's zero (default: the run's metadata).
    rig_mapping : bool
        Use the pantograph rig mapping when no inputs and outputs are named.
    start, stop : float or None
        Keep the samples with ``start <= t < stop`` [s] (time from the first kept row).
    rig_outputs : tuple of str
        Rig mapping: the outputs (among ``F_c``, ``y_cb``, ``xi``).
    cross_bar : {"laser", "video"}
        Rig mapping: which measurement gives ``y_cb``.
    position_latency : float or None
        Rig mapping: how late [s] the drive reports the slider position (default: the run's
        recorded set-up, else 0).
    lowpass : float or None
        Plain tables: cut-off [Hz] of a zero-phase low-pass (4th-order Butterworth run forward
        and backward, :func:`scipy.signal.sosfiltfilt`) applied to every used column of the whole
        record before the rows are selected and the data decimated (e.g. the EMPS benchmark's
        25 Hz prefilter, Janot et al. 2019).
    key : str or None
        HDF5 files: the table to read when the file holds several
        (:func:`~panto.identification.data.hdf5.read_hdf5`; a path ``FILE.h5:KEY`` names it too).
    """

    inputs: Mapping[str, str] = field(default_factory=dict)
    outputs: Mapping[str, str] = field(default_factory=dict)
    rate: float | None = None
    sample_rate: float | None = None
    rows: slice = field(default_factory=lambda: slice(None))
    eta_offset: float | None = None
    rig_mapping: bool = False
    start: float | None = None
    stop: float | None = None
    rig_outputs: tuple[str, ...] = ("F_c", "y_cb")
    cross_bar: str = "laser"
    position_latency: float | None = None
    lowpass: float | None = None
    key: str | None = None

    def __post_init__(self) -> None:
        if self.lowpass is not None and not (math.isfinite(self.lowpass) and self.lowpass > 0):
            raise ValueError(f"lowpass {self.lowpass} Hz: must be a positive cut-off frequency")

#: What :func:`load_identification_data` and :func:`read_table` accept besides a path.
Table = Any  # pandas.DataFrame or Mapping[str, array-like]


def read_table(source: str | Path | Table, key: str | None = None) -> dict[str, np.ndarray]:
    """Named numeric columns of a plain table, all of one length.

    Parameters
    ----------
    source : str, pathlib.Path, pandas.DataFrame or mapping of str to array
        A CSV, Parquet, .mat (v7.3 too) or HDF5 (``.h5``, ``.hdf5``: needs PyTables) file,
        suffix in any case; or a table in memory. A DataFrame without a ``time``/``t`` column
        whose index is of floats gives that index as the column ``time`` [s].
    key : str, optional
        HDF5: the table to read when the file holds several (or ``FILE.h5:KEY`` as `source`).
    """
    if not isinstance(source, (str, Path)):
        columns = _memory_columns(source)
        where = "table"
    else:
        columns, where = _file_columns(Path(source), key), str(source)
    if not columns:
        raise ValueError(f"{where}: no numeric columns")
    length = max(len(v) for v in columns.values())
    return {k: v for k, v in columns.items() if len(v) == length}


def _file_columns(path: Path, key: str | None = None) -> dict[str, np.ndarray]:
    from panto.fmu_src.dataformat import TABLE_SUFFIXES, data_suffix
    from panto.identification.data.hdf5 import read_hdf5, split_key

    path, in_path = split_key(path)
    key = in_path or key
    if not path.is_file():
        raise ValueError(f"{path}: no such {'file' if path.suffix else 'file or run folder'}")
    suffix = data_suffix(path, "table", TABLE_SUFFIXES)
    if key is not None and suffix not in (".h5", ".hdf5", ".mat"):
        raise ValueError(f"{path}: --key {key!r}: only an HDF5 file (.h5, .hdf5, v7.3 .mat) "
                         "holds named tables")
    if suffix == ".mat":
        import scipy.io

        try:
            raw = scipy.io.loadmat(path)
        except NotImplementedError:  # a v7.3 file: HDF5 inside
            return _memory_columns(read_hdf5(path, key))
        except Exception as error:  # scipy's errors do not name the file
            raise ValueError(f"{path}: not a readable .mat file ({error})") from None
        if key is not None:
            raise ValueError(f"{path}: --key {key!r}: a .mat file before v7.3 holds one table")
        return {k: np.asarray(v, float).ravel() for k, v in raw.items()
                if not k.startswith("__") and isinstance(v, np.ndarray) and v.dtype.kind in "fiu"
                and v.size > 1 and min(v.shape) == 1}
    import pandas as pd

    if suffix in (".h5", ".hdf5"):
        frame = read_hdf5(path, key)
        if not isinstance(frame, pd.DataFrame):
            return frame
    else:
        frame = _read_frame(path, suffix)
    if len(frame) == 0:
        raise ValueError(f"{path}: no data rows (only a header)")
    return _memory_columns(frame)


def _read_frame(path: Path, suffix: str) -> Any:
    """A CSV or Parquet file as a DataFrame; a reader's error names the file."""
    import pandas as pd

    from panto.fmu_src.dataformat import read_text_file

    if suffix == ".parquet":
        try:
            return pd.read_parquet(path)
        except Exception as error:  # pyarrow's errors do not name the file
            raise ValueError(f"{path}: not a readable Parquet file ({error})") from None
    try:
        return pd.read_csv(path)
    except UnicodeDecodeError:
        read_text_file(path, "CSV")  # raises, saying what the file is (e.g. Parquet)
        raise
    except pd.errors.EmptyDataError:
        raise ValueError(f"{path}: file is empty") from None


def _memory_columns(table: Table) -> dict[str, np.ndarray]:
    """Numeric columns of a DataFrame (a float index as ``time``) or of a mapping."""
    import pandas as pd

    if not isinstance(table, pd.DataFrame):
        if not isinstance(table, Mapping):
            raise ValueError(f"a table is a path, a pandas.DataFrame or a mapping of column to "
                             f"array, not {type(table).__name__}")
        columns = {str(k): np.asarray(v) for k, v in table.items()}
        return {k: v.astype(float).ravel() for k, v in columns.items()
                if v.dtype.kind in "fiu" and v.size > 1 and v.squeeze().ndim == 1}
    frame = table.loc[:, [c for c in table.columns if not str(c).startswith("Unnamed")]]
    columns = {str(c): frame[c].to_numpy(float) for c in frame.columns
               if pd.api.types.is_numeric_dtype(frame[c])}
    if "time" not in columns and "t" not in columns and frame.index.dtype.kind == "f":
        columns = {"time": frame.index.to_numpy(float), **columns}
    return columns


def load_identification_data(source: str | Path | Table,
                             options: LoadOptions | None = None) -> IdentificationData:
    """Identification data of one run as `options` say (module notes).

    Parameters
    ----------
    source : str, pathlib.Path, pandas.DataFrame or mapping of str to array
        A file, a run folder, or a table in memory (:func:`read_table`).
    options : LoadOptions, optional
        Default: the rig mapping is off, so inputs and outputs must be named.

    Raises
    ------
    ValueError
        Inputs or outputs not named (and no rig mapping), a missing column, or a table without
        a time base; the message names the file (or "table") and the columns it has. A value
        beyond the plausible range, or a constant output (:func:`check_outputs_vary`).
    """
    options = options or LoadOptions()
    data = _load(source, options)
    _check_plausible_signals(data)
    return check_outputs_vary(data, options.outputs)


def _load(source: str | Path | Table, options: LoadOptions) -> IdentificationData:
    if not isinstance(source, (str, Path)):
        return _window(_table_data("table", read_table(source), options), options)
    from panto.identification.data.datasets import data_from_dataset, pantograph_data

    path, inputs, outputs = str(source), dict(options.inputs), dict(options.outputs)
    if not inputs and not outputs and options.rig_mapping and _is_run(path):
        data = pantograph_data(path, rate=options.rate or 50.0, eta_offset=options.eta_offset,
                               start=options.start, stop=options.stop,
                               cross_bar=options.cross_bar,
                               position_latency=options.position_latency,
                               outputs=options.rig_outputs)
        return select_rows(data, options.rows)
    try:
        from panto.rig.dataset import read_dataset

        dataset = read_dataset(path, required=())
    except Exception:  # not a dataset of this product: a plain table
        if _has_side_file(path):  # it is one, and it is broken: say why
            raise
        dataset = None
    if dataset is not None:
        from panto.rig.dataset import check_plausible

        _check_named(path, options, dataset.names)
        used = [c for c in [*inputs.values(), *outputs.values()] if isinstance(c, str)]
        check_plausible(dataset, path, [c for c in used if c in dataset.names])
        data = data_from_dataset(dataset, inputs=inputs, outputs=outputs, rate=options.rate,
                                 source=path)
        return _window(select_rows(data, options.rows), options)
    return _window(_table_data(path, read_table(path, options.key), options), options)


def _is_run(path: str) -> bool:
    """Whether `path` can be a recorded run (a folder, Parquet, .mat, or a CSV with its side
    file): only then does the rig mapping apply; a plain CSV needs its columns named."""
    from panto.fmu_src.dataformat import metadata_path_for

    candidate = Path(path)
    if candidate.is_dir():
        return True
    suffix = candidate.suffix.lower()
    return suffix in (".parquet", ".mat") or (suffix == ".csv"
                                              and metadata_path_for(candidate).is_file())


def _has_side_file(path: str) -> bool:
    from panto.fmu_src.dataformat import metadata_path_for

    return Path(path).suffix.lower() == ".csv" and metadata_path_for(path).is_file()


def _check_named(where: str, options: LoadOptions, columns: Any) -> None:
    """Inputs and outputs must be named when the rig mapping does not apply."""
    if not options.inputs or not options.outputs:
        raise ValueError(f"{where}: --inputs and --outputs name the columns (NAME=CHANNEL) for "
                         f"this data; its columns are {sorted(columns)}")


def _window(data: IdentificationData, options: LoadOptions) -> IdentificationData:
    """The samples inside ``[start, stop)`` [s], if a window is set."""
    if options.start is None and options.stop is None:
        return data
    start = -np.inf if options.start is None else options.start
    kept = data.segment(start, np.inf if options.stop is None else options.stop)
    if len(kept) < 2:
        raise ValueError(f"{data.source or 'table'}: fewer than two samples in "
                         f"[{options.start}, {options.stop}) s")
    return kept


def _table_data(where: str, table: Mapping[str, np.ndarray],
                options: LoadOptions) -> IdentificationData:
    """A plain table's columns on its time base, rows selected, decimated."""
    from panto.identification.data.preprocessing import (butterworth_zero_phase,
                                                         decimate_zero_phase)

    inputs, outputs = dict(options.inputs), dict(options.outputs)
    _check_named(where, options, table)
    missing = [c for c in list(inputs.values()) + list(outputs.values()) if c not in table]
    if missing:
        raise ValueError(f"{where}: {_why_missing(where, missing)}; numeric columns are "
                         f"{sorted(table)}")
    length = len(next(iter(table.values())))
    time_column = next((table[c] for c in ("time", "t") if c in table), None)
    _check_values(where, table, [*inputs.values(), *outputs.values()],
                  None if options.sample_rate else time_column)
    if options.sample_rate:
        time_column = np.arange(length) / options.sample_rate
    elif time_column is not None:  # the median step (printed times carry rounding)
        time_column = np.arange(length) * float(np.median(np.diff(time_column)))
    else:
        raise ValueError(f"{where}: no time column; give --sample-rate HZ")
    u = np.column_stack([table[c] for c in inputs.values()])
    y = np.column_stack([table[c] for c in outputs.values()])
    if options.lowpass:
        rate = 1.0 / float(time_column[1] - time_column[0])
        try:
            u, y = (butterworth_zero_phase(x, options.lowpass, rate) for x in (u, y))
        except ValueError as error:
            raise ValueError(f"{where}: {error}") from None
    u, y, t = u[options.rows], y[options.rows], time_column[options.rows]
    if len(t) < 2:
        raise ValueError(f"{where}: rows {options.rows.start}:{options.rows.stop} keep {len(t)} of "
                         f"{length} samples; need at least 2")
    if options.rate:
        factor = int(round(1.0 / ((t[1] - t[0]) * options.rate)))
        if factor > 1:
            t, u, y = t[::factor], decimate_zero_phase(u, factor), decimate_zero_phase(y, factor)
    return IdentificationData(t - t[0], u, y, tuple(inputs), tuple(outputs), source=where)


def _why_missing(where: str, missing: list[str]) -> str:
    """``no column(s) [...]``, or for a column of a CSV file holding text, its first text cell."""
    if Path(where).suffix.lower() == ".csv" and Path(where).is_file():
        import pandas as pd

        frame = pd.read_csv(where, dtype=str, keep_default_na=False)
        for name in (c for c in missing if c in frame.columns):
            numbers = pd.to_numeric(frame[name].replace("", "nan"), errors="coerce")
            bad = np.flatnonzero(numbers.isna() & (frame[name].str.lower() != "nan")
                                 & (frame[name] != ""))
            if bad.size:
                return (f"column {name!r} is not numeric: row {bad[0]} (line {bad[0] + 2}) holds "
                        f"{frame[name].iloc[bad[0]]!r}")
    return f"no column(s) {missing}"


def _check_values(where: str, table: Mapping[str, np.ndarray], names: list[str],
                  time: np.ndarray | None) -> None:
    """The columns used must be finite and plausible (as the rig's datasets), the time column
    strictly increasing."""
    from panto.rig.dataset import PLAUSIBLE_MAGNITUDE

    for name in dict.fromkeys(names):
        bad = np.flatnonzero(~np.isfinite(table[name]))
        if bad.size:
            raise ValueError(f"{where}: column {name!r}: {table[name][bad[0]]} at row {bad[0]} "
                             f"({bad.size} non-finite values); identification needs numbers")
        bad = np.flatnonzero(np.abs(table[name]) > PLAUSIBLE_MAGNITUDE)
        if bad.size:
            raise ValueError(f"{where}: column {name!r}: {table[name][bad[0]]:.6g} at row "
                             f"{bad[0]} is not a plausible measurement (plausible range "
                             f"-{PLAUSIBLE_MAGNITUDE:g} to {PLAUSIBLE_MAGNITUDE:g}; {bad.size} "
                             "value(s) outside)")
    if time is not None:
        steps = np.diff(time)
        bad = np.flatnonzero(~(steps > 0.0))
        if bad.size:
            raise ValueError(f"{where}: time is not strictly increasing at row {bad[0] + 1} "
                             f"({time[bad[0]]:.9g} s then {time[bad[0] + 1]:.9g} s)")


def _check_plausible_signals(data: IdentificationData) -> None:
    """The loaded inputs and outputs within the plausible range (whatever path loaded them)."""
    from panto.rig.dataset import PLAUSIBLE_MAGNITUDE

    for names, values in ((data.input_names, data.inputs), (data.output_names, data.outputs)):
        for name, column in zip(names, np.asarray(values, float).T):
            bad = np.flatnonzero(np.abs(column) > PLAUSIBLE_MAGNITUDE)
            if bad.size:
                raise ValueError(f"{data.source or 'table'}: signal {name!r}: {column[bad[0]]:.6g} "
                                 f"at loaded sample {bad[0]} is not a plausible measurement "
                                 f"(plausible range -{PLAUSIBLE_MAGNITUDE:g} to "
                                 f"{PLAUSIBLE_MAGNITUDE:g})")


def check_outputs_vary(data: IdentificationData, columns: Mapping[str, str] | None = None
                       ) -> IdentificationData:
    """`data` if every output varies; a constant output (there is nothing to fit, the fit % is
    undefined) is refused naming the file, the output (and its `columns` entry) and the value.

    Constant means a spread below 1e-9 of its magnitude, under the resolution of any converter
    (a 24-bit one resolves 6e-8 of its range): a number only rounding made vary.
    """
    for name, values in zip(data.output_names, np.asarray(data.outputs, float).T):
        finite = values[np.isfinite(values)]
        if finite.size and np.ptp(finite) <= 1e-9 * np.max(np.abs(finite)):
            column = (columns or {}).get(name)
            label = f"output {name!r}" + (f" (column {column!r})" if column else "")
            raise ValueError(f"{data.source or 'table'}: {label} is constant ({finite[0]:.6g} in "
                             f"all {finite.size} samples): there is nothing to fit (the fit % "
                             "is undefined)")
    return data


def select_rows(data: IdentificationData, rows: slice) -> IdentificationData:
    """`data` with only the samples `rows` (time, inputs and outputs; the rest kept)."""
    if rows == slice(None):
        return data
    return IdentificationData(data.time[rows], data.inputs[rows], data.outputs[rows],
                              data.input_names, data.output_names, data.units, data.source,
                              data.metadata)
