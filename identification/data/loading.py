"""Load one run as :class:`~panto.identification.estimation.base.IdentificationData` from a file.

:func:`load_identification_data` is what the command line (``panto diagnose``), the demo,
notebooks and fitting scripts call; :class:`LoadOptions` says how:

- a rig run with no inputs or outputs named and ``rig_mapping=True``: the rig mapping
  (eta, p) -> (F_c, y_cb) of :func:`~panto.identification.data.datasets.pantograph_data` at
  ``rate`` (default 50 Hz);
- a dataset of this product (:func:`panto.rig.dataset.read_dataset`: CSV with its side file,
  Parquet, .mat): the named channels through
  :func:`~panto.identification.data.datasets.data_from_dataset`, resampled to ``rate``;
- any other table (:func:`read_table`: CSV, Parquet or .mat with named numeric columns): the
  time base is the median step of a ``time``/``t`` column (printed times carry rounding) or
  ``1 / sample_rate``; ``rate`` decimates with
  :func:`~panto.identification.data.preprocessing.decimate_zero_phase`.

``rows`` then keeps a slice of the samples (two parts of one file can train and validate).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

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
    """

    inputs: Mapping[str, str] = field(default_factory=dict)
    outputs: Mapping[str, str] = field(default_factory=dict)
    rate: float | None = None
    sample_rate: float | None = None
    rows: slice = field(default_factory=lambda: slice(None))
    eta_offset: float | None = None
    rig_mapping: bool = False


def read_table(path: str | Path) -> dict[str, np.ndarray]:
    """Named columns of a plain CSV, Parquet or .mat file (1-D numeric variables, equal length)."""
    path = Path(path)
    if path.suffix == ".mat":
        import scipy.io

        raw = scipy.io.loadmat(path)
        columns = {k: np.asarray(v, float).ravel() for k, v in raw.items()
                   if not k.startswith("__") and isinstance(v, np.ndarray) and v.dtype.kind in "fiu"
                   and v.size > 1 and min(v.shape) == 1}
    else:
        import pandas as pd

        frame = pd.read_parquet(path) if path.suffix == ".parquet" else pd.read_csv(path)
        frame = frame.loc[:, [c for c in frame.columns if not str(c).startswith("Unnamed")]]
        columns = {str(c): frame[c].to_numpy(float) for c in frame.columns}
    if not columns:
        raise ValueError(f"{path}: no numeric columns")
    length = max(len(v) for v in columns.values())
    return {k: v for k, v in columns.items() if len(v) == length}


def load_identification_data(path: str | Path,
                             options: LoadOptions | None = None) -> IdentificationData:
    """Identification data of one run (file or run folder) as `options` say (module notes).

    Default options: the rig mapping is off, so inputs and outputs must be named.

    Raises
    ------
    ValueError
        Inputs or outputs not named (and no rig mapping), a missing column, or a table without
        a time base; the message names the file.
    """
    from panto.identification.data.datasets import data_from_dataset, pantograph_data

    path, options = str(path), options or LoadOptions()
    inputs, outputs = dict(options.inputs), dict(options.outputs)
    if not inputs and not outputs and options.rig_mapping:
        data = pantograph_data(path, rate=options.rate or 50.0, eta_offset=options.eta_offset)
        return select_rows(data, options.rows)
    if not inputs or not outputs:
        raise ValueError("--inputs and --outputs name the columns (NAME=CHANNEL) for this data")
    try:
        from panto.rig.dataset import read_dataset

        dataset = read_dataset(path, required=())
    except Exception:  # not a dataset of this product: a plain table
        dataset = None
    if dataset is not None:
        return select_rows(data_from_dataset(dataset, inputs=inputs, outputs=outputs,
                                             rate=options.rate, source=path), options.rows)
    return _table_data(path, read_table(path), inputs, outputs, options)


def _table_data(path: str, table: Mapping[str, np.ndarray], inputs: Mapping[str, str],
                outputs: Mapping[str, str], options: LoadOptions) -> IdentificationData:
    """A plain table's columns on its time base, rows selected, decimated."""
    from panto.identification.data.preprocessing import decimate_zero_phase

    missing = [c for c in list(inputs.values()) + list(outputs.values()) if c not in table]
    if missing:
        raise ValueError(f"{path}: no column(s) {missing}; columns are {sorted(table)}")
    length = len(next(iter(table.values())))
    time_column = next((table[c] for c in ("time", "t") if c in table), None)
    if options.sample_rate:
        time_column = np.arange(length) / options.sample_rate
    elif time_column is not None:  # the median step (printed times carry rounding)
        time_column = np.arange(length) * float(np.median(np.diff(time_column)))
    else:
        raise ValueError(f"{path}: no time column; give --sample-rate HZ")
    u = np.column_stack([table[c] for c in inputs.values()])[options.rows]
    y = np.column_stack([table[c] for c in outputs.values()])[options.rows]
    t = time_column[options.rows]
    if options.rate:
        factor = int(round(1.0 / ((t[1] - t[0]) * options.rate)))
        if factor > 1:
            t, u, y = t[::factor], decimate_zero_phase(u, factor), decimate_zero_phase(y, factor)
    return IdentificationData(t - t[0], u, y, tuple(inputs), tuple(outputs), source=path)


def select_rows(data: IdentificationData, rows: slice) -> IdentificationData:
    """`data` with only the samples `rows` (time, inputs and outputs; the rest kept)."""
    if rows == slice(None):
        return data
    return IdentificationData(data.time[rows], data.inputs[rows], data.outputs[rows],
                              data.input_names, data.output_names, data.units, data.source,
                              data.metadata)
