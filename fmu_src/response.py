"""Time responses: a time vector and named signals with units, as every part of the project uses.

A :class:`TimeResponse` is what a simulation returns, what a recorder writes and what an estimator
compares: sampled signals :math:`y_i(t_k)` on one strictly increasing time grid :math:`t_k` (in
seconds), each with a name and a unit, plus free metadata (model, interface, parameters used, ...).
It is immutable; methods that change something return a new response.

Files a person can open: :meth:`TimeResponse.to_csv` writes a plain CSV whose header carries the
units (``time [s],F_c [N],xi [1]``) and, when there is metadata, a JSON side file next to it;
:meth:`TimeResponse.from_csv` reads both back (the format: :mod:`panto.fmu_src.dataformat`).
:meth:`TimeResponse.save_plot` writes a PNG/PDF/SVG.

The design follows python-control's ``TimeResponseData`` (named signals, ``to_pandas()``,
``plot()``), reduced to what a sampled, single-trajectory signal set needs.
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from panto.fmu_src.dataformat import (TIME_NAME, TIME_UNIT, csv_header, csv_read_options,
                                      format_csv_row, format_header, parse_header,
                                      read_side_file, write_side_file)

if TYPE_CHECKING:  # imported lazily at run time: pandas and matplotlib are slow to import
    import pandas
    from matplotlib.figure import Figure


def _frozen_array(values: Any, what: str) -> np.ndarray:
    """Return `values` as a read-only 1-D float array, or raise a ValueError naming `what`."""
    try:
        array = np.array(values, dtype=float)  # a copy: the caller's array stays theirs
    except (TypeError, ValueError) as error:
        raise ValueError(f"{what} must be numeric: {error}") from None
    if array.ndim != 1:
        raise ValueError(f"{what} must be one-dimensional, got shape {array.shape}")
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False, repr=False)
class TimeResponse:
    """Named signals sampled on one time grid, with units and metadata.

    Parameters
    ----------
    time : array_like, shape (n,)
        Sample times :math:`t_0 < t_1 < \\dots < t_{n-1}` in seconds, finite and strictly
        increasing.
    signals : mapping of str to array_like, shape (n,)
        Signal name → samples :math:`y(t_k)`. The order of the mapping is the order of
        :attr:`names`. NaN marks a missing sample.
    units : mapping of str to str, optional
        Signal name → unit in the project's notation (``"N"``, ``"m"``, ``"rad/s"``, ``"1"`` for
        dimensionless). Signals without an entry get ``""`` (unknown). Time is always in ``s``.
    metadata : mapping, optional
        Free information on where the response comes from: model name, interface (``"ME"``,
        ``"CS"``, ``"python"``), parameters used, file it was read from, ...

    Raises
    ------
    ValueError
        If the time vector is not one-dimensional, finite and strictly increasing, if a signal's
        length differs from the time vector's (the message names the signal), or if a unit is
        given for a name that is not a signal.

    Notes
    -----
    The response is immutable: the arrays are read-only copies and the mappings read-only views.
    Methods such as :meth:`resample` return a new response.

    Examples
    --------
    >>> import numpy as np
    >>> from panto.fmu_src.response import TimeResponse
    >>> t = np.linspace(0.0, 1.0, 5)
    >>> response = TimeResponse(t, {"x": 0.01 * t, "F_c": 100.0 + 0 * t},
    ...                         units={"x": "m", "F_c": "N"}, metadata={"model": "Toy"})
    >>> response.names
    ('x', 'F_c')
    >>> float(response["F_c"][-1])
    100.0
    >>> response.to_pandas().columns.tolist()
    ['x', 'F_c']
    >>> float(response.resample([0.125])["x"][0])
    0.00125
    """

    time: np.ndarray
    signals: Mapping[str, np.ndarray]
    units: Mapping[str, str] = field(default_factory=dict)
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        time = _frozen_array(self.time, "time")
        if not np.all(np.isfinite(time)):
            index = int(np.flatnonzero(~np.isfinite(time))[0])
            raise ValueError(f"time must be finite, got {time[index]} at index {index}")
        steps = np.diff(time)
        if np.any(steps <= 0.0):
            index = int(np.flatnonzero(steps <= 0.0)[0])
            raise ValueError(
                "time must be strictly increasing, got "
                f"time[{index}] = {time[index]!r} and time[{index + 1}] = {time[index + 1]!r}")
        signals: dict[str, np.ndarray] = {}
        for name, values in dict(self.signals).items():
            if not isinstance(name, str) or not name:
                raise ValueError(f"signal names must be non-empty strings, got {name!r}")
            if name == TIME_NAME:
                raise ValueError(f"{TIME_NAME!r} is reserved for the time vector, not a signal")
            array = _frozen_array(values, f"signal {name!r}")
            if array.shape != time.shape:
                raise ValueError(f"signal {name!r} has {array.size} samples but time has "
                                 f"{time.size}")
            signals[name] = array
        units = {str(name): str(unit) for name, unit in dict(self.units).items()}
        unknown = sorted(set(units) - set(signals) - {TIME_NAME})
        if unknown:
            raise ValueError(f"units given for unknown signal(s) {unknown}; signals are "
                             f"{list(signals)}")
        if units.get(TIME_NAME, TIME_UNIT) != TIME_UNIT:
            raise ValueError(f"time is in {TIME_UNIT!r}, got unit {units[TIME_NAME]!r}")
        units = {name: units.get(name, "") for name in signals}
        object.__setattr__(self, "time", time)
        object.__setattr__(self, "signals", MappingProxyType(signals))
        object.__setattr__(self, "units", MappingProxyType(units))
        object.__setattr__(self, "metadata", MappingProxyType(dict(self.metadata)))

    # --- access -----------------------------------------------------------------------------

    @property
    def names(self) -> tuple[str, ...]:
        """Signal names, in order (time is not a signal)."""
        return tuple(self.signals)

    def __getitem__(self, name: str) -> np.ndarray:
        """Samples of the signal `name` (read-only array); ``"time"`` gives the time vector."""
        if name == TIME_NAME:
            return self.time
        try:
            return self.signals[name]
        except KeyError:
            raise KeyError(f"no signal {name!r}; signals are {list(self.names)}") from None

    def __contains__(self, name: object) -> bool:
        return name in self.signals

    def __len__(self) -> int:
        """Number of samples."""
        return int(self.time.size)

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickle (e.g. to return from a process-pool worker) through the constructor."""
        return (type(self), (np.array(self.time), dict(self.signals), dict(self.units),
                             dict(self.metadata)))

    def __repr__(self) -> str:
        span = (f"t = {self.time[0]:g} … {self.time[-1]:g} s" if self.time.size
                else "no samples")
        signals = ", ".join(format_header(name, unit) for name, unit in self.units.items())
        return f"TimeResponse({len(self)} samples, {span}; {signals})"

    def _repr_html_(self) -> str:
        """A notebook's view: the time span, then one row per signal (unit, range, NaNs)."""
        from panto.fmu_src.display import html_block, html_table

        rows = []
        for name, values in self.signals.items():
            finite = values[np.isfinite(values)]
            low, high = (finite.min(), finite.max()) if finite.size else (None, None)
            rows.append([name, self.units[name] or "?", low, high,
                         int(values.size - finite.size)])
        span = (f"{len(self)} samples, t = {self.time[0]:g} to {self.time[-1]:g} s"
                if self.time.size else "no samples")
        source = ", ".join(str(self.metadata[key]) for key in ("model", "interface", "source")
                           if self.metadata.get(key))
        table = html_table(["signal", "unit", "minimum", "maximum", "missing samples"], rows)
        return html_block("TimeResponse", table, lines=[span, source])

    # --- tables and files -------------------------------------------------------------------

    def to_pandas(self, *, units_in_names: bool = False) -> pandas.DataFrame:
        """The signals as a DataFrame indexed by time.

        Parameters
        ----------
        units_in_names : bool, optional
            Name the columns ``name [unit]`` (and the index ``time [s]``) as the CSV header
            does, e.g. for a table a person reads; default ``False``: the plain signal names.

        Returns
        -------
        pandas.DataFrame
            Index named ``"time"`` (s), one column per signal named as in :attr:`names`.
            ``df.attrs["units"]`` maps each column (and ``"time"``) to its unit and
            ``df.attrs["metadata"]`` holds a copy of :attr:`metadata`.

        Examples
        --------
        >>> from panto.fmu_src.response import TimeResponse
        >>> df = TimeResponse([0.0, 1.0], {"F_c": [90.0, 110.0]}, units={"F_c": "N"}).to_pandas()
        >>> df.attrs["units"]["F_c"]
        'N'
        >>> df = TimeResponse([0.0, 1.0], {"F_c": [90.0, 110.0]}, units={"F_c": "N"}).to_pandas(
        ...     units_in_names=True)
        >>> df.index.name, df.columns.tolist()
        ('time [s]', ['F_c [N]'])
        """
        import pandas as pd

        def column(name: str) -> str:
            return format_header(name, self.units.get(name, TIME_UNIT)) if units_in_names \
                else name

        frame = pd.DataFrame({column(name): np.array(values)
                              for name, values in self.signals.items()},
                             index=pd.Index(np.array(self.time), name=column(TIME_NAME)))
        frame.attrs["units"] = {column(TIME_NAME): TIME_UNIT,
                                **{column(name): unit for name, unit in self.units.items()}}
        frame.attrs["metadata"] = dict(self.metadata)
        return frame

    def to_csv(self, path: str | Path, *, write_metadata: bool = True) -> Path:
        """Write the response as a plain CSV with units in the header.

        The first column is ``time [s]``, then one column per signal headed ``name [unit]``
        (just ``name`` when the unit is unknown). Numbers are written with full precision, so
        :meth:`from_csv` restores them exactly; missing samples are empty cells. When
        `write_metadata` is true and there is metadata, it goes to the JSON side file
        :func:`~panto.fmu_src.dataformat.metadata_path_for` (``result.csv.json``).

        Parameters
        ----------
        path : str or pathlib.Path
            CSV file to write; its folder must exist.
        write_metadata : bool, optional
            Write the metadata side file (default ``True``).

        Returns
        -------
        pathlib.Path
            The CSV path written.

        Examples
        --------
        >>> import tempfile, pathlib
        >>> from panto.fmu_src.response import TimeResponse
        >>> response = TimeResponse([0.0, 0.5], {"F_c": [90.0, 110.0]}, units={"F_c": "N"})
        >>> path = response.to_csv(pathlib.Path(tempfile.mkdtemp()) / "contact.csv")
        >>> path.read_text().splitlines()[0]
        'time [s],F_c [N]'
        >>> TimeResponse.from_csv(path)["F_c"].tolist()
        [90.0, 110.0]
        """
        path = Path(path)
        columns = np.column_stack([self.time, *self.signals.values()])
        with open(path, "w", encoding="utf-8", newline="") as stream:
            stream.write(csv_header(self.names, self.units))
            stream.writelines(format_csv_row(row) for row in columns.tolist())
        if write_metadata and self.metadata:
            write_side_file(path, dict(self.metadata))
        return path

    @classmethod
    def from_csv(cls, path: str | Path) -> "TimeResponse":
        """Read a response written by :meth:`to_csv` (or any CSV laid out the same way).

        Parameters
        ----------
        path : str or pathlib.Path
            CSV whose first column is time in seconds (header ``time [s]``, ``time`` or
            ``t [s]``) and whose other columns are signals headed ``name [unit]`` or ``name``.

        Returns
        -------
        TimeResponse
            With the units from the header, and the metadata from the JSON side file when it
            exists (JSON turns tuples into lists), plus ``metadata["source"]`` = the CSV path.

        Raises
        ------
        ValueError
            If the file is empty, the first column is not time in seconds, a cell is not a
            number, or time is not strictly increasing; the message names the file.
        """
        import pandas as pd

        path = Path(path)
        try:
            frame = pd.read_csv(path, **csv_read_options())
        except pd.errors.EmptyDataError:
            raise ValueError(f"{path}: file is empty") from None
        if frame.shape[1] == 0:
            raise ValueError(f"{path}: no columns")
        headers = [parse_header(str(column)) for column in frame.columns]
        time_name, time_unit = headers[0]
        if time_name not in (TIME_NAME, "t") or time_unit not in ("", TIME_UNIT):
            raise ValueError(f"{path}: first column must be time in seconds ('time [s]'), "
                             f"got {frame.columns[0]!r}")
        names = [name for name, _ in headers[1:]]
        duplicates = sorted({name for name in names if names.count(name) > 1})
        if duplicates:
            raise ValueError(f"{path}: duplicate column(s) {duplicates}")
        signals = {}
        for column, name in zip(frame.columns[1:], names):
            try:
                signals[name] = pd.to_numeric(frame[column]).to_numpy(dtype=float)
            except (TypeError, ValueError) as error:
                raise ValueError(f"{path}: column {column!r} is not numeric ({error})") from None
        metadata: dict[str, Any] = dict(read_side_file(path) or {})
        metadata["source"] = str(path)
        try:
            return cls(time=frame.iloc[:, 0].to_numpy(dtype=float), signals=signals,
                       units={name: unit for name, unit in headers[1:]}, metadata=metadata)
        except ValueError as error:
            raise ValueError(f"{path}: {error}") from None

    # --- derived responses --------------------------------------------------------------------

    def resample(self, time: Sequence[float] | np.ndarray) -> "TimeResponse":
        """The response at other time points, by linear interpolation between samples.

        Between samples :math:`t_k \\le t \\le t_{k+1}`,

        .. math:: y(t) = y_k + \\frac{t - t_k}{t_{k+1} - t_k} (y_{k+1} - y_k).

        Parameters
        ----------
        time : array_like, shape (m,)
            New time points in seconds, strictly increasing and inside
            ``[self.time[0], self.time[-1]]`` (no extrapolation).

        Returns
        -------
        TimeResponse
            Same names, units and metadata, sampled at `time`.

        Raises
        ------
        ValueError
            If a new time point lies outside the recorded span, or `time` is not strictly
            increasing.

        Examples
        --------
        >>> import numpy as np
        >>> from panto.fmu_src.response import TimeResponse
        >>> response = TimeResponse([0.0, 2.0], {"x": [0.0, 4.0]}, units={"x": "m"})
        >>> response.resample([0.5, 1.0])["x"].tolist()
        [1.0, 2.0]
        """
        new_time = _frozen_array(time, "time")
        if new_time.size and self.time.size:
            span = self.time[-1] - self.time[0]
            slack = 1e-12 * max(span, abs(self.time[0]), abs(self.time[-1]), 1.0)
            if new_time[0] < self.time[0] - slack or new_time[-1] > self.time[-1] + slack:
                raise ValueError(
                    f"cannot resample at t = {new_time[0]:g} … {new_time[-1]:g} s: the response "
                    f"covers only {self.time[0]:g} … {self.time[-1]:g} s (no extrapolation)")
        elif new_time.size:
            raise ValueError("cannot resample a response without samples")
        signals = {name: np.interp(new_time, self.time, values)
                   for name, values in self.signals.items()}
        return TimeResponse(new_time, signals, units=self.units, metadata=self.metadata)

    # --- plots ----------------------------------------------------------------------------------

    def plot(self, names: Iterable[str] | None = None, ax: Any = None, *,
             label: str | None = None, **line_options: Any) -> Figure:
        """Plot signals against time, one subplot per signal, units on the axes.

        The figure is a bare :class:`matplotlib.figure.Figure` (no pyplot, no GUI, no global
        figure registry, no backend chosen), so it is safe in scripts, tests, servers and loops;
        save it with ``fig.savefig(...)`` or :meth:`save_plot`. Jupyter and IPython display it
        as a picture when it is the last expression of a cell
        (:class:`panto.fmu_src.figures.NotebookFigure`).

        Parameters
        ----------
        names : iterable of str, optional
            Signals to plot, in order (default: all).
        ax : matplotlib.axes.Axes or sequence of Axes, optional
            Where to draw instead of a new figure: a sequence with one Axes per signal (e.g.
            ``fig.axes`` of an earlier plot, to overlay two responses), or a single Axes on which
            all the signals are drawn together.
        label : str, optional
            Legend label of the lines (a legend is drawn when given, or when several signals
            share one Axes).
        **line_options
            Passed to :meth:`matplotlib.axes.Axes.plot` (``color``, ``linestyle``, ...).

        Returns
        -------
        matplotlib.figure.Figure
            The figure drawn on.

        Examples
        --------
        >>> import numpy as np
        >>> from panto.fmu_src.response import TimeResponse
        >>> t = np.linspace(0.0, 1.0, 11)
        >>> measured = TimeResponse(t, {"x": t, "F_c": 1 + t}, units={"x": "m", "F_c": "N"})
        >>> fig = measured.plot(label="measured")
        >>> len(fig.axes)
        2
        >>> fig = measured.plot(ax=fig.axes, label="again", linestyle="--")
        """
        selected = list(self.names if names is None else names)
        if isinstance(names, str):
            selected = [names]
        for name in selected:
            self[name]  # raises a KeyError listing the valid names
        if not selected:
            raise ValueError("nothing to plot: no signal names selected")
        axes, shared = self._axes_for(selected, ax)
        for axis, name in zip(axes, selected):
            heading = format_header(name, self.units[name])
            line_label = label if not shared else (f"{name} ({label})" if label else name)
            axis.plot(self.time, self.signals[name], label=line_label, **line_options)
            if not shared:
                axis.set_ylabel(heading)
            axis.grid(True, alpha=0.3)
        if shared:
            units = {self.units[name] for name in selected}
            axes[0].set_ylabel(f"[{units.pop()}]" if len(units) == 1 else "")
        for axis in set(axes):
            if label is not None or shared:
                axis.legend(loc="best", fontsize="small")
        axes[-1].set_xlabel(format_header(TIME_NAME, TIME_UNIT))
        return axes[0].figure

    def _axes_for(self, names: list[str], ax: Any) -> tuple[list[Any], bool]:
        """Axes to draw `names` on, and whether they all share one Axes."""
        if ax is None:
            from panto.fmu_src.figures import NotebookFigure

            figure = NotebookFigure(figsize=(8.0, 1.0 + 1.8 * len(names)), layout="constrained")
            axes = figure.subplots(len(names), 1, sharex=True, squeeze=False)[:, 0]
            title = self.metadata.get("model")
            if title:
                figure.suptitle(f"{title} ({self.metadata['interface']})"
                                if self.metadata.get("interface") else str(title))
            return list(axes), False
        if hasattr(ax, "plot"):
            return [ax] * len(names), len(names) > 1
        axes = list(np.ravel(np.asarray(ax, dtype=object)))
        if len(axes) != len(names):
            raise ValueError(f"got {len(axes)} Axes for {len(names)} signals {names}; pass one "
                             "Axes per signal, or a single Axes")
        return axes, False

    def save_plot(self, path: str | Path, names: Iterable[str] | None = None, *,
                  dpi: float = 150.0, **plot_options: Any) -> Path:
        """Plot (see :meth:`plot`) and write the figure to `path` (PNG, PDF, SVG by suffix).

        Returns
        -------
        pathlib.Path
            The file written.

        Examples
        --------
        >>> import tempfile, pathlib
        >>> from panto.fmu_src.response import TimeResponse
        >>> response = TimeResponse([0.0, 1.0], {"F_c": [90.0, 110.0]}, units={"F_c": "N"})
        >>> response.save_plot(pathlib.Path(tempfile.mkdtemp()) / "contact.png").suffix
        '.png'
        """
        path = Path(path)
        figure = self.plot(names, **plot_options)
        figure.savefig(path, dpi=dpi)
        return path


def is_close(first: TimeResponse, second: TimeResponse, *, rtol: float = 1e-9,
             atol: float = 0.0) -> bool:
    """Whether two responses have the same names, units, time grid and (nearly) equal samples.

    Metadata is not compared. NaNs compare equal to NaNs.
    """
    if first.names != second.names or dict(first.units) != dict(second.units):
        return False
    if first.time.shape != second.time.shape or not np.allclose(first.time, second.time,
                                                                rtol=rtol, atol=atol):
        return False
    return all(np.allclose(first[name], second[name], rtol=rtol, atol=atol, equal_nan=True)
               for name in first.names)


__all__ = ["TimeResponse", "is_close"]
