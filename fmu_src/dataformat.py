"""The file format of the project's time series: one module for every reader and writer.

A simulation result (:class:`panto.fmu_src.response.TimeResponse`) and a rig run
(:class:`panto.rig.dataset.Dataset`) are written the same way:

- **CSV**: the first column is time in seconds, every column is headed ``name [unit]``
  (:func:`format_header`, :func:`parse_header`; just ``name`` when the unit is unknown), one row
  per sample with the shortest exact text of each float (``repr``, reads back to the same double)
  and an empty cell for a missing sample (:func:`csv_header`, :func:`format_csv_row`);
- **a JSON side file** next to the CSV, ``result.csv`` -> ``result.csv.json``
  (:func:`metadata_path_for`), written atomically (:func:`write_side_file`) and read back with
  a clear error (:func:`read_side_file`);
- **Parquet** or **MATLAB .mat** instead of CSV, chosen by the file's suffix
  (:data:`DATA_SUFFIXES`, :func:`data_suffix`, case-insensitive: ``.CSV`` is ``.csv``); the rig's
  datasets use all three. Plain tables may also be HDF5 (:data:`TABLE_SUFFIXES`).
"""
from __future__ import annotations

import csv
import io
import json
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

TIME_NAME = "time"
TIME_UNIT = "s"
#: Suffixes of the data files, by format.
DATA_SUFFIXES = (".csv", ".parquet", ".mat")
#: Suffixes of plain tables (identification data from any source): the data files and HDF5.
TABLE_SUFFIXES = DATA_SUFFIXES + (".h5", ".hdf5")
_HEADER_PATTERN = re.compile(r"^(?P<name>.+?) \[(?P<unit>[^\[\]]*)\]$")


class DataFormatError(ValueError):
    """A file does not follow the format; the message names the file and the problem."""


def format_header(name: str, unit: str) -> str:
    """Column header for a signal: ``"F_c [N]"``, or just the name when the unit is empty."""
    return f"{name} [{unit}]" if unit else name


def parse_header(header: str) -> tuple[str, str]:
    """Split a column header ``"F_c [N]"`` into ``("F_c", "N")``; no ``" [...]"`` means no unit.

    Names may themselves contain brackets (``"q[1] [rad]"`` is ``("q[1]", "rad")``); the unit is
    the last bracketed group preceded by one space.
    """
    header = header.strip()
    match = _HEADER_PATTERN.match(header)
    if match is None:
        return header, ""
    return match["name"], match["unit"]


def csv_header(names: Sequence[str], units: Mapping[str, str]) -> str:
    """The header line ``time [s],name [unit],...`` (a header holding a comma or a quote is
    quoted as the ``csv`` module does)."""
    headers = [format_header(TIME_NAME, TIME_UNIT)] + [format_header(n, units[n]) for n in names]
    line = io.StringIO()
    csv.writer(line, lineterminator="\n").writerow(headers)
    return line.getvalue()


def format_csv_row(values: Sequence[float]) -> str:
    """One CSV line: shortest exact ``repr`` of each float, NaN as an empty cell."""
    return ",".join("" if v != v else repr(float(v)) for v in values) + "\n"


def csv_read_options() -> dict[str, str]:
    """``pandas.read_csv`` options for exact floats: pandas >= 3 is exact by default (and
    deprecates ``float_precision``), older versions need ``float_precision="round_trip"``."""
    import pandas as pd

    major = int(pd.__version__.split(".")[0])
    return {} if major >= 3 else {"float_precision": "round_trip"}


def json_default(value: Any) -> Any:
    """Convert what ``json`` cannot: numpy scalars and arrays, sets; anything else as text."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (set, frozenset)):
        return sorted(value, key=str)
    return str(value)


def metadata_path_for(csv_path: str | Path) -> Path:
    """The JSON side file that holds a CSV's metadata: ``result.csv`` → ``result.csv.json``."""
    csv_path = Path(csv_path)
    return csv_path.with_name(csv_path.name + ".json")


def write_side_file(csv_path: str | Path, document: Any) -> Path:
    """Write `document` as the CSV's JSON side file (indented, newline-terminated).

    Atomic: a temporary file is written, flushed to disk and renamed, so a reader never sees
    half a side file. Returns the side file's path.
    """
    side = metadata_path_for(csv_path)
    text = json.dumps(document, indent=2, default=json_default) + "\n"
    temporary = side.with_name(side.name + ".tmp")
    with open(temporary, "w", encoding="utf-8") as stream:
        stream.write(text)
        stream.flush()
        os.fsync(stream.fileno())
    os.replace(temporary, side)
    return side


def read_side_file(csv_path: str | Path) -> Any:
    """The CSV's JSON side file, parsed; None when there is none (:class:`DataFormatError` when it
    is not valid JSON)."""
    side = metadata_path_for(csv_path)
    if not side.is_file():
        return None
    try:
        return json.loads(side.read_text(encoding="utf-8"))
    except json.JSONDecodeError as error:
        raise DataFormatError(f"{side}: not valid JSON ({error})") from None


def data_suffix(path: str | Path, what: str = "dataset",
                suffixes: Sequence[str] = DATA_SUFFIXES) -> str:
    """The suffix of a data file in lower case (one of `suffixes`: ``.CSV`` gives ``.csv``), or
    a clear error naming the file and the accepted suffixes."""
    suffix = Path(path).suffix.lower()
    if suffix not in suffixes:
        raise DataFormatError(f"{path}: unknown {what} format {Path(path).suffix!r}; use one of "
                              f"{sorted(suffixes)}")
    return suffix


#: The first bytes of the binary formats a CSV may turn out to be, and their names.
_MAGIC = ((b"PAR1", "a Parquet file (suffix .parquet)"), (b"MATLAB", "a MATLAB file (suffix .mat)"),
          (b"\x89HDF", "an HDF5 file (suffix .h5)"), (b"PK\x03\x04", "a zip archive"))


def read_text_file(path: str | Path, what: str = "CSV") -> str:
    """The text of `path` (UTF-8), or a :class:`DataFormatError` naming the file and, for a
    binary file under a text suffix (a Parquet file named ``.csv``), what it really is."""
    path = Path(path)
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as error:
        with open(path, "rb") as stream:
            head = stream.read(8)
        found = next((name for magic, name in _MAGIC if head.startswith(magic)), None)
        raise DataFormatError(f"{path}: not a text {what} file: "
                              + (f"it is {found}" if found else f"byte {error.start} is not UTF-8")
                              ) from None


__all__ = ["TIME_NAME", "TIME_UNIT", "DATA_SUFFIXES", "TABLE_SUFFIXES", "DataFormatError",
           "format_header", "parse_header", "csv_header", "format_csv_row", "csv_read_options",
           "json_default", "metadata_path_for", "write_side_file", "read_side_file", "data_suffix",
           "read_text_file"]
