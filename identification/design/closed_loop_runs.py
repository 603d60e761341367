"""The runs of the closed-loop experiment (:mod:`panto.identification.design.closed_loop`).

* :class:`VirtualTestBedRunner`: plays an input on the virtual test bed
  (:func:`panto.rig.virtual.run_virtual_profile`) and reads the run back as identification data.
* :class:`JointExperiments` and :func:`join_records`: several records fitted as one
  least-squares problem by :func:`panto.identification.estimation.least_squares.fit_least_squares`,
  each record simulated from its own rest start.
"""
from __future__ import annotations

import math
import shutil
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from panto.identification.data.datasets import pantograph_data
from panto.identification.design.constraints import RigInputConstraints
from panto.identification.design.profiles import sensor_noise_only, write_design_profile
from panto.identification.estimation.base import (IdentificationData, IdentificationError,
                                                  ModelStructure)
from panto.identification.estimation.least_squares import structure_units
from panto.rig.imperfections import RigImperfections
from panto.rig.profiles import load_profile
from panto.rig.virtual import run_virtual_profile


# --- two records as one least-squares problem ---------------------------------------------------


class JointExperiments(ModelStructure):
    """`structure` on several records joined end to end: each is simulated on its own (from its
    own rest start), so the joint residual is the records' residuals side by side.

    Parameters
    ----------
    structure : ModelStructure
    lengths : sequence of int
        Samples per record, in the order of the joined data (:func:`join_records`).
    """

    def __init__(self, structure: ModelStructure, lengths: Sequence[int]) -> None:
        self.structure, self.lengths = structure, tuple(int(n) for n in lengths)
        self.name = structure.name
        self.input_names, self.output_names = structure.input_names, structure.output_names
        self.parameter_names = structure.parameter_names
        self.difference_step = getattr(structure, "difference_step", 1e-6)

    def nominal(self) -> dict[str, float]:
        """The structure's nominal values."""
        return self.structure.nominal()

    def bounds(self) -> dict[str, tuple[float, float]]:
        """The structure's bounds."""
        return self.structure.bounds()

    def units(self) -> dict[str, str]:
        """The structure's parameter units ({} when it has none)."""
        return structure_units(self.structure)

    def simulate(self, parameters: Mapping[str, float], data: IdentificationData) -> np.ndarray:
        """Every record simulated on its own, stacked, shape ``(len(data), n_outputs)``."""
        if sum(self.lengths) != len(data):
            raise IdentificationError(f"{self.name}: records of {list(self.lengths)} samples, "
                                      f"data of {len(data)}")
        pieces, start = [], 0
        for n in self.lengths:
            part = slice(start, start + n)
            pieces.append(self.structure.simulate(parameters, IdentificationData(
                data.time[part], data.inputs[part], data.outputs[part], data.input_names,
                data.output_names, data.units, data.source, data.metadata)))
            start += n
        return np.vstack(pieces)


def join_records(records: Sequence[IdentificationData]) -> tuple[IdentificationData, tuple[int, ...]]:
    """Records of one sample period and the same channels end to end (time continued), and
    their lengths for :class:`JointExperiments`."""
    first = records[0]
    for record in records[1:]:
        if (record.input_names, record.output_names) != (first.input_names, first.output_names) \
                or not math.isclose(record.sample_period, first.sample_period, rel_tol=1e-9):
            raise IdentificationError(f"{record.source}: channels or sample period differ from "
                                      f"{first.source}")
    lengths = tuple(len(r) for r in records)
    time = first.time[0] + np.arange(sum(lengths)) * first.sample_period
    joined = IdentificationData(time, np.vstack([r.inputs for r in records]),
                                np.vstack([r.outputs for r in records]), first.input_names,
                                first.output_names, first.units,
                                " + ".join(r.source for r in records), first.metadata)
    return joined, lengths


# --- the plant ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class VirtualTestBedRunner:
    """A :data:`Runner` on the virtual test bed: the input is written as a replay profile
    (:func:`panto.identification.design.profiles.write_design_profile`) into
    ``folder/<name>/`` and run by :func:`panto.rig.virtual.run_virtual_profile` into
    ``folder/<name>/run``; the run is read at 50 Hz with outputs F_c and y_cb
    (:func:`panto.identification.data.datasets.pantograph_data`).

    Parameters
    ----------
    fmu_path : str or pathlib.Path
        The Pantograph FMU (the plant).
    folder : str or pathlib.Path
        Where the runs go (a run's folder is replaced if it exists).
    parameters : mapping
        The plant's true model parameters (default: the FMU's).
    imperfections : RigImperfections, optional
        Default :func:`panto.identification.design.profiles.sensor_noise_only`.
    seed : int
        Noise seed; each run's noise is seeded by it and the run's name (CRC-32), so two runs
        of one loop have independent noise and a loop is reproducible.
    position_latency : float
        How late [s] the drive reports the slider (the fit advances the motor position by it).
    """

    fmu_path: str | Path
    folder: str | Path
    parameters: Mapping[str, float] = field(default_factory=dict)
    imperfections: RigImperfections | None = None
    seed: int = 0
    position_latency: float = 0.005

    def __call__(self, name: str, motor: np.ndarray, demand: np.ndarray,
                 constraints: RigInputConstraints) -> IdentificationData:
        """Play `motor`, `demand` on the bed and read the run back (class notes)."""
        folder = Path(self.folder) / name
        shutil.rmtree(folder, ignore_errors=True)
        profile, _ = write_design_profile(motor, demand, constraints, folder, name=name,
                                          notes="closed-loop DoE run (panto doe --closed-loop)")
        run_virtual_profile(load_profile(profile), fmu_path=self.fmu_path, folder=folder / "run",
                            imperfections=self.imperfections or sensor_noise_only(),
                            parameters=dict(self.parameters) or None,
                            seed=self.seed + zlib.crc32(name.encode()) % 100_000)
        return pantograph_data(folder / "run", outputs=("F_c", "y_cb"),
                               position_latency=self.position_latency)


__all__ = ["VirtualTestBedRunner", "JointExperiments", "join_records"]
