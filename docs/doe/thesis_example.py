"""The thesis' chapter 5 examples (line and one-mass oscillator), with plots.

    .venv/bin/python docs/doe/thesis_example.py [--end-time 30] [--generations 300] [--out docs/doe]

Writes the line-design plot (Fig. 5.1), the inputs/outputs of the two-sine, offline and online
inputs (Figs. 5.3-5.5), the covariance comparison and the online estimates as PNG, plus
``doe_example.json`` (estimates, RLS P matrices, grey-box m, c, k; eqs. 5.26-5.28, Table 5.1)
and ``doe_example_inputs.csv``. The full example takes about a minute on one core.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from panto.identification.design.thesis_example import run_thesis_example
from panto.identification.design.plots import plot_line_designs, plot_thesis_example
from panto.identification.design.input_design import GeneticOptions
from panto.identification.design.online_design import OnlineOptions


def main(argv: list[str] | None = None) -> list[Path]:
    """Run the examples; returns the files written."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--end-time", type=float, default=30.0, help="experiment length [s]")
    parser.add_argument("--generations", type=int, default=300, help="offline GA generations")
    parser.add_argument("--online-generations", type=int, default=12,
                        help="GA generations per online step")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent, help="output folder")
    args = parser.parse_args(argv)
    example = run_thesis_example(
        end_time=args.end_time, offline_options=GeneticOptions(60, args.generations),
        online_options=OnlineOptions(genetic=GeneticOptions(20, args.online_generations)),
        progress=lambda line: print(line, flush=True))
    files = [plot_line_designs(args.out / "doe_line.png")]
    files += plot_thesis_example(example, args.out) + example.write(args.out)
    for name, ratio in example.variance_ratios().items():
        print(f"{name:8s} Cramer-Rao variance ratio sine/{name}: {ratio.round(1)}")
    for name, evaluation in example.evaluations.items():
        print(f"{name:8s} grey-box m, c, k = {evaluation.grey_box.values.round(4)}, "
              f"variances {evaluation.grey_box.variances}")
    return files


if __name__ == "__main__":
    main()
