"""Designed pantograph experiments as rig profiles, and the conventional input they beat.

* :func:`conventional_inputs`: the APRBS training profile (thesis 4.2) of equal length as the rig
  plays it (conditioning chain), sampled at the design period: the comparison input.
* :func:`write_design_profile`: a designed motor position and pressure demand as a rig profile
  (``rig/profiles`` JSON format, :mod:`rig.profiles`) that replays a CSV table (signal kind
  ``replay``, linear interpolation, not periodic). The conditioning keeps its limiter (which
  never acts: the design moves less than ``motor_max_step`` per stream sample) and has no
  reference filter and no fade-in (the design starts at rest, and a filter would change what
  was designed). The written profile is read back with :func:`rig.profiles.load_profile`
  (which checks every demand against the limits) and rendered with
  :func:`rig.profiles.render_profile`; the rendered demand must equal the design.
* :func:`write_design_report` / :func:`plot_design`: covariance table (CSV), summary (JSON) and
  the plots (designed and conventional inputs, predicted std per parameter).
"""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from identification.pantograph_design import PantographDesign, RigInputConstraints


def profile_path(profile: str | Path) -> Path:
    """A profile file: a path, or the name of one of the rig's profiles (``aprbs_training``)."""
    path = Path(profile)
    if path.suffix == ".json" or path.exists():
        return path
    import rig

    return Path(rig.__file__).parent / "profiles" / f"{profile}.json"


def conventional_inputs(n_samples: int, constraints: RigInputConstraints, *,
                        profile: str = "aprbs_training",
                        seed: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The APRBS training profile of equal length as the rig plays it, at the design period.

    The profile is rendered for ``n_samples`` design samples, the motor demand conditioned
    (:class:`rig.conditioning.MotorConditioner`: its 4 Hz reference filter, fade-in and limiter,
    at the 250 Hz stream) and both channels are sampled at the design period. Returns motor
    positions [m] and pressure demands [bar].
    """
    from rig.conditioning import MotorConditioner
    from rig.profiles import load_profile, render_profile

    rig = load_profile(profile_path(profile))
    rig = replace(rig, duration=n_samples * constraints.sample_period,
                  seed=rig.seed if seed is None else seed)
    rendered = render_profile(rig)
    every = int(round(rig.sample_rate / rig.conditioning.sample_rate))
    stream = slice(None, None, every)
    chain = MotorConditioner(rig.conditioning, rig.limits.motor_limits(), initial_position=0.0)
    command = chain.apply(rendered.motor_offset[stream], rendered.motor_dynamic[stream]).command
    step = int(round(constraints.sample_period * rig.conditioning.sample_rate))
    pick = int(round(constraints.sample_period * rig.sample_rate))
    return command[::step][:n_samples], rendered.pressure_demand[::pick][:n_samples]


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
    rig.profiles.ProfileError
        If the written profile does not load (a demand outside the limits) or its rendering
        differs from the design by more than 1e-9.
    """
    from fmu_src.response import TimeResponse
    from rig.profiles import ProfileError, load_profile, render_profile

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


def plot_design(design: PantographDesign, folder: str | Path) -> dict[str, Path]:
    """``doe_inputs.png`` (both inputs, designed and conventional, predicted outputs) and
    ``doe_std.png`` (predicted relative std per parameter, designed vs conventional)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder = Path(folder)
    t = design.time
    fig, axes = plt.subplots(2 + len(design.output_names), 1, figsize=(10, 8), sharex=True)
    axes[0].plot(t, 1e3 * design.conventional_motor_position, lw=0.8, label="APRBS (conditioned)")
    axes[0].plot(t, 1e3 * design.motor_position, lw=0.8, label="designed")
    axes[0].set_ylabel("motor [mm]")
    axes[1].plot(t, design.conventional_pressure_demand, lw=0.8, label="APRBS demand")
    axes[1].plot(t, design.pressure_demand, lw=0.8, label="designed demand")
    axes[1].plot(t, design.pressure, lw=0.8, label="designed, measured (lag)")
    axes[1].set_ylabel("pressure [bar]")
    for axis, j in zip(axes[2:], range(len(design.output_names))):
        axis.plot(t, design.conventional_outputs[:, j], lw=0.8, label="APRBS")
        axis.plot(t, design.outputs[:, j], lw=0.8, label="designed")
        axis.set_ylabel(design.output_names[j])
    for axis in axes:
        axis.legend(loc="upper right", fontsize=7)
        axis.grid(True, alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{design.structure}: {design.criterion}-optimal inputs vs APRBS")
    fig.tight_layout()
    inputs = folder / "doe_inputs.png"
    fig.savefig(inputs, dpi=120)
    plt.close(fig)
    scale = np.array([abs(design.parameters[n]) or 1.0 for n in design.parameter_names])
    fig, axis = plt.subplots(figsize=(8, 4))
    x = np.arange(len(scale))
    axis.bar(x - 0.2, 100 * design.conventional_std / scale, 0.4, label="APRBS")
    axis.bar(x + 0.2, 100 * design.std / scale, 0.4, label="designed")
    axis.set_xticks(x, design.parameter_names, rotation=45)
    axis.set_yscale("log")
    axis.set_ylabel("predicted std [% of value]")
    axis.legend()
    axis.grid(True, axis="y", alpha=0.3)
    fig.tight_layout()
    std = folder / "doe_std.png"
    fig.savefig(std, dpi=120)
    plt.close(fig)
    return {"inputs_plot": inputs, "std_plot": std}

