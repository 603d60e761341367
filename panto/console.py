"""What the command line prints: results on standard output, everything else on standard error.

- :func:`say` prints a result line on standard output (on standard error when ``--json -``
  takes standard output for the JSON document alone, :func:`write_json`).
- :func:`progress` is the callback the CLI hands to the library's ``progress=`` parameters: each
  line is a :mod:`logging` record (logger ``panto.progress``, level INFO; a line with the word
  ``WARNING`` at level WARNING) written to standard error. On a terminal, lines that count
  (``3/10``, ``t = 4.0 s of 30 s``, `` 42 %``, ``120 evaluations``, ``round 2``) move a
  :mod:`tqdm` progress bar instead of scrolling; a count's last line stays.
- :func:`set_verbosity` sets how much: ``--quiet`` only warnings and errors; the default the
  progress; ``-v`` every line with its time and the library's debug records, no bar; ``-vv``
  also the records of third-party libraries.
"""
from __future__ import annotations

import json
import logging
import re
import sys
from pathlib import Path
from typing import Any

#: The logger of the progress lines.
LOGGER = logging.getLogger("panto.progress")

#: Verbosity levels of :func:`set_verbosity`: ``--quiet``, default, ``-v``, ``-vv``.
QUIET, NORMAL, VERBOSE, DEBUG = -1, 0, 1, 2

# A line that counts: (pattern, how to read done and total from the match).
_COUNTS = (
    (re.compile(r"(\d+)\s*/\s*(\d+)(?![\d.])"), lambda m: (int(m[1]), int(m[2]))),
    (re.compile(r"t\s*=\s*([\d.]+)\s*s of ([\d.]+)\s*s"), lambda m: (float(m[1]), float(m[2]))),
    (re.compile(r"^\s*(\d+)\s*%"), lambda m: (int(m[1]), 100)),
    (re.compile(r"(\d+) evaluations"), lambda m: (int(m[1]), None)),
    (re.compile(r"\bround (\d+)\b"), lambda m: (int(m[1]), None)),
)
_WARNING = re.compile(r"\bWARNING\b")


class _State:
    """The console's settings for the running command and its progress bar, if any."""

    level = NORMAL
    results_to_stderr = False
    bars = False
    bar: Any = None
    bar_key: tuple | None = None


def _terminal() -> bool:
    """Whether standard error is a terminal (a progress bar is drawn only there)."""
    isatty = getattr(sys.stderr, "isatty", None)
    return bool(isatty and isatty())


def say(line: str) -> None:
    """Print the result line `line` (standard output; standard error under ``--json -``)."""
    stream = sys.stderr if _State.results_to_stderr else sys.stdout
    with _bar_hidden():
        print(line, file=stream, flush=True)


def progress(line: str) -> None:
    """Report how a run goes: the ``progress=`` callback the CLI gives the library."""
    if _WARNING.search(line):
        LOGGER.warning(line.strip())
        return
    if _State.bars and LOGGER.isEnabledFor(logging.INFO) and _count(line):
        return
    LOGGER.info(line)


def write_json(target: str, document: Any, *, default: Any = None) -> None:
    """Write `document` as JSON to the file `target`, or to standard output if `target` is ``-``.

    Parameters
    ----------
    target : str
        A file path (its folder is created; ``wrote <path>`` is said) or ``-``.
    document : Any
        JSON-serialisable object.
    default : callable, optional
        ``json.dumps``'s converter for other objects.
    """
    text = json.dumps(document, indent=2, default=default) + "\n"
    if target == "-":
        sys.stdout.write(text)
        sys.stdout.flush()
        return
    Path(target).parent.mkdir(parents=True, exist_ok=True)
    Path(target).write_text(text)
    say(f"wrote {target}")


def set_verbosity(level: int = NORMAL, *, json_to_stdout: bool = False) -> None:
    """Set up standard error's logging for a command (``reset`` with the defaults).

    Parameters
    ----------
    level : int
        :data:`QUIET`, :data:`NORMAL`, :data:`VERBOSE` or :data:`DEBUG` (higher: more).
    json_to_stdout : bool
        ``--json -``: standard output carries only the JSON document; :func:`say` goes to
        standard error.
    """
    _close_bar()
    _State.level = max(QUIET, min(DEBUG, level))
    _State.results_to_stderr = json_to_stdout
    _State.bars = _State.level == NORMAL and _terminal()
    _HANDLER.setFormatter(_Formatter(timestamps=_State.level >= VERBOSE))
    verbose = _State.level >= VERBOSE
    logging.getLogger("panto").setLevel(logging.DEBUG if verbose else logging.WARNING)
    LOGGER.setLevel(logging.INFO if _State.level == NORMAL else logging.NOTSET)
    root = logging.getLogger()
    if _HANDLER not in root.handlers:
        root.addHandler(_HANDLER)
    root.setLevel(logging.DEBUG if _State.level >= DEBUG else logging.WARNING)


def reset() -> None:
    """End the command's logging: close the bar, remove the handler, restore the defaults."""
    set_verbosity(NORMAL)
    logging.getLogger().removeHandler(_HANDLER)
    logging.getLogger("panto").setLevel(logging.NOTSET)
    LOGGER.setLevel(logging.NOTSET)
    logging.getLogger().setLevel(logging.WARNING)
    _State.bars = False


class _Formatter(logging.Formatter):
    """Progress lines as they are; other records with their level and logger."""

    def __init__(self, *, timestamps: bool) -> None:
        super().__init__(datefmt="%H:%M:%S")
        self.timestamps = timestamps

    def format(self, record: logging.LogRecord) -> str:
        """The record as one line (with its time under ``-v``)."""
        text = record.getMessage()
        if record.name != LOGGER.name:
            text = f"{record.levelname} {record.name}: {text}"
        if record.exc_info:
            text += "\n" + self.formatException(record.exc_info)
        return f"{self.formatTime(record, self.datefmt)} {text}" if self.timestamps else text


class _StderrHandler(logging.Handler):
    """Write records to the current ``sys.stderr`` above the progress bar, if one is drawn."""

    def emit(self, record: logging.LogRecord) -> None:
        """Print the formatted record on standard error and flush."""
        try:
            text = self.format(record)
            with _bar_hidden():
                print(text, file=sys.stderr, flush=True)
        except Exception:  # logging's convention: a failing handler never raises
            self.handleError(record)


_HANDLER = _StderrHandler()


class _bar_hidden:
    """Context: the progress bar is cleared while a line is printed, then redrawn below it."""

    def __enter__(self) -> None:
        if _State.bar is not None:
            _State.bar.clear()

    def __exit__(self, *exc: Any) -> None:
        if _State.bar is not None:
            _State.bar.refresh()


def _count(line: str) -> bool:
    """Move the progress bar if `line` counts (module notes); whether it did."""
    for pattern, read in _COUNTS:
        match = pattern.search(line)
        if match:
            done, total = read(match)
            break
    else:
        return False
    if total is not None and (total <= 0 or done > total):
        return False
    key = (re.sub(r"[\d.]+", "#", line[:match.start()]).strip("[ "), total)
    text = " ".join(line.split())[:60]
    if _State.bar is None or _State.bar_key != key or done < _State.bar.n:
        _open_bar(key, total, text)
    _State.bar.set_description_str(text, refresh=False)
    _State.bar.update(done - _State.bar.n)
    if total is not None and done >= total:  # done: the last line stays, as a log line
        _close_bar()
        return False
    return True


def _open_bar(key: tuple, total: float | None, text: str) -> None:
    from tqdm import tqdm

    _close_bar()
    _State.bar = tqdm(total=total, desc=text, file=sys.stderr, leave=False, dynamic_ncols=True,
                      bar_format=None if total else "{desc} [{elapsed}]")
    _State.bar_key = key


def _close_bar() -> None:
    if _State.bar is not None:
        bar, _State.bar, _State.bar_key = _State.bar, None, None
        bar.close()
