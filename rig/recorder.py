"""The recorder: writes a run to disk while it happens, so a crash or a fault loses little.

A run lives in its own folder::

    run_0007/run.csv        time [s], channels with units in the header, one row per sample
    run_0007/run.csv.json   units and metadata (:class:`panto.rig.dataset.RunMetadata`), with status

Rows are kept in a buffer of `buffer_rows` (500 = 1 s at 500 Hz) and appended to the CSV when it
is full, followed by ``flush`` and ``os.fsync``; so a crash of the process or of the machine loses
at most the last buffer (and at worst leaves a torn last line, which :func:`panto.rig.dataset.read_csv`
drops and reports). Writing and ``fsync`` of a buffer take a few milliseconds; in a 2 ms
real-time loop pass ``background=True``: full buffers then go to a writer thread (the loop only
formats rows, about 20 µs each), and a crash loses at most the buffer being written plus the one
being filled. The side file is written when the run starts (status ``"running"``) and
replaced atomically at the end with ``"complete"`` or ``"aborted: <reason> at t = <time> s"``.

A recorder never overwrites: it refuses a folder that already holds a run (the CSV is also opened
in exclusive-creation mode), and :func:`new_run_folder` makes the next free numbered folder.
Used as a context manager, an exception inside the block flushes what was recorded and marks the
run aborted before the exception propagates.
"""
from __future__ import annotations

import math
import os
import queue
import threading
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import TracebackType

import numpy as np

from panto.fmu_src.dataformat import csv_header, format_csv_row
from panto.rig.dataset import (REQUIRED_CHANNELS, STANDARD_CHANNELS, DatasetError, RunMetadata,
                               check_dataset, read_csv, write_sidecar)

RUN_FILE = "run.csv"


def new_run_folder(root: str | Path, prefix: str = "run") -> Path:
    """Create and return the next free folder ``<root>/<prefix>_0001``, ``..._0002``, ...

    The folder is created with ``mkdir(exist_ok=False)``, so two recorders started at once never
    get the same folder.
    """
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    taken = [int(p.name.rsplit("_", 1)[1]) for p in root.glob(f"{prefix}_*")
             if p.name.rsplit("_", 1)[1].isdigit()]
    number = max(taken, default=0) + 1
    while True:
        folder = root / f"{prefix}_{number:04d}"
        try:
            folder.mkdir()
            return folder
        except FileExistsError:
            number += 1


class Recorder:
    """Incremental writer of one run.

    Parameters
    ----------
    folder : str or pathlib.Path
        The run folder; created if needed; refused if it already holds a run.
    channels : sequence of str
        Channel names in column order (time comes first by itself).
    metadata : RunMetadata
        The run's metadata; its status is set to ``"running"`` until :meth:`finish`.
    units : mapping, optional
        Units of non-standard channels (standard ones have theirs, see
        :data:`panto.rig.dataset.STANDARD_CHANNELS`).
    buffer_rows : int
        Rows per flush (500 = 1 s at 500 Hz).
    required : sequence of str
        Channels that must be among `channels` (the rig's by default).
    background : bool
        Write and fsync full buffers in a writer thread instead of in :meth:`append`.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from panto.rig.dataset import RunMetadata, read_dataset
    >>> folder = pathlib.Path(tempfile.mkdtemp()) / "run_0001"
    >>> with Recorder(folder, channels=["force"], required=(),
    ...               metadata=RunMetadata(sample_rate=500.0, source="emulator")) as rec:
    ...     for k in range(3):
    ...         rec.append(k / 500.0, [100.0 + k])
    ...     _ = rec.finish()
    >>> read_dataset(folder, required=())["force"].tolist()
    [100.0, 101.0, 102.0]
    """

    def __init__(self, folder: str | Path, *, channels: Sequence[str], metadata: RunMetadata,
                 units: Mapping[str, str] | None = None, buffer_rows: int = 500,
                 required: Sequence[str] = REQUIRED_CHANNELS, background: bool = False) -> None:
        self.folder = Path(folder)
        self.path = self.folder / RUN_FILE
        if self.path.exists() or (self.folder / (RUN_FILE + ".json")).exists():
            raise FileExistsError(f"{self.folder}: already holds a run; a recorder never "
                                  "overwrites (use new_run_folder() for a fresh folder)")
        self.channels = tuple(channels)
        duplicated = sorted({n for n in self.channels if self.channels.count(n) > 1})
        if duplicated:
            raise DatasetError(f"{self.folder}: channel(s) {duplicated} duplicated")
        given = dict(units or {})
        self.units = {n: given.get(n, STANDARD_CHANNELS[n].unit if n in STANDARD_CHANNELS
                                   else "") for n in self.channels}
        check_dataset([], {n: [] for n in self.channels}, self.units, required=required,
                      source=str(self.folder))
        self._no_nan = np.array([n in STANDARD_CHANNELS and not STANDARD_CHANNELS[n].allow_nan
                                 for n in self.channels])
        self._no_nan_index = tuple(int(i) for i in np.flatnonzero(self._no_nan))
        self.metadata = metadata
        self.buffer_rows = max(1, int(buffer_rows))
        self.rows_written = 0
        self.last_time = -math.inf
        self.status = "running"
        self._buffer: list[str] = []
        self.folder.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "x", encoding="utf-8", newline="")  # never overwrite
        self._file.write(csv_header(self.channels, self.units))
        self._sync()
        write_sidecar(self.path, self.channels, self.units, metadata.with_status("running"))
        self._queue: queue.Queue[list[str] | None] | None = None
        self._writer_error: BaseException | None = None
        if background:
            self._queue = queue.Queue()
            self._writer = threading.Thread(target=self._write_in_background,
                                            name=f"recorder {self.folder.name}", daemon=True)
            self._writer.start()

    # --- writing ------------------------------------------------------------------------------

    def append(self, time: float, values: Sequence[float] | Mapping[str, float]) -> None:
        """Record one row; refuses (without recording it) a row that breaks the schema."""
        if self._file is None:
            raise RuntimeError(f"{self.folder}: the run is already {self.status}")
        if isinstance(values, Mapping):
            missing = [n for n in self.channels if n not in values]
            if missing:
                raise DatasetError(f"{self.folder}: row at t = {time!r} s lacks {missing}")
            row = [float(values[n]) for n in self.channels]
        else:
            row = [float(v) for v in values]
        if len(row) != len(self.channels):
            raise DatasetError(f"{self.folder}: row at t = {time!r} s has {len(row)} values for "
                               f"{len(self.channels)} channels")
        time = float(time)
        if not (math.isfinite(time) and time > self.last_time):
            raise DatasetError(f"{self.folder}: time {time!r} s is not finite and after the "
                               f"previous row ({self.last_time!r} s)")
        bad = [i for i in self._no_nan_index if row[i] != row[i]]  # NaN where not allowed
        if bad:
            raise DatasetError(f"{self.folder}: channel {self.channels[bad[0]]!r}: "
                               f"NaN at t = {time!r} s, not allowed in this channel")
        self._buffer.append(format_csv_row([time, *row]))
        self.last_time = time
        if len(self._buffer) >= self.buffer_rows:
            self.flush()

    def append_block(self, time: Sequence[float], values: Mapping[str, Sequence[float]]) -> None:
        """Record several rows: `time` and one array per channel."""
        columns = np.column_stack([np.asarray(values[n], dtype=float) for n in self.channels])
        for t, row in zip(np.asarray(time, dtype=float).tolist(), columns.tolist()):
            self.append(t, row)

    def _sync(self) -> None:
        self._file.flush()
        os.fsync(self._file.fileno())

    def flush(self) -> None:
        """Write the buffer to the CSV and force it to disk (``flush`` + ``os.fsync``); with
        ``background`` hand it to the writer thread."""
        if self._file is None or not self._buffer:
            return
        lines, self._buffer = self._buffer, []
        if self._queue is None:
            self._write(lines)
            return
        if self._writer_error is not None:
            raise OSError(f"{self.path}: the writer thread failed: {self._writer_error}")
        self._queue.put(lines)

    def _write(self, lines: list[str]) -> None:
        self._file.writelines(lines)
        self._sync()
        self.rows_written += len(lines)

    def _write_in_background(self) -> None:
        while (lines := self._queue.get()) is not None:
            try:
                self._write(lines)
            except BaseException as error:  # reported by the next flush or at the end
                self._writer_error = error
                return

    def _drain(self) -> None:
        """Wait until the writer thread has written everything handed to it."""
        if self._queue is not None:
            self._queue.put(None)
            self._writer.join()
            self._queue = None

    # --- ending -------------------------------------------------------------------------------

    def _close(self, status: str) -> None:
        try:
            self.flush()
        except OSError:
            pass  # the writer thread failed: reported below
        self._drain()
        self._file.close()
        self._file = None
        if self._writer_error is not None:
            status = f"aborted: writing failed ({self._writer_error})"
        self.status = status
        self.metadata = self.metadata.with_status(status)
        write_sidecar(self.path, self.channels, self.units, self.metadata)
        if self._writer_error is not None:
            raise OSError(f"{self.path}: {status}")

    def finish(self, *, formats: Sequence[str] = ()) -> Path:
        """Flush, close, mark the run ``"complete"``; optionally write ``run.parquet`` /
        ``run.mat`` copies (`formats` among ``"parquet"``, ``"mat"``). Returns the folder."""
        unknown = sorted(set(formats) - {"parquet", "mat"})
        if unknown:
            raise ValueError(f"formats = {unknown}: only 'parquet' and 'mat' copies exist")
        if self._file is not None:
            self._close("complete")
        if formats:
            dataset = read_csv(self.path, required=())
            for suffix in formats:
                dataset.write(self.folder / f"run.{suffix}")
        return self.folder

    def abort(self, reason: str, *, at: float | None = None) -> Path:
        """Flush what was recorded and mark the run ``"aborted: <reason> at t = <at> s"``."""
        if self._file is None:
            return self.folder
        instant = self.last_time if at is None else at
        where = (f" at t = {round(instant, 6)!r} s" if math.isfinite(instant)
                 else " before the first row")
        self._close(f"aborted: {reason.strip() or 'no reason given'}{where}")
        return self.folder

    def __enter__(self) -> "Recorder":
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        if self._file is None:
            return
        if error is not None:
            self.abort(f"{kind.__name__}: {error}")
        else:
            self.abort("recorder closed without finish()")
