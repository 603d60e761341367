"""The virtual test bed assembled: drive emulator + plant on a virtual CAN bus, run in lock step.

:func:`run_virtual_profile` is what ``panto rig run PROFILE`` does without hardware: the unchanged
driver and run loop of :mod:`panto.rig.session` talk real CAN frames (python-can's ``virtual``
interface) to :class:`panto.rig.drive_emulator.DriveEmulator`, whose slider drives
:class:`panto.rig.testbed.VirtualTestBed` (the pantograph FMU and the rig's imperfections). A
:class:`panto.rig.clock.SimulatedClock` steps the emulator once per cycle, so a run takes as long as
its computation, not its duration, and is exactly reproducible. The run folder also receives
``truth.csv``: what really happened (true bar height, contact force, marker positions, LED).
"""
from __future__ import annotations

import itertools
import os
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable, Mapping

import can

from panto.rig.clock import SimulatedClock
from panto.rig.drive import LinearMotorDriver
from panto.rig.drive_emulator import DriveEmulator, DriveParameters
from panto.rig.imperfections import RigImperfections
from panto.rig.profiles import Profile
from panto.rig.session import RunOptions, RunResult, run_profile
from panto.rig.testbed import VirtualTestBed

_channels = itertools.count()
#: File in a virtual run's folder with the plant's hidden quantities at 500 Hz (marker positions,
#: true contact force, bellow pressure, LED); for the camera renderer and tests, never the diagnosis.
TRUTH_FILE = "truth.csv"
#: How late the recorded ``motor_position`` is [s]: the drive's reply to a SYNC (one 4 ms stream
#: period) held for two 500 Hz samples (half a period on average). Measured against truth.csv:
#: 2 samples late on even, 3 on odd samples. Recorded in each run's rig set-up.
POSITION_LATENCY = 0.005


def run_virtual_profile(profile: Profile, *, fmu_path: str | Path, folder: str | Path,
                        imperfections: RigImperfections | None = None,
                        parameters: Mapping[str, float] | None = None, seed: int = 0,
                        drive: Mapping[str, Any] | None = None,
                        options: RunOptions | None = None,
                        progress: Callable[[str], None] | None = None) -> RunResult:
    """Run `profile` on the virtual test bed and record it into `folder`.

    Parameters
    ----------
    profile : Profile
    fmu_path : str or pathlib.Path
        The pantograph FMU used as the plant (``Pantograph.fmu``).
    folder : str or pathlib.Path
        Run folder (refused if it already holds a run).
    imperfections : RigImperfections, optional
        Default: the rig as the thesis describes it (all effects on).
    parameters : mapping, optional
        The "true" pantograph's model parameters.
    seed : int
        Seed of the sensor noise.
    drive : mapping, optional
        Overrides of :class:`panto.rig.drive_emulator.DriveParameters` (e.g. bandwidth).
    options : RunOptions, optional
        Run options; the source is set to ``"emulator"`` and the truth is filled in.
    progress : callable, optional

    Returns
    -------
    RunResult
    """
    channel = f"panto-virtual-{os.getpid()}-{next(_channels)}"
    clock = SimulatedClock()
    drive_parameters = replace(DriveParameters(), **dict(drive or {}))
    with VirtualTestBed(fmu_path, parameters=parameters, imperfections=imperfections,
                        seed=seed, sample_period=1.0 / profile.sample_rate) as bed, \
            can.Bus(interface="virtual", channel=channel) as master_bus, \
            can.Bus(interface="virtual", channel=channel) as drive_bus:
        bed.initialise(slider_position=0.0, pressure=profile.pressure.offset)
        emulator = DriveEmulator(drive_bus, clock=clock, parameters=drive_parameters,
                                 listener=bed.on_slider_sample, load_force=bed.load_force,
                                 initial_position=0.0)
        clock.add_hook(emulator.process_pending)
        driver = LinearMotorDriver(master_bus, clock=clock,
                                   position_limits=(profile.limits.motor_min,
                                                    profile.limits.motor_max))
        truth = {**bed.truth_record(), "drive": plain_drive_parameters(drive_parameters)}
        run_options = replace(emulator_run_options(options, bed, truth), background_writer=False)
        origin = 0.0
        try:
            result = run_profile(profile, driver=driver, io=bed, clock=clock, folder=folder,
                                 options=run_options, progress=progress)
            origin = result.clock_origin
            return result
        finally:  # the truth beside the run, also when it stopped early
            if Path(folder).is_dir() and not (Path(folder) / TRUTH_FILE).exists():
                bed.truth_dataset(origin).write(Path(folder) / TRUTH_FILE)


def emulator_run_options(options: RunOptions | None, bed: VirtualTestBed,
                         truth: Mapping[str, Any]) -> RunOptions:
    """`options` for a run on the emulator: its source, its `truth`, and the bed's rig set-up
    (motor zero height, :data:`POSITION_LATENCY`) under the set-up already given."""
    options = options or RunOptions()
    return replace(options, source="emulator", truth=truth,
                   rig_setup={"motor_zero_height": bed.motor_zero_height,
                              "position_latency": POSITION_LATENCY, **dict(options.rig_setup)})


def plain_drive_parameters(parameters: DriveParameters) -> dict[str, Any]:
    """Drive parameters as plain JSON values (for a run's truth record)."""
    from dataclasses import asdict

    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(parameters).items()}
