"""Designed pantograph experiments as rig profiles, and their proof on the virtual test bed.

The conventional input a design is compared with (the APRBS training profile as the rig plays it)
is :func:`panto.identification.design.constraints.conventional_inputs`.

* :func:`write_design_profile`: a designed motor position and pressure demand as a rig profile
  (``rig/profiles`` JSON format, :mod:`panto.rig.profiles`) that replays a CSV table (signal kind
  ``replay``, linear interpolation, not periodic). The conditioning keeps its limiter (which
  never acts: the design moves less than ``motor_max_step`` per stream sample) and has no
  reference filter and no fade-in (the design starts at rest, and a filter would change what
  was designed). The written profile is read back with :func:`panto.rig.profiles.load_profile`
  (which checks every demand against the limits) and rendered with
  :func:`panto.rig.profiles.render_profile`; the rendered demand must equal the design.
* :func:`write_design_report` (plots by :func:`panto.identification.design.plots.plot_design`):
  covariance table (CSV), summary (JSON) and the plots (designed and conventional inputs,
  predicted std per parameter).
"""
from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from panto.build_fmu.project import project_fmu
from panto.fmu_src.models import default_parameters
from panto.fmu_src.response import TimeResponse
from panto.identification.data.datasets import pantograph_data
from panto.identification.design.constraints import RigInputConstraints, profile_path
from panto.identification.design.pantograph import PantographDesign
from panto.identification.design.pantograph_sensitivity import LinearisedPantograph
from panto.identification.design.plots import plot_design
from panto.identification.estimation.least_squares import fit_least_squares
from panto.rig.imperfections import RigImperfections
from panto.rig.profiles import ProfileError, load_profile, render_profile
from panto.rig.virtual import run_virtual_profile


def design_profile_dict(name: str, table: str, duration: float,
                        constraints: RigInputConstraints, notes: str) -> dict[str, Any]:
    """The profile JSON object replaying columns of `table` (a CSV beside the profile)."""
    c = constraints
    replay = {"kind": "replay", "path": table, "periodic": False, "interpolation": "linear"}
    return {
        "format": "panto-rig-profile", "version": 1, "name": name, "notes": notes,
        "duration": duration, "sample_rate": 500.0, "seed": 0,
        "limits": {"motor_min": c.motor_min, "motor_max": c.motor_max, "motor_max_step": 0.005,
                   "pressure_min": c.pressure_min, "pressure_max": c.pressure_max,
                   "safe_pressure": c.pressure_start},
        "conditioning": {"reference_filter": False, "blend_time_constant": 0.0, "limiter": True,
                         "sample_rate": 250.0},
        "motor": {"offset": 0.0, "signals": [replay | {"column": "motor_position"}]},
        "pressure": {"offset": c.pressure_start,
                     "signals": [replay | {"column": "pressure_change"}]},
    }


def write_design_profile(motor: np.ndarray, demand: np.ndarray, constraints: RigInputConstraints,
                         folder: str | Path, *, name: str = "designed",
                         notes: str = "") -> tuple[Path, Path]:
    """Write ``<name>.json`` (the profile) and ``<name>.csv`` (its table) into `folder`.

    Parameters
    ----------
    motor, demand : ndarray, shape (N,)
        Motor position about mid-stroke [m] and pressure demand [bar] at the design period.
    constraints : RigInputConstraints
        Limits written into the profile; its start pressure is the pressure offset.
    folder : str or pathlib.Path
    name : str
    notes : str

    Returns
    -------
    (profile path, table path)

    Raises
    ------
    panto.rig.profiles.ProfileError
        If the written profile does not load (a demand outside the limits) or its rendering
        differs from the design by more than 1e-9.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    motor, demand = np.asarray(motor, float), np.asarray(demand, float)
    time = np.arange(len(motor)) * constraints.sample_period
    table = folder / f"{name}.csv"
    TimeResponse(time, {"motor_position": motor, "pressure_change": demand -
                        constraints.pressure_start, "pressure_demand": demand},
                 units={"motor_position": "m", "pressure_change": "bar",
                        "pressure_demand": "bar"}).to_csv(table, write_metadata=False)
    duration = round(len(motor) * constraints.sample_period, 9)
    path = folder / f"{name}.json"
    path.write_text(json.dumps(design_profile_dict(name, table.name, duration, constraints,
                                                   notes), indent=2) + "\n", encoding="utf-8")
    rendered = render_profile(load_profile(path))
    every = int(round(constraints.sample_period * 500.0))
    error = max(np.max(np.abs(rendered.motor_demand[::every] - motor)),
                np.max(np.abs(rendered.pressure_demand[::every] - demand)))
    if not error <= 1e-9:
        raise ProfileError(f"{path}: the rendered profile differs from the design by {error:.3g}")
    return path, table


def write_design_report(design: PantographDesign, folder: str | Path, *,
                        name: str = "designed") -> dict[str, Path]:
    """Profile, covariance table (CSV), summary (JSON) and plots of a design into `folder`."""
    folder = Path(folder)
    notes = (f"D-optimal design ({design.criterion}) for {design.structure}, free "
             f"{list(design.parameter_names)}; made by panto doe (thesis section 5.5). Motor "
             "positions relative to mid-stroke; pressure = offset + pressure_change.")
    profile, table = write_design_profile(design.motor_position, design.pressure_demand,
                                          design.constraints, folder, name=name, notes=notes)
    covariance = folder / "predicted_covariance.csv"
    rows = design.covariance_table()
    lines = [",".join(rows[0])] + [",".join(f"{v}" for v in row.values()) for row in rows]
    covariance.write_text("\n".join(lines) + "\n", encoding="utf-8")
    summary = folder / "doe_summary.json"
    summary.write_text(json.dumps(design.summary(), indent=2, default=float) + "\n",
                       encoding="utf-8")
    return {"profile": profile, "table": table, "covariance": covariance, "summary": summary,
            **plot_design(design, folder)}


# --- proof on the virtual test bed -----------------------------------------------------------


def sensor_noise_only():
    """:class:`panto.rig.imperfections.RigImperfections` with every effect off except the sensors'
    white noise (force and lasers at the rig's magnitudes), so that a comparison of two inputs
    on the virtual test bed is about information, not about model errors."""
    rig = RigImperfections()
    return replace(RigImperfections.none(), force_noise=rig.force_noise,
                   laser_noise=rig.laser_noise)


@dataclass(frozen=True)
class RunEstimate:
    """Least-squares estimates of the free parameters from one virtual rig run.

    Parameters
    ----------
    name : str
        ``"designed"`` or ``"conventional"``.
    folder : pathlib.Path
        The recorded run.
    estimates, std : mapping
        Estimate and reported standard deviation per free parameter.
    covariance : ndarray, shape (n_free, n_free)
        Reported covariance :math:`\\hat\\sigma^2 (J^T J)^{-1}` (physical units).
    truth : mapping
        The plant's value per free parameter.
    within : mapping
        Whether the truth lies in the estimate's 95 % interval (:math:`\\pm 1.96\\,\\sigma`).
    fit, residual_std : mapping
        Fit [%] and residual standard deviation per output.
    """

    name: str
    folder: Path
    estimates: dict[str, float]
    std: dict[str, float]
    covariance: np.ndarray
    truth: dict[str, float]
    within: dict[str, bool]
    fit: dict[str, float]
    residual_std: dict[str, float]


def identify_run(name: str, folder: Path, structure, free: Sequence[str],
                 initial: Mapping[str, float], truth: Mapping[str, float], *,
                 position_latency: float | None = 0.005) -> RunEstimate:
    """Fit `free` of `structure` to the run in `folder` (50 Hz, outputs F_c and y_cb) by
    :func:`panto.identification.estimation.least_squares.fit_least_squares` from `initial`."""
    data = pantograph_data(folder, outputs=("F_c", "y_cb"), position_latency=position_latency)
    result = fit_least_squares(structure, data, free=free, initial=initial)
    std = {n: float(result.std[n]) for n in free}
    estimates = {n: float(result.parameters[n]) for n in free}
    within = {n: bool(abs(estimates[n] - truth[n]) <= 1.96 * std[n]) for n in free}
    return RunEstimate(name, Path(folder), estimates, std, np.asarray(result.covariance),
                       {n: float(truth[n]) for n in free}, within, dict(result.fit),
                       {k: float(v) for k, v in result.details["residual_std"].items()})


@dataclass(frozen=True)
class VirtualComparison:
    """Designed vs conventional input, each run on the virtual test bed and identified.

    ``det_ratio_per_parameter`` is :math:`(\\det C_\\mathrm{conv} / \\det C_\\mathrm{des})^{1/n}`
    of the *reported* covariances (> 1: the designed run is more informative), ``std_ratio``
    the conventional over the designed standard deviation per parameter.
    """

    structure: str
    free: tuple[str, ...]
    duration: float
    designed: RunEstimate
    conventional: RunEstimate
    predicted_det_ratio_per_parameter: float

    @property
    def det_ratio_per_parameter(self) -> float:
        _, designed = np.linalg.slogdet(self.designed.covariance)
        _, conventional = np.linalg.slogdet(self.conventional.covariance)
        return float(np.exp((conventional - designed) / len(self.free)))

    @property
    def std_ratio(self) -> dict[str, float]:
        return {n: self.conventional.std[n] / self.designed.std[n] for n in self.free}

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary."""
        runs = {r.name: {"estimates": r.estimates, "std": r.std, "truth": r.truth,
                         "within_95": r.within, "fit_percent": r.fit,
                         "residual_std": r.residual_std, "folder": str(r.folder)}
                for r in (self.designed, self.conventional)}
        return {"structure": self.structure, "free": list(self.free), "duration_s": self.duration,
                "det_ratio_per_parameter": self.det_ratio_per_parameter,
                "predicted_det_ratio_per_parameter": self.predicted_det_ratio_per_parameter,
                "std_ratio_conventional_to_designed": self.std_ratio, "runs": runs}

    def markdown(self) -> str:
        """A table per parameter: truth, estimates +- std (designed, APRBS), std ratio."""
        d, c = self.designed, self.conventional
        lines = [f"{self.structure}, {self.duration:g} s each, free {list(self.free)}", "",
                 "| parameter | truth | designed | APRBS | std ratio APRBS/designed |",
                 "|---|---|---|---|---|"]
        for n in self.free:
            lines.append(f"| {n} | {d.truth[n]:.5g} | {d.estimates[n]:.5g} +- {d.std[n]:.3g}"
                         f"{'' if d.within[n] else ' (truth outside 95 %)'} | "
                         f"{c.estimates[n]:.5g} +- {c.std[n]:.3g}"
                         f"{'' if c.within[n] else ' (truth outside 95 %)'} | "
                         f"{self.std_ratio[n]:.2f} |")
        lines += ["", f"Reported covariance, det ratio per parameter APRBS/designed: "
                  f"{self.det_ratio_per_parameter:.2f} (predicted by the design: "
                  f"{self.predicted_det_ratio_per_parameter:.2f}).",
                  f"Fit [%] designed {_rounded(d.fit)}, APRBS {_rounded(c.fit)}; residual std "
                  f"designed {_rounded(d.residual_std, 4)}, APRBS {_rounded(c.residual_std, 4)}."]
        return "\n".join(lines) + "\n"


def _rounded(values: Mapping[str, float], digits: int = 2) -> dict[str, float]:
    return {k: round(float(v), digits) if abs(v) >= 1e-2 else float(f"{v:.3g}")
            for k, v in values.items()}


@dataclass(frozen=True)
class VirtualRigOptions:
    """How :func:`compare_on_virtual_rig` runs the virtual test bed and fits its runs."""

    fmu_path: str | Path | None = None
    """The Pantograph FMU (default: the project's)."""
    imperfections: RigImperfections | None = None
    """The bed's imperfections (default :func:`sensor_noise_only`)."""
    seed: int = 0
    """Seed of the bed's random imperfections (noise)."""
    position_latency: float | None = 0.005
    """How late [s] the drive reports the slider; the fits advance ``motor_position`` by it."""
    start_factor: float = 1.1
    """The fits start from the true values times this factor."""


def compare_on_virtual_rig(design: PantographDesign, folder: str | Path, *,
                           options: VirtualRigOptions = VirtualRigOptions(),
                           progress: Callable[[str], None] | None = None) -> VirtualComparison:
    """Run the designed input and the APRBS profile of equal length on the virtual test bed and
    identify the design's free parameters from each: the design's promise is that its run gives
    tighter parameter estimates than the APRBS run of equal length.

    The plant is the Pantograph FMU at ``design.parameters`` (for ``physical-linear``: its
    linearisation is the design's model), with :func:`sensor_noise_only` unless
    `imperfections` is given. Both runs are fitted with the design's structure
    (:meth:`LinearisedPantograph.structure_for`) from the design's parameter values, at 50 Hz,
    the motor position advanced by ``options.position_latency`` (the drive's report latency),
    starting from the true values times ``options.start_factor``.
    """
    fmu_path, imperfections = options.fmu_path, options.imperfections
    if design.structure != "physical-linear":
        raise ValueError(f"compare_on_virtual_rig needs a 'physical-linear' design (the plant is "
                         f"the pantograph FMU, whose parameters are the truth), got "
                         f"{design.structure!r}")
    if fmu_path is None:
        fmu_path = project_fmu("Pantograph")
    folder = Path(folder)
    duration = round(len(design.time) * design.constraints.sample_period, 9)
    profile, _ = write_design_profile(design.motor_position, design.pressure_demand,
                                      design.constraints, folder, name="designed")
    profiles = {"designed": load_profile(profile),
                "conventional": replace(load_profile(profile_path("aprbs_training")),
                                        duration=duration)}
    structure = LinearisedPantograph.structure_for(design.structure)
    plant = {k: v for k, v in design.parameters.items() if k in _fmu_parameter_names()}
    truth = dict(design.parameters)
    initial = truth | {n: options.start_factor * truth[n] for n in design.parameter_names}
    runs = {}
    for name, rig_profile in profiles.items():
        if progress:
            progress(f"virtual test bed: running the {name} input ({duration:g} s)")
        run_virtual_profile(rig_profile, fmu_path=fmu_path, folder=folder / name,
                            imperfections=imperfections or sensor_noise_only(),
                            parameters=plant, seed=options.seed)
        if progress:
            progress(f"identifying {list(design.parameter_names)} from the {name} run")
        runs[name] = identify_run(name, folder / name, structure, design.parameter_names,
                                  initial, truth, position_latency=options.position_latency)
    return VirtualComparison(design.structure, design.parameter_names, duration,
                             runs["designed"], runs["conventional"],
                             float(design.summary()["det_ratio_per_parameter"]))


def _fmu_parameter_names() -> set[str]:
    return set(default_parameters("Pantograph").names)
