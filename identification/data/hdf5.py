"""HDF5 tables (``.h5``, ``.hdf5``, and MATLAB v7.3 ``.mat`` files, which are HDF5) as named
numeric columns, read through PyTables (the ``tables`` package, also pandas' HDF5 reader).

Two layouts are read:

- a table written by pandas (:meth:`pandas.DataFrame.to_hdf`, fixed or table format): the group
  carrying pandas' ``pandas_type`` attribute, read by :func:`pandas.read_hdf`;
- plain datasets (h5py, MATLAB v7.3, a data logger's export): the one-dimensional numeric
  datasets of a group (``N``, ``N x 1`` or ``1 x N``) are its columns, named by the dataset; a
  compound dataset (a record array) is a table whose scalar numeric fields are the columns.

A file that holds one table is read as it is. A file that holds several (pandas keys, groups of
columns, compound datasets) needs the table's name: :func:`read_hdf5` takes it as `key`, and a
path may carry it after a colon (``runs.h5:train``, :func:`split_key`), so that two tables of one
file can train and validate. Without it the message lists the tables.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path
from typing import Any

import numpy as np

#: Suffixes of HDF5 files (any case).
HDF5_SUFFIXES = (".h5", ".hdf5")


def split_key(source: str | Path) -> tuple[Path, str | None]:
    """``"runs.h5:train"`` -> ``(Path("runs.h5"), "train")``; any other path -> ``(path, None)``.

    Only a path that is not a file itself and whose part before the last colon has an HDF5
    suffix is split (a Windows drive letter or a colon inside a folder name stays).
    """
    path = Path(source)
    head, colon, key = str(source).rpartition(":")
    if colon and key and not path.is_file() and Path(head).suffix.lower() in HDF5_SUFFIXES:
        return Path(head), key
    return path, None


def read_hdf5(path: str | Path, key: str | None = None) -> Any:
    """The table `key` of the HDF5 file `path` (module notes): a :class:`pandas.DataFrame` for a
    pandas table, else a dict of column name to 1-D array.

    Parameters
    ----------
    path : str or pathlib.Path
        The HDF5 file.
    key : str, optional
        The table's name as :func:`hdf5_tables` lists it (a leading ``/`` may be left out);
        needed when the file holds more than one.

    Raises
    ------
    ValueError
        PyTables missing, a file HDF5 cannot open, no table of numeric columns, several tables
        and no `key`, or an unknown `key`; the message names the file and lists its tables.
    """
    if importlib.util.find_spec("tables") is None:  # pandas reads HDF5 through PyTables too
        raise ValueError(f"{path}: reading HDF5 needs PyTables: pip install tables")
    import tables

    try:
        handle = tables.open_file(str(path), "r")
    except Exception as error:  # HDF5's errors are its whole error stack
        last = [line.strip() for line in str(error).splitlines() if line.strip()]
        raise ValueError(f"{path}: not a readable HDF5 file ({last[-1] if last else error})"
                         ) from None
    with handle:
        found = _tables_in(handle)
        name = _choose(path, found, key)
        kind = found[name]
        if kind != "pandas":
            return _plain_columns(handle.get_node(_node_path(name)), kind)
    import pandas as pd

    return pd.read_hdf(path, key=_node_path(name))


def hdf5_tables(path: str | Path) -> list[str]:
    """The names of the tables in the HDF5 file `path` (module notes), as `key` takes them."""
    import tables

    with tables.open_file(str(path), "r") as handle:
        return sorted(_tables_in(handle))


def _tables_in(handle: Any) -> dict[str, str]:
    """Table name -> kind (``"pandas"``, ``"group"``, ``"compound"``) of an open file."""
    import tables

    found: dict[str, str] = {}
    pandas_groups: list[str] = []
    for group in handle.walk_groups("/"):
        where = group._v_pathname
        if any(where.startswith(p + "/") for p in pandas_groups) or "/#" in where:
            continue  # inside a pandas table; MATLAB's #refs#
        if "pandas_type" in group._v_attrs._v_attrnames:
            pandas_groups.append(where)
            found[_shown(where)] = "pandas"
            continue
        leaves = [leaf for leaf in group._f_iter_nodes("Leaf")]
        if any(_is_column(leaf) for leaf in leaves):
            found[_shown(where)] = "group"
        for leaf in leaves:
            if isinstance(leaf, tables.Table) and _compound_fields(leaf):
                found[_shown(leaf._v_pathname)] = "compound"
    return found


def _shown(where: str) -> str:
    """A node path as a table name: without the leading ``/`` (the root stays ``/``)."""
    return where.lstrip("/") or "/"


def _node_path(name: str) -> str:
    return "/" + name.strip("/")


def _choose(path: str | Path, found: dict[str, str], key: str | None) -> str:
    """The table to read: `key`, or the only one; else a message listing them."""
    listed = ", ".join(repr(n) for n in sorted(found))
    if key is not None:
        name = _shown(_node_path(key))
        if name not in found:
            raise ValueError(f"{path}: no table {key!r} of numeric columns; its tables are "
                             f"{listed or 'none'}")
        return name
    if not found:
        raise ValueError(f"{path}: no table of numeric columns (a pandas table, or a group of "
                         "one-dimensional numeric datasets)")
    if len(found) > 1:
        raise ValueError(f"{path}: holds {len(found)} tables ({listed}); name one with --key "
                         f"NAME or as {Path(path).name}:NAME")
    return next(iter(found))


def _is_column(leaf: Any) -> bool:
    """A numeric dataset of one dimension (or two with one of length 1) and two values or more."""
    import tables

    if not isinstance(leaf, tables.Array) or leaf.dtype.kind not in "fiub":
        return False
    shape = tuple(leaf.shape)
    return 1 <= len(shape) <= 2 and max(shape) > 1 and (len(shape) == 1 or min(shape) == 1)


def _compound_fields(leaf: Any) -> list[str]:
    fields = leaf.dtype.fields or {}
    return [n for n, (dtype, *_) in fields.items() if dtype.kind in "fiub" and dtype.shape == ()]


def _plain_columns(node: Any, kind: str) -> dict[str, np.ndarray]:
    """The columns of a group of datasets or of a compound dataset."""
    if kind == "compound":
        records = node.read()
        return {n: np.asarray(records[n], float) for n in _compound_fields(node)}
    return {leaf.name: np.asarray(leaf.read(), float).ravel()
            for leaf in node._f_iter_nodes("Leaf") if _is_column(leaf)}


__all__ = ["HDF5_SUFFIXES", "split_key", "read_hdf5", "hdf5_tables"]
