"""``panto sync``, ``panto preprocess``, ``panto aliasing-check`` (thesis 3.2 and 4.2).

* ``panto sync RUN_FOLDER TRACK_CSV --out FOLDER [--json FILE] [--plot sync.png]
  [--min-confidence X]``: align a marker track with a 500 Hz run through the LED and write the
  merged dataset ``FOLDER/run.csv``; a refused alignment exits non-zero and writes nothing;
* ``panto preprocess DATASET --rate 50 --out FILE``: zero-phase low-pass (20 Hz stop band) and
  decimation;
* ``panto aliasing-check RUN_A RUN_B --channel force --out PNG [--json FILE]``: compare the spectra
  of two runs recorded at mutually prime rates (thesis Fig. 4.1); exits 1 when aliasing is
  suspected.
"""
from __future__ import annotations

import argparse
from typing import Callable

from panto.console import progress, say, write_json
from panto.data_options import non_negative_int, positive_float


def run_sync(args: argparse.Namespace) -> int:
    """Synchronise and merge (module notes)."""
    from panto.video_sync.merge import MergeOptions, sync_and_merge

    options = MergeOptions(interpolation=args.interpolation, min_confidence=args.min_confidence,
                           min_peak_ratio=args.min_peak_ratio, min_overlap=args.min_overlap,
                           min_led_quality=args.min_led_quality)
    result = sync_and_merge(args.run_folder, args.track_csv, args.out, options=options,
                            plot=args.plot, progress=progress)
    sync = result.sync
    seconds = sync.shift / result.dataset.metadata.sample_rate
    say(f"shift {sync.shift} fine samples = {seconds:+.3f} s (lag {sync.lag} frames, phase "
        f"{sync.phase})")
    say(f"confidence {sync.confidence:.3f} (second best {sync.second_best:.3f}, peak ratio "
        f"{sync.peak_ratio:.2f}, tied shifts {sync.tied_shifts})")
    say(f"frames merged {result.frames_merged}, samples {len(result.dataset)}")
    say("gap samples: " + ", ".join(f"{m} {n}" for m, n in result.gap_samples.items()))
    say(f"wrote {result.path}" + (f" and {result.plot}" if result.plot else ""))
    if args.json:
        summary = dict(result.dataset.metadata.extra["video_sync"])
        summary.update(merged_dataset=str(result.path), samples=len(result.dataset))
        write_json(args.json, summary)
    return 0


def run_preprocess(args: argparse.Namespace) -> int:
    """Low-pass and resample a dataset."""
    from panto.identification.data.preprocessing import resample_dataset
    from panto.rig.dataset import read_dataset

    dataset = read_dataset(args.dataset, required=())
    out = resample_dataset(dataset, args.rate, stopband=args.stopband, passband=args.passband,
                           channels=args.channels)
    record = out.metadata.extra["preprocessing"][-1]
    say(f"{len(dataset)} samples at {dataset.metadata.sample_rate:g} Hz -> {len(out)} at "
        f"{args.rate:g} Hz; filter: Butterworth order {record['filter']['order']}, pass band "
        f"{record['filter']['passband_hz']:g} Hz, stop band {args.stopband:g} Hz, zero phase")
    for name, count in record["nan_samples_from_gaps"].items():
        say(f"  {name}: {count} samples NaN (filter touched a gap)")
    say(f"wrote {out.write(args.out)}")
    return 0


def run_aliasing_check(args: argparse.Namespace) -> int:
    """Compare two runs' spectra; exit 1 when aliasing is suspected."""
    from panto.identification.data.plots import plot_aliasing_check
    from panto.identification.data.preprocessing import check_aliasing
    from panto.rig.dataset import read_dataset

    check = check_aliasing(read_dataset(args.run_a, required=()),
                           read_dataset(args.run_b, required=()), args.channel,
                           band_width=args.band_width, tolerance_db=args.tolerance_db)
    rates = " and ".join(f"{r:g} Hz" for r in check.rates)
    say(f"{args.channel} at {rates} (mutually prime: {'yes' if check.coprime else 'NO'}), "
        f"compared up to {check.max_frequency:g} Hz in {check.relevant.sum()} relevant bands")
    if check.aliasing_suspected:
        for low, high, difference in check.where:
            say(f"  aliasing suspected in {low:g}-{high:g} Hz: spectra differ by "
                f"{difference:+.1f} dB")
    else:
        worst = max(abs(check.band_difference[check.relevant]), default=0.0)
        say(f"  spectra agree (largest difference {worst:.2f} dB)")
    say(f"wrote {plot_aliasing_check(check, args.out)}")
    if args.json:
        write_json(args.json, check.summary())
    return 1 if check.aliasing_suspected else 0


def register(add: Callable) -> None:
    """Declare ``panto sync``, ``panto preprocess`` and ``panto aliasing-check``."""
    p = add("sync", run_sync, "align a marker track with a 500 Hz run (LED) and merge them")
    p.add_argument("run_folder", help="run folder or dataset file (its 'led' channel)")
    p.add_argument("track_csv", help="track file of 'panto video track' (+ its .json)")
    p.add_argument("--out", required=True, help="folder of the merged dataset (run.csv)")
    p.add_argument("--json", help="also write the synchronisation summary as JSON")
    p.add_argument("--plot", help="also draw the correlation per phase (PNG, thesis Fig. 3.8)")
    p.add_argument("--min-confidence", type=float, default=0.5,
                   help="refuse below this normalised correlation (default 0.5)")
    p.add_argument("--min-peak-ratio", type=float, default=1.5,
                   help="refuse when best / second-best peak is below this (default 1.5)")
    p.add_argument("--min-overlap", type=non_negative_int, default=250,
                   help="camera frames that must overlap the run (default 250 = 5 s)")
    p.add_argument("--min-led-quality", type=float, default=0.0,
                   help="LED bits of lower quality count as unknown (default 0)")
    p.add_argument("--interpolation", choices=("cubic", "linear"), default="cubic",
                   help="upsampling of the positions between frames (default cubic)")

    p = add("preprocess", run_preprocess, "zero-phase low-pass and resample a dataset "
                                          "(thesis 4.2: 500 -> 50 Hz, 20 Hz stop band)")
    p.add_argument("dataset", help="dataset file or run folder")
    p.add_argument("--rate", type=positive_float, default=50.0,
                   help="target rate [Hz] (default 50)")
    p.add_argument("--stopband", type=positive_float, default=20.0, help="stop-band edge [Hz]")
    p.add_argument("--passband", type=positive_float,
                   help="pass-band edge [Hz] (default stopband / 2)")
    p.add_argument("--channels", nargs="*", help="channels to keep (default all)")
    p.add_argument("--out", required=True, help="output dataset (.csv, .parquet or .mat)")

    p = add("aliasing-check", run_aliasing_check,
            "compare two runs at mutually prime rates for aliasing (thesis Fig. 4.1)")
    p.add_argument("run_a", help="first run (folder or dataset file)")
    p.add_argument("run_b", help="second run, at another sample rate")
    p.add_argument("--channel", default="force", help="channel to compare (default force)")
    p.add_argument("--band-width", type=positive_float, default=5.0, help="band width [Hz]")
    p.add_argument("--tolerance-db", type=float, default=6.0,
                   help="largest band difference still counted as agreement [dB]")
    p.add_argument("--out", required=True, help="plot (PNG)")
    p.add_argument("--json", help="also write the verdict and the bands as JSON")
