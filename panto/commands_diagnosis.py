"""``panto diagnose``: where the model and the measurement disagree, which unmodelled effect causes
it, and how far the gap shrinks once it is in the model (issue 8).

``panto diagnose --train TRAIN --validate VALIDATION --model STRUCTURE [--inputs NAME=CHANNEL ...]
[--outputs NAME=CHANNEL ...] [--rate HZ] [--sample-rate HZ] [--roles position=..,force=..]
[--candidates ...] [--option KEY=VALUE ...] [--out FOLDER] [--json FILE]``

- Rig runs with a pantograph structure (``physical``, ``physical-linear``, ``two-mass``, ...) and
  no ``--inputs``/``--outputs``: the rig mapping (eta, p) -> (F_c, y_cb) at ``--rate`` (50 Hz).
- Any other data (CSV, Parquet or .mat with named columns; the product's datasets or plain
  tables): ``--inputs``/``--outputs`` name the columns; a plain table without a ``time``/``t``
  column needs ``--sample-rate``; ``--rate`` decimates (zero-phase low-pass first);
  ``--train-samples``/``--validate-samples START:STOP`` select rows (e.g. two parts of one file).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any, Callable

import numpy as np

PANTOGRAPH_MODELS = ("physical", "physical-linear", "two-mass", "two-mass-friction", "three-mass",
                     "three-mass-friction")


def _say(line: str) -> None:
    print(line, flush=True)


def _pairs(items: list[str] | None, flag: str) -> dict[str, str]:
    out = {}
    for item in items or []:
        for part in item.split(","):
            name, sep, value = part.partition("=")
            if not sep or not name.strip() or not value.strip():
                raise ValueError(f"{flag} {part!r}: expected NAME=VALUE")
            out[name.strip()] = value.strip()
    return out


def _value(text: str) -> Any:
    lowered = text.lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    if lowered == "none":
        return None
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _rows(text: str | None) -> slice:
    if not text:
        return slice(None)
    start, _, stop = text.partition(":")
    return slice(int(start) if start else None, int(stop) if stop else None)


def read_table(path: str | Path) -> dict[str, np.ndarray]:
    """Named columns of a plain CSV, Parquet or .mat file (1-D numeric variables of equal length)."""
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


def load_data(path: str, args: argparse.Namespace, rows: slice):
    """IdentificationData of one run from the options (module notes)."""
    from panto.identification.estimation.base import IdentificationData
    from panto.identification.data.datasets import data_from_dataset, pantograph_data

    inputs, outputs = _pairs(args.inputs, "--inputs"), _pairs(args.outputs, "--outputs")
    if not inputs and not outputs and args.model in PANTOGRAPH_MODELS:
        data = pantograph_data(path, rate=args.rate or 50.0, eta_offset=args.eta_offset)
        return _slice(data, rows)
    if not inputs or not outputs:
        raise ValueError("--inputs and --outputs name the columns (NAME=CHANNEL) for this data")
    try:
        from panto.rig.dataset import read_dataset

        dataset = read_dataset(path, required=())
    except Exception:  # not a dataset of this product: a plain table
        dataset = None
    if dataset is not None:
        return _slice(data_from_dataset(dataset, inputs=inputs, outputs=outputs, rate=args.rate,
                                        source=path), rows)
    table = read_table(path)
    missing = [c for c in list(inputs.values()) + list(outputs.values()) if c not in table]
    if missing:
        raise ValueError(f"{path}: no column(s) {missing}; columns are {sorted(table)}")
    length = len(next(iter(table.values())))
    time_column = next((table[c] for c in ("time", "t") if c in table), None)
    if args.sample_rate:
        time_column = np.arange(length) / args.sample_rate
    elif time_column is not None:  # the median step (printed times carry rounding)
        time_column = np.arange(length) * float(np.median(np.diff(time_column)))
    else:
        raise ValueError(f"{path}: no time column; give --sample-rate HZ")
    u = np.column_stack([table[c] for c in inputs.values()])[rows]
    y = np.column_stack([table[c] for c in outputs.values()])[rows]
    t = time_column[rows]
    if args.rate:
        t, u, y = _decimate(t, u, y, args.rate)
    return IdentificationData(t - t[0], u, y, tuple(inputs), tuple(outputs), source=path)


def _decimate(t: np.ndarray, u: np.ndarray, y: np.ndarray, rate: float):
    from scipy import signal as sps

    factor = int(round(1.0 / ((t[1] - t[0]) * rate)))
    if factor <= 1:
        return t, u, y
    sos = sps.butter(8, 0.8 / factor, output="sos")
    smooth = lambda x: sps.sosfiltfilt(sos, x, axis=0)
    return t[::factor], smooth(u)[::factor], smooth(y)[::factor]


def _slice(data, rows: slice):
    if rows == slice(None):
        return data
    from panto.identification.estimation.base import IdentificationData

    return IdentificationData(data.time[rows], data.inputs[rows], data.outputs[rows],
                              data.input_names, data.output_names, data.units, data.source,
                              data.metadata)


def _roles(text: str | None):
    if not text:
        return None
    from panto.identification.diagnosis.effects import SignalRoles

    values = _pairs([text], "--roles")
    actuators = tuple(a for a in values.pop("actuators", "").split("+") if a)
    unknown = sorted(set(values) - {"position", "velocity", "acceleration", "force", "mode_drive"})
    if unknown:
        raise ValueError(f"--roles: unknown role(s) {unknown}")
    return SignalRoles(position=values.get("position"), velocity=values.get("velocity"),
                       acceleration=values.get("acceleration"), force=values.get("force"),
                       actuators=actuators, mode_drive=values.get("mode_drive"))


def run_diagnose(args: argparse.Namespace) -> int:
    """Load both runs, diagnose, print the verdict, write the report."""
    from panto.identification.diagnosis.pipeline import diagnose
    from panto.identification.diagnosis.report import write_report
    from panto.identification.diagnosis.effects import EFFECTS

    train = load_data(args.train, args, _rows(args.train_samples))
    validation = load_data(args.validate, args, _rows(args.validate_samples))
    options = {k: _value(v) for k, v in _pairs(args.option, "--option").items()}
    if args.free:
        options["free"] = tuple(args.free)
    _say(f"diagnose {args.model}: training {args.train} ({len(train)} samples at "
         f"{1 / train.sample_period:g} Hz), validation {args.validate} ({len(validation)} samples)")
    result = diagnose(train, validation, structure=args.model, structure_options=options,
                      roles=_roles(args.roles), candidates=tuple(args.candidates or EFFECTS),
                      max_effects=args.max_effects, folds=args.folds, progress=_say)
    _say(f"verdict: {result.verdict}" + (f" ({' then '.join(result.effects)})"
                                         if result.effects else ""))
    for output in result.output_names:
        _say(f"  {output}: validation fit {result.fit_before[output]:.2f} % -> "
             f"{result.fit_after[output]:.2f} %")
    _say(result.summary)
    if args.out:
        paths = write_report(result, args.out)
        _say(f"wrote {paths['html']} and {paths['json']}")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(result.to_dict(), indent=2))
        _say(f"wrote {args.json}")
    return 0


def run_benchmark(args: argparse.Namespace) -> int:
    """Draw the cases, diagnose them blind in parallel, score, write JSON + markdown + PNG."""
    from concurrent.futures import ProcessPoolExecutor

    from panto.identification.diagnosis.benchmark import run_diagnosis_benchmark
    from panto.identification.diagnosis.benchmark_report import write_benchmark

    if args.cases < 1 or args.workers < 1 or args.duration <= 2.0:
        raise ValueError(f"--cases {args.cases}, --workers {args.workers}, --duration "
                         f"{args.duration}: need cases >= 1, workers >= 1, duration > 2 s")
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        result = run_diagnosis_benchmark(args.cases, args.seed, executor=pool, progress=_say,
                                         duration=args.duration, structure=args.model)
    target = Path(args.json) if args.json else Path(args.out) / "diagnosis_benchmark.json"
    paths = write_benchmark(result, target)
    _say(f"wrote {paths['json']}, {paths['markdown']} and {paths['png']}")
    return 0


def register(add: Callable) -> None:
    """Declare ``diagnose`` and ``diagnose-benchmark`` with ``add(name, handler, help)``."""
    p = add("diagnose", run_diagnose, "sim-to-real gap diagnosis: where the model misses, which "
            "unmodelled effect causes it, how far adding it closes the gap on withheld data")
    p.add_argument("--train", required=True, help="training run (folder, .csv, .parquet, .mat)")
    p.add_argument("--validate", required=True, help="withheld validation run")
    p.add_argument("--model", required=True, help="nominal structure: physical, physical-linear, "
                   "two-mass, three-mass, linear-N, rigid-body")
    p.add_argument("--inputs", nargs="*", help="NAME=CHANNEL (any data)")
    p.add_argument("--outputs", nargs="*", help="NAME=CHANNEL (any data)")
    p.add_argument("--rate", type=float, help="identification rate [Hz] (rig runs: 50)")
    p.add_argument("--sample-rate", type=float, help="rate of a table without a time column")
    p.add_argument("--train-samples", help="rows START:STOP of the training file")
    p.add_argument("--validate-samples", help="rows START:STOP of the validation file")
    p.add_argument("--eta-offset", type=float, help="rig runs: height of the motor's zero [m]")
    p.add_argument("--roles", help="position=..,velocity=..,force=..,actuators=a+b")
    p.add_argument("--candidates", nargs="*", help="subset of the effect vocabulary")
    p.add_argument("--free", nargs="*", help="free parameters of the nominal")
    p.add_argument("--option", nargs="*", help="structure option KEY=VALUE (e.g. centre=true, "
                   "cutoff=0.2, input_delay=1)")
    p.add_argument("--max-effects", type=int, default=3)
    p.add_argument("--folds", type=int, default=4)
    p.add_argument("--out", help="folder for report.html, report.json and the plots")
    p.add_argument("--json", help="also write the JSON summary here")

    b = add("diagnose-benchmark", run_benchmark, "blind benchmark of the diagnosis on the virtual "
            "test bed: hidden effects of random magnitude, confusion matrix and scores")
    b.add_argument("--cases", type=int, required=True, help="number of cases drawn")
    b.add_argument("--seed", type=int, default=0, help="seed of the draw")
    b.add_argument("--workers", type=int, default=2, help="processes running the cases")
    b.add_argument("--duration", type=float, default=25.0, help="length of each run [s]")
    b.add_argument("--model", default="physical-linear", help="nominal structure")
    b.add_argument("--out", default=".", help="folder for diagnosis_benchmark.json/.md/.png")
    b.add_argument("--json", help="JSON path (the .md and _confusion.png go beside it)")
