"""One rig run: the 500 Hz loop that plays a profile through the linear motor and the bellow.

Per 2 ms sample (thesis section 3.1, the real-time unit's job): read the analogue inputs (force,
pressure, lasers), step the PI pressure controller and write the valve voltage, write the LED bit;
every second sample (250 Hz) condition the motor demand (Fig. 3.5/3.6), stream it to the drive
and read the drive's replies; record one row. The loop keeps absolute deadlines
(:class:`panto.rig.clock.Ticker`), so a late cycle does not shift the run.

At the end of the profile the stream stops and the drive is switched off. A fault (drive error,
missing replies, bus error) ends the excitation safely: the motor stream
stops, the bellow is driven back to the profile's safe pressure (recorded as well), the run is
marked ``aborted: <code> <meaning> at t = ... s`` and everything recorded is on disk.

The same loop runs against the real rig and the virtual test bed: what differs is the bus, the
clock and the :class:`RigIO` behind the analogue channels.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Protocol

from panto.rig.clock import Clock, SimulatedClock, Ticker
from panto.rig.conditioning import MotorConditioner
from panto.rig.dataset import RunMetadata
from panto.rig.drive import DriveFault, LinearMotorDriver, RigError
from panto.rig.pressure import PressureController, PressureControllerOptions
from panto.rig.profiles import Profile, ProfileStream, profile_to_dict
from panto.rig.recorder import Recorder

#: Channels of a rig run, in column order.
RUN_CHANNELS = ("motor_demand", "motor_command", "motor_position", "motor_current", "force",
                "pressure_demand", "pressure", "valve_voltage", "laser_1", "laser_2", "led",
                "dynamic_gain", "drive_state", "drive_error")


class RigIO(Protocol):
    """The rig's analogue and digital I/O besides the drive (a DAQ on the rig, the plant here)."""

    def read_sensors(self, now: float) -> Mapping[str, float]:
        """``force`` [N], ``pressure`` [bar], ``laser_1``, ``laser_2`` [m] sampled at `now`."""

    def write_valve_voltage(self, voltage: float) -> None:
        """Valve control voltage [V]."""

    def write_led(self, bit: int) -> None:
        """Synchronisation LED."""


@dataclass(frozen=True, kw_only=True)
class RunOptions:
    """How a run is executed and stored.

    Parameters
    ----------
    source : str
        ``"rig"`` or ``"emulator"`` (recorded in the metadata).
    formats : tuple of str
        Copies written beside the incremental CSV when the run ends (``"parquet"``, ``"mat"``).
    pressure_controller : PressureControllerOptions
    settle_time : float
        Longest time [s] the bellow is driven to the safe pressure after a fault or at the end.
    settle_tolerance : float
        The bellow counts as safe within this band around the safe pressure [bar].
    notes : str
    truth : mapping
        What generated the data (the emulator fills it; empty on the rig).
    background_writer : bool
        Write the recorder's buffers from a thread (keeps fsync out of the 2 ms cycle).
    rig_setup : mapping
        Known facts of the rig's set-up, recorded in the metadata's ``extra["rig_setup"]``; the
        identification reads ``motor_zero_height`` [m] (bar height at slider position 0, the
        model input ``eta = motor_zero_height + motor_position``).
    """

    source: str = "rig"
    formats: tuple[str, ...] = ("parquet", "mat")
    pressure_controller: PressureControllerOptions = field(default_factory=PressureControllerOptions)
    settle_time: float = 5.0
    settle_tolerance: float = 0.1
    notes: str = ""
    truth: Mapping[str, Any] = field(default_factory=dict)
    background_writer: bool = True
    rig_setup: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class RunResult:
    """Outcome of a run: where it is, how it ended, how well the loop kept time."""

    folder: Path
    status: str
    samples: int
    fault_code: int | None
    fault_meaning: str | None
    late_cycles: int
    lateness_p99: float
    lateness_max: float
    clock_origin: float = math.nan
    """Clock time [s] of the dataset's t = 0 (NaN if the drive never started)."""

    @property
    def success(self) -> bool:
        return self.status == "complete"


class _Loop:
    """State of one run (kept apart from :func:`run_profile` so each phase is a short method)."""

    def __init__(self, profile: Profile, driver: LinearMotorDriver, io: RigIO, clock: Clock,
                 recorder: Recorder, options: RunOptions) -> None:
        self.profile, self.driver, self.io, self.clock = profile, driver, io, clock
        self.recorder, self.options = recorder, options
        self.dt = 1.0 / profile.sample_rate
        self.lateness: list[float] = []
        self.feedback = None
        self.row: dict[str, float] = {}
        self.time = 0.0
        self.clock_origin = math.nan

    def _wait(self) -> Mapping[str, float]:
        self.lateness.append(self.ticker.wait())
        if isinstance(self.clock, SimulatedClock):  # lock step: let the emulator catch up to now
            self.clock.run_hooks()
        return self.io.read_sensors(self.clock.now())

    def _pressure(self, demand: float, sensors: Mapping[str, float]) -> float:
        voltage = self.controller.step(demand, sensors["pressure"])
        self.io.write_valve_voltage(voltage)
        return voltage

    def _record(self, time: float, sensors: Mapping[str, float], **values: float) -> None:
        fb = self.feedback
        self.row.update(values)
        self.row.update(force=sensors["force"], pressure=sensors["pressure"],
                        laser_1=sensors["laser_1"], laser_2=sensors["laser_2"],
                        motor_position=fb.actual_position if fb else math.nan,
                        motor_current=fb.demand_current if fb else math.nan,
                        drive_state=float(fb.main_state) if fb else math.nan,
                        drive_error=float(fb.error_code) if fb else math.nan)
        self.recorder.append(time, self.row)
        self.time = time

    def start(self) -> None:
        self.feedback = self.driver.start()
        position = self.feedback.actual_position
        self.conditioner = MotorConditioner(self.profile.conditioning,
                                            self.profile.limits.motor_limits(),
                                            initial_position=position)
        self.ticker = Ticker(self.clock, self.dt)  # deadlines from the end of the start-up
        self.clock_origin = self.clock.now() + self.dt  # clock time of the run's t = 0
        sensors = self.io.read_sensors(self.clock.now())
        opts = self.options.pressure_controller
        self.controller = PressureController(opts, initial_voltage=_holding_voltage(sensors))
        self.row = dict(motor_demand=position, motor_command=position, dynamic_gain=0.0, led=0.0,
                        pressure_demand=sensors["pressure"], valve_voltage=self.controller.voltage)

    def excite(self, progress: Callable[[str], None] | None) -> None:
        stream, every = ProfileStream(self.profile), int(round(self.profile.sample_rate))
        for sample in stream:
            sensors = self._wait()
            voltage = self._pressure(sample.pressure_demand, sensors)
            self.io.write_led(sample.led)
            demand = sample.motor_offset + sample.motor_dynamic
            if sample.index % 2 == 0:  # 250 Hz stream
                self.feedback = self.driver.check()
                conditioned = self.conditioner.step(sample.motor_offset, sample.motor_dynamic)
                self.driver.stream(conditioned.command)
                self.row["motor_command"] = conditioned.command
                self.row["dynamic_gain"] = self.conditioner.gain
            self._record(sample.time, sensors, motor_demand=demand, valve_voltage=voltage,
                         pressure_demand=sample.pressure_demand, led=float(sample.led))
            if progress and sample.index % (10 * every) == 0 and sample.index:
                progress(f"  t = {sample.time:6.1f} s of {self.profile.duration:g} s")

    def settle(self) -> bool:
        """Drive the bellow to the safe pressure (motor stream stopped); True when reached."""
        safe = self.profile.limits.safe_pressure
        self.io.write_led(0)
        for _ in range(int(self.options.settle_time / self.dt)):
            sensors = self._wait()
            voltage = self._pressure(safe, sensors)
            self._record(self.time + self.dt, sensors, pressure_demand=safe, valve_voltage=voltage,
                         led=0.0)
            if abs(sensors["pressure"] - safe) < self.options.settle_tolerance:
                return True
        return False

    def stop_drive(self) -> None:
        try:
            self.driver.stop_streaming()
            self.feedback = self.driver.disable() or self.feedback
        except RigError:
            pass  # the drive is already faulted or gone; the fault has been recorded


def _holding_voltage(sensors: Mapping[str, float]) -> float:
    """Start the PI loop with the voltage that holds the present pressure (bumpless start)."""
    from panto.rig.pneumatics import ValveParameters

    return float(ValveParameters().voltage_for(sensors["pressure"]))


def run_profile(profile: Profile, *, driver: LinearMotorDriver, io: RigIO, clock: Clock,
                folder: str | Path, options: RunOptions | None = None,
                progress: Callable[[str], None] | None = None) -> RunResult:
    """Play `profile` on the rig (or the virtual test bed) and record it into `folder`.

    Parameters
    ----------
    profile : Profile
        Both channels, sample rate, duration, limits (see :mod:`panto.rig.profiles`).
    driver : LinearMotorDriver
        The linear motor on its bus (not yet started).
    io : RigIO
        Analogue inputs, valve output and LED.
    clock : Clock
        :class:`panto.rig.clock.RealClock` on the rig; a :class:`panto.rig.clock.SimulatedClock` whose hooks
        step the emulator for a lock-step virtual run.
    folder : str or pathlib.Path
        Run folder (must not hold a run: a recorder never overwrites).
    options : RunOptions, optional
    progress : callable, optional
        Receives a line every 10 s of run time.

    Returns
    -------
    RunResult
        ``status`` is ``"complete"`` or ``"aborted: ..."``; the dataset is in `folder` either way.
    """
    options = options or RunOptions()
    recorder = _recorder(profile, folder, options)
    loop = _Loop(profile, driver, io, clock, recorder, options)
    fault: RigError | None = None
    try:
        loop.start()
        if progress:
            progress(f"drive in operation at {loop.feedback.actual_position * 1e3:.2f} mm; "
                     f"running {profile.name} for {profile.duration:g} s")
        loop.excite(progress)
    except RigError as error:
        fault = error
    except BaseException as error:  # keep what is recorded, mark why it stopped, re-raise
        recorder.abort(f"{type(error).__name__}: {error}", at=loop.time)
        loop.stop_drive()
        error.add_note(f"the run up to t = {loop.time:.3f} s is recorded in {folder}")
        raise
    loop.stop_drive()
    status, status_path = _end_recording(recorder, loop, fault, profile, options)
    if progress:
        progress(f"run {status}; data in {status_path}")
    return _result(Path(folder), status, recorder.rows_written, fault, loop.lateness, loop.dt,
                   loop.clock_origin)


def _recorder(profile: Profile, folder: str | Path, options: RunOptions) -> Recorder:
    """The run's recorder, its metadata filled from the profile and the options."""
    metadata = RunMetadata(sample_rate=profile.sample_rate, source=options.source,
                           seed=profile.seed, profile=profile_to_dict(profile),
                           notes=options.notes or profile.notes, truth=dict(options.truth),
                           extra={"rig_setup": dict(options.rig_setup)} if options.rig_setup else {})
    return Recorder(folder, channels=RUN_CHANNELS, metadata=metadata,
                    background=options.background_writer)


def _end_recording(recorder: Recorder, loop: _Loop, fault: RigError | None, profile: Profile,
                   options: RunOptions) -> tuple[str, Path]:
    """Finish the recording (after a fault: settle the bellow, then abort it with the reason);
    return the status and the path the recorder wrote it to."""
    reached = loop.settle() if fault is not None and loop.lateness else True
    if fault is None:
        return "complete", recorder.finish(formats=options.formats)
    reason = _fault_reason(fault, loop.time, reached, profile.limits.safe_pressure)
    return f"aborted: {reason}", recorder.abort(reason, at=loop.time)


def _fault_reason(fault: RigError, time: float, reached: bool, safe: float) -> str:
    code = getattr(fault, "code", None)
    text = f"drive error 0x{code:02X}: {fault.meaning}" if isinstance(fault, DriveFault) \
        else f"{type(fault).__name__}: {fault}"
    bellow = "bellow at safe pressure" if reached else f"bellow NOT yet at {safe} bar"
    return f"{text} at t = {time:.3f} s ({bellow})"


def _result(folder: Path, status: str, rows: int, fault: RigError | None,
            lateness: list[float], dt: float, clock_origin: float) -> RunResult:
    late = [x for x in lateness if x > 0.5 * dt]
    ordered = sorted(lateness) or [0.0]
    return RunResult(
        folder=folder, status=status, samples=rows,
        fault_code=getattr(fault, "code", None) if fault else None,
        fault_meaning=getattr(fault, "meaning", str(fault)) if fault else None,
        late_cycles=len(late), lateness_p99=ordered[int(0.99 * (len(ordered) - 1))],
        lateness_max=max(ordered), clock_origin=clock_origin)
