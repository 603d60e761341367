"""A profile as a person checks it before a run: the demands, the conditioned command, the LED."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from panto.rig.conditioning import MotorConditioner
from panto.rig.profiles import Profile, load_profile, render_profile


def conditioned_command(profile: Profile) -> tuple[np.ndarray, np.ndarray]:
    """The 250 Hz command the run loop would stream (from rest at the offset): (time, command)."""
    rendered = render_profile(profile)
    chain = MotorConditioner(profile.conditioning, profile.limits.motor_limits(),
                             initial_position=profile.motor.offset)
    stream = slice(None, None, 2)  # every second 500 Hz sample, as the run loop does
    result = chain.apply(rendered.motor_offset[stream], rendered.motor_dynamic[stream])
    return rendered.time[stream], result.command


def preview_profile(path: str | Path | Profile, *, out: str | Path) -> list[Path]:
    """Write ``<name>.csv`` (500 Hz demands, LED) and ``<name>.png`` (plot) into `out`."""
    import pandas as pd
    from matplotlib.figure import Figure

    profile = path if isinstance(path, Profile) else load_profile(path)
    rendered = render_profile(profile)
    stream_time, command = conditioned_command(profile)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    table = pd.DataFrame({"time [s]": rendered.time, "motor_demand [m]": rendered.motor_demand,
                          "pressure_demand [bar]": rendered.pressure_demand,
                          "led [1]": rendered.led})
    csv_path = out / f"{profile.name}.csv"
    table.to_csv(csv_path, index=False)
    fig = Figure(figsize=(11, 7))
    axes = fig.subplots(3, 1, sharex=True, gridspec_kw={"height_ratios": [3, 2, 1]})
    axes[0].plot(rendered.time, rendered.motor_demand * 1e3, lw=0.8, label="demand")
    axes[0].plot(stream_time, command * 1e3, lw=0.8, label="command (conditioned, 250 Hz)")
    for limit in (profile.limits.motor_min, profile.limits.motor_max):
        axes[0].axhline(limit * 1e3, color="0.6", ls="--", lw=0.8)
    axes[0].set_ylabel("linear motor [mm]")
    axes[0].legend(loc="upper right")
    axes[1].plot(rendered.time, rendered.pressure_demand, lw=0.8, color="C2")
    axes[1].set_ylabel("pressure demand [bar]")
    axes[2].step(rendered.time, rendered.led, where="post", lw=0.6, color="C3")
    axes[2].set_ylabel("LED")
    axes[2].set_xlabel("time [s]")
    fig.suptitle(f"profile {profile.name}: {profile.duration:g} s at {profile.sample_rate:g} Hz, "
                 f"seed {profile.seed}")
    fig.tight_layout()
    fig.set_layout_engine(None)  # laid out: savefig draws once
    png_path = out / f"{profile.name}.png"
    fig.savefig(png_path, dpi=110)
    return [csv_path, png_path]
