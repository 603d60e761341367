"""The virtual test bed against the wall clock: the emulated rig served in real time.

:func:`panto.rig.virtual.run_virtual_profile` runs in lock step on a simulated clock: exact and
reproducible, but it never meets a deadline. Here the same pieces run as on the rig:

* :func:`run_virtual_profile_realtime`: the unchanged run loop of :mod:`panto.rig.session` keeps its
  2 ms deadlines on :class:`panto.rig.clock.RealClock`, while :meth:`DriveEmulator.serve
  <panto.rig.drive_emulator.DriveEmulator.serve>` answers its CAN frames from a background thread and
  steps the plant (:class:`panto.rig.testbed.VirtualTestBed`) every 2 ms of drive time. A run takes as
  long as its duration, and what it records depends on how well this computer keeps time.
* :func:`serve_emulator` (``panto rig emulate``): the drive emulator and the plant on any
  python-can bus, in real time, until stopped, for a master in another process or on another
  machine.

Threads and the plant
    The emulator thread steps the plant; the run loop reads the plant's sensors from the main
    thread. :class:`SharedPlant` makes that safe without a lock the loop could wait on: each plant
    step builds a new, never-mutated :class:`panto.rig.testbed.PlantSample`, and publishing it is one
    reference store (atomic in CPython), so the loop always reads a complete sample, the newest
    one, and never waits for an FMU step in progress. The loop's writes (valve voltage, LED) are
    single float/int stores that the next plant step picks up.

Why the drive timing is lenient here (:data:`REALTIME_DRIVE_SETTINGS`)
    The real drive interpolates the stream 1.5 periods behind the SYNCs and faults with 0x83
    (underflow) when a setpoint is more than half a period (2 ms) late, and with 0x84/0x85 when
    an interval leaves 2-5 ms. The thesis' rig meets that with a real-time unit. A Python master
    on a shared, non-real-time machine does not: the operating system, the garbage collector and
    the GIL (the emulator thread and the loop share one interpreter) stall it for milliseconds
    now and then. **The real drive would fault on such a master too.** The lenient settings
    keep the emulated run going so that the rest of the chain can be exercised in real time:

    * 3 periods of setpoint delay (12 ms): a setpoint may come up to 2 periods (8 ms) late;
    * command intervals of 0-12 ms accepted, up to 6 setpoints waiting (the catch-up burst
      after a stall);
    * a time base that follows the master (correction g = 0.3). The drive measures its period
      from the first two commands; when the first command is late, that interval is too short
      and a time base that keeps it (g = 0, or g = 0.1 as first proposed) runs out of setpoints
      within a few periods. An offline replay of :class:`panto.rig.drive_emulator.SetpointStream`
      (3 periods of delay, first two commands 0-3.2 ms late) failed 15 of 60 starts with
      g = 0.1 and 6 of 60 with g = 0.3; stalls later in the run were tolerated up to the delay
      margin whatever g. The price: a setpoint's schedule moves by g times its arrival jitter.

    They are recorded in the dataset's truth; pass ``lenient_timing=False`` to emulate the
    faithful drive (for example to see whether this machine would trip it, see
    ``benchmarks/rig_loop_timing.py``).

Analogue I/O
    Force, pressure and laser signals and the valve voltage are analogue lines to the rig's DAQ,
    not CAN frames: in :func:`run_virtual_profile_realtime` they are in-process calls
    (:class:`SharedPlant`); :func:`serve_emulator` puts only the drive on the bus.
"""
from __future__ import annotations

import contextlib
import gc
import math
import os
import sys
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

import can

from panto.rig.clock import Clock, RealClock
from panto.rig.can_protocol import DEFAULT_NODE_ID
from panto.rig.drive import LinearMotorDriver, open_bus
from panto.rig.drive_emulator import DriveEmulator, DriveParameters
from panto.rig.imperfections import RigImperfections
from panto.rig.profiles import Profile, ProfileStream
from panto.rig.virtual import TRUTH_FILE, emulator_run_options, plain_drive_parameters
from panto.rig.session import RunOptions, RunResult, run_profile
from panto.rig.testbed import PlantSample, VirtualTestBed

#: Drive timing for a real-time emulation on a non-real-time machine (see the module notes).
REALTIME_DRIVE_SETTINGS: Mapping[str, Any] = MappingProxyType({
    "timebase_correction": 0.3, "stream_delay_periods": 3.0,
    "stream_period_range": (0.0, 0.012), "stream_buffer_size": 6})


@dataclass(frozen=True, kw_only=True)
class RealtimeOptions:
    """How the real-time virtual test bed is run.

    Parameters
    ----------
    lenient_timing : bool
        Start from :data:`REALTIME_DRIVE_SETTINGS` (True) or from the faithful drive timing of
        :class:`panto.rig.drive_emulator.DriveParameters` (False); ``drive`` overrides go on top.
    reply_timeout_cycles : int
        SYNC periods without a drive reply before the driver reports "missing replies"
        (the rig's driver uses 3; the emulator thread may wake late, so more here).
    switch_interval : float or None
        Interpreter thread switch interval [s] during the run (``sys.setswitchinterval``;
        CPython's default is 5 ms, longer than a 2 ms cycle, so a busy emulator thread could
        hold the loop off for a whole cycle). None leaves it alone. Restored afterwards.
    poll_interval : float
        Longest wait of the emulator thread for a frame [s] before it advances the plant anyway.
    join_timeout : float
        Longest wait for the emulator thread to stop at the end [s].
    freeze_gc : bool
        Collect garbage once before the run, then ``gc.freeze()`` everything alive (undone
        afterwards): a full collection walks every tracked object (the SymPy-derived model
        leaves about 10^5) and stalls all threads for tens of ms, longer than the drive's
        tolerance; frozen objects are not walked again.
    """

    lenient_timing: bool = True
    reply_timeout_cycles: int = 10
    switch_interval: float | None = 0.0005
    poll_interval: float = 0.001
    join_timeout: float = 5.0
    freeze_gc: bool = True

    def __post_init__(self) -> None:
        if isinstance(self.reply_timeout_cycles, bool) or not (
                isinstance(self.reply_timeout_cycles, int) and self.reply_timeout_cycles >= 1):
            raise ValueError("RealtimeOptions.reply_timeout_cycles must be an integer >= 1, "
                             f"got {self.reply_timeout_cycles!r}")
        for name in ("poll_interval", "join_timeout") + (
                ("switch_interval",) if self.switch_interval is not None else ()):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"RealtimeOptions.{name} must be a finite number > 0 s, "
                                 f"got {value!r}")


def drive_parameters(drive: Mapping[str, Any] | None = None, *,
                     lenient_timing: bool = True) -> DriveParameters:
    """The emulated drive's parameters: lenient or faithful timing, then the `drive` overrides."""
    base = dict(REALTIME_DRIVE_SETTINGS) if lenient_timing else {}
    try:
        return replace(DriveParameters(), **{**base, **dict(drive or {})})
    except TypeError as error:  # an unknown field name
        raise ValueError(f"drive overrides {sorted(dict(drive or {}))}: {error}") from None


class SharedPlant:
    """The plant stepped by the emulator thread, read by the run loop (a :class:`RigIO`).

    Parameters
    ----------
    bed : VirtualTestBed
        An initialised test bed. Only the emulator thread may step it, through
        :meth:`on_slider_sample` (the emulator's listener).

    Notes
    -----
    The latest sample is published by a single reference store after each step and read by a
    single reference load (see the module notes); no lock, so a reader never waits.
    """

    def __init__(self, bed: VirtualTestBed) -> None:
        self.bed = bed
        self._latest: PlantSample = bed.read()
        self.samples = 0
        """Plant steps taken since construction."""

    @property
    def latest(self) -> PlantSample:
        """The newest complete plant sample."""
        return self._latest

    def on_slider_sample(self, time: float, position: float, velocity: float) -> None:
        """Step the plant (emulator thread only) and publish the new sample."""
        sample = self.bed.on_slider_sample(time, position, velocity)
        self._latest = sample  # the publication: one atomic reference store
        self.samples += 1

    def load_force(self) -> float:
        """Force of the bar on the slider [N] (emulator thread)."""
        return self.bed.load_force()

    def read_sensors(self, now: float) -> dict[str, float]:
        """The newest sample's sensor values (a copy; `now` is not needed: it is never older)."""
        return dict(self._latest.sensors)

    def write_valve_voltage(self, voltage: float) -> None:
        """Valve voltage [V]; the next plant step uses it."""
        self.bed.write_valve_voltage(voltage)

    def write_led(self, bit: int) -> None:
        """Synchronisation LED bit."""
        self.bed.write_led(bit)


class EmulatorThread:
    """:meth:`DriveEmulator.serve` in a daemon thread, with its failure kept for the caller.

    Use as a context manager: the thread runs inside the ``with`` block and is stopped and
    joined on exit; :attr:`error` holds what ended it abnormally (None otherwise).
    """

    def __init__(self, emulator: DriveEmulator, *, poll_interval: float = 0.001,
                 join_timeout: float = 5.0) -> None:
        self.emulator, self.stop_event = emulator, threading.Event()
        self.error: BaseException | None = None
        self._poll, self._join_timeout = poll_interval, join_timeout
        self._thread = threading.Thread(target=self._serve, name="panto drive emulator",
                                        daemon=True)

    def _serve(self) -> None:
        try:
            self.emulator.serve(self.stop_event, poll_interval=self._poll)
        except BaseException as error:  # reported by check(); the master sees missing replies
            self.error = error

    @property
    def alive(self) -> bool:
        """True while the thread runs."""
        return self._thread.is_alive()

    def check(self) -> None:
        """Raise RuntimeError if the emulator thread failed."""
        if self.error is not None:
            raise RuntimeError(f"the drive emulator thread failed: {type(self.error).__name__}: "
                               f"{self.error}") from self.error

    def __enter__(self) -> EmulatorThread:
        self._thread.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop_event.set()
        self._thread.join(self._join_timeout)
        if self._thread.is_alive():  # never close the plant under a running thread
            raise RuntimeError(f"the drive emulator thread did not stop within "
                               f"{self._join_timeout} s")


@contextlib.contextmanager
def realtime_interpreter(settings: RealtimeOptions) -> Iterator[None]:
    """Inside the block: the thread switch interval of `settings`, and a frozen heap if asked.

    Both are process-wide and restored on exit (see :class:`RealtimeOptions`).
    """
    previous = sys.getswitchinterval()
    if settings.freeze_gc:
        gc.collect()
        gc.freeze()
    if settings.switch_interval is not None:
        sys.setswitchinterval(settings.switch_interval)
    try:
        yield
    finally:
        sys.setswitchinterval(previous)
        if settings.freeze_gc:
            gc.unfreeze()


@contextlib.contextmanager
def emulated_rig(bus: can.BusABC, *, bed: VirtualTestBed, drive: DriveParameters,
                 settings: RealtimeOptions, pressure: float = 4.0,
                 node_id: int = DEFAULT_NODE_ID,
                 ) -> Iterator[tuple[SharedPlant, DriveEmulator, EmulatorThread]]:
    """The drive emulator and the plant `bed` served on `bus` in real time inside the block.

    Yields ``(plant, emulator, thread)``; on exit the emulator thread is stopped and joined and
    the plant's FMU is released (not while the thread still runs). The bellow starts, and is
    held (valve voltage unchanged until a master writes it), at `pressure` [bar]; the slider
    starts at 0. :func:`realtime_interpreter` applies inside the block.
    """
    wall = RealClock()
    thread: EmulatorThread | None = None
    try:
        bed.initialise(slider_position=0.0, pressure=pressure, start_time=wall.now())
        plant = SharedPlant(bed)
        emulator = DriveEmulator(bus, clock=wall, node_id=node_id, parameters=drive,
                                 listener=plant.on_slider_sample, load_force=plant.load_force,
                                 initial_position=0.0)
        thread = EmulatorThread(emulator, poll_interval=settings.poll_interval,
                                join_timeout=settings.join_timeout)
        with realtime_interpreter(settings), thread:
            yield plant, emulator, thread
    finally:
        if thread is None or not thread.alive:
            bed.close()


def _test_bed(fmu_path: str | Path, imperfections: RigImperfections | None,
              parameters: Mapping[str, float] | None, seed: int, sample_period: float,
              keep_truth: bool) -> VirtualTestBed:
    """The plant of an emulated rig (not yet initialised)."""
    bed = VirtualTestBed(fmu_path, parameters=parameters, imperfections=imperfections, seed=seed,
                         sample_period=sample_period)
    bed.keep_truth = keep_truth
    return bed


def run_virtual_profile_realtime(profile: Profile, *, fmu_path: str | Path, folder: str | Path,
                                 imperfections: RigImperfections | None = None,
                                 parameters: Mapping[str, float] | None = None, seed: int = 0,
                                 drive: Mapping[str, Any] | None = None,
                                 options: RunOptions | None = None,
                                 realtime: RealtimeOptions | None = None,
                                 clock: Clock | None = None,
                                 progress: Callable[[str], None] | None = None) -> RunResult:
    """Run `profile` on the virtual test bed in real time and record it into `folder`.

    As :func:`panto.rig.virtual.run_virtual_profile`, but against the wall clock: the run loop keeps
    its 500 Hz deadlines on `clock` and the drive emulator answers from a background thread
    (see the module notes for the threads and for the lenient drive timing).

    Parameters
    ----------
    profile, fmu_path, folder, imperfections, parameters, seed
        As for :func:`panto.rig.virtual.run_virtual_profile`.
    drive : mapping, optional
        Overrides of :class:`panto.rig.drive_emulator.DriveParameters`, applied on top of
        :data:`REALTIME_DRIVE_SETTINGS` (or of the faithful defaults, see `realtime`).
    options : RunOptions, optional
        Run options; the source is set to ``"emulator"`` and the truth is filled in.
    realtime : RealtimeOptions, optional
    clock : Clock, optional
        The run loop's clock; default :class:`panto.rig.clock.RealClock`. It must read
        ``time.monotonic`` (the driver and the emulator use a plain RealClock); a benchmark may
        pass a wrapper that records every wake-up.
    progress : callable, optional
        Receives a line every 10 s of run time.

    Returns
    -------
    RunResult
        ``status`` is ``"complete"`` or ``"aborted: ..."`` (a drive fault, e.g. 0x83 when this
        machine stalled longer than the drive tolerates); the dataset, and ``truth.csv`` beside
        it, are in `folder` either way.

    Raises
    ------
    RuntimeError
        The emulator thread failed (a bug or an FMU failure, not a drive fault); what the run
        recorded is in `folder`.
    """
    settings = realtime or RealtimeOptions()
    drive_settings = drive_parameters(drive, lenient_timing=settings.lenient_timing)
    channel = f"panto-realtime-{os.getpid()}-{threading.get_ident()}-{time.monotonic_ns()}"
    result: RunResult | None = None
    plant: SharedPlant | None = None
    thread: EmulatorThread | None = None
    with can.Bus(interface="virtual", channel=channel) as master_bus, \
            can.Bus(interface="virtual", channel=channel) as drive_bus:
        bed = _test_bed(fmu_path, imperfections, parameters, seed,
                        sample_period=1.0 / profile.sample_rate, keep_truth=True)
        rig = emulated_rig(drive_bus, bed=bed, drive=drive_settings, settings=settings,
                           pressure=profile.pressure.offset)
        try:
            with rig as (plant, _, thread):
                driver = _driver(master_bus, profile, settings)
                truth = _realtime_truth(plant.bed, drive_settings, settings)
                _warm_up(profile)
                result = run_profile(profile, driver=driver, io=plant,
                                     clock=clock if clock is not None else RealClock(),
                                     folder=folder,
                                     options=emulator_run_options(options, plant.bed, truth),
                                     progress=progress)
        finally:  # once the thread has stopped, the plant's truth is complete
            if plant is not None and thread is not None and not thread.alive:
                _write_truth(plant.bed, folder, result)
    _check_thread(thread, folder, result)
    return result


def _driver(bus: can.BusABC, profile: Profile, settings: RealtimeOptions) -> LinearMotorDriver:
    """The run loop's drive driver on `bus`, on a plain wall clock, within the profile's limits."""
    return LinearMotorDriver(bus, clock=RealClock(),
                             reply_timeout_cycles=settings.reply_timeout_cycles,
                             position_limits=(profile.limits.motor_min, profile.limits.motor_max))


def _realtime_truth(bed: VirtualTestBed, drive: DriveParameters,
                    settings: RealtimeOptions) -> dict[str, Any]:
    """The run's truth record: the plant's, the drive's parameters and the real-time settings."""
    return {**bed.truth_record(), "drive": plain_drive_parameters(drive),
            "realtime": {"lenient_timing": settings.lenient_timing,
                         "reply_timeout_cycles": settings.reply_timeout_cycles}}


def _check_thread(thread: EmulatorThread | None, folder: str | Path,
                  result: RunResult | None) -> None:
    """Raise the emulator thread's failure, noting where the run recorded up to then is."""
    try:
        if thread is not None:
            thread.check()
    except RuntimeError as error:
        error.add_note(f"the run recorded up to then is in {folder}"
                       + (f" ({result.status})" if result else ""))
        raise


def _warm_up(profile: Profile) -> None:
    """Render the profile's first samples once, so first-call costs (numpy paths, imports, a few
    ms) do not fall into the first cycles, where a late stream start can make the drive measure
    a wrong stream period."""
    stream = ProfileStream(profile)
    for _ in range(min(4, profile.sample_count)):
        stream.next()


def _write_truth(bed: VirtualTestBed, folder: str | Path, result: RunResult | None) -> None:
    """``truth.csv`` beside the run (as :func:`panto.rig.virtual.run_virtual_profile` writes it)."""

    path = Path(folder) / TRUTH_FILE
    origin = result.clock_origin if result is not None else math.nan
    if Path(folder).is_dir() and not path.exists() and math.isfinite(origin):
        bed.truth_dataset(origin).write(path)


@dataclass(frozen=True)
class EmulationSummary:
    """How a :func:`serve_emulator` session ended.

    Attributes
    ----------
    seconds : wall time served [s].
    stopped_by : ``"duration"``, ``"stop_event"`` or ``"interrupt"`` (Ctrl-C).
    plant_samples : plant steps taken (500 per second).
    main_state, error_code : the drive's state and error code at the end.
    malformed_frames : frames for the drive that could not be decoded.
    """

    seconds: float
    stopped_by: str
    plant_samples: int
    main_state: int
    error_code: int
    malformed_frames: int

    @property
    def success(self) -> bool:
        """True: the session ended as asked (a drive fault is the master's business)."""
        return self.stopped_by in ("duration", "stop_event", "interrupt")

    @property
    def message(self) -> str:
        return (f"served {self.seconds:.1f} s ({self.plant_samples} plant samples), stopped by "
                f"{self.stopped_by}; drive state {self.main_state}, error 0x{self.error_code:02X}")


@dataclass(frozen=True, kw_only=True)
class EmulatorOptions:
    """What :func:`serve_emulator` serves: the plant behind the drive, the drive, the reports.

    Parameters
    ----------
    imperfections : RigImperfections or None
        Default: the rig as the thesis describes it.
    parameters : mapping or None
        The "true" pantograph's model parameters.
    seed : int
        Seed of the sensor noise.
    drive : mapping or None
        Overrides of the drive parameters, on top of :data:`REALTIME_DRIVE_SETTINGS` unless
        ``RealtimeOptions.lenient_timing`` is False.
    pressure : float
        Bellow pressure held during the session [bar].
    node_id : int
        The emulated drive's CANopen node id.
    status_period : float
        Seconds between progress lines [s].
    """

    imperfections: RigImperfections | None = None
    parameters: Mapping[str, float] | None = None
    seed: int = 0
    drive: Mapping[str, Any] | None = None
    pressure: float = 4.0
    node_id: int = DEFAULT_NODE_ID
    status_period: float = 10.0


def serve_emulator(bus_or_config: can.BusABC | Mapping[str, Any], *, fmu_path: str | Path,
                   duration: float | None = None, stop_event: threading.Event | None = None,
                   progress: Callable[[str], None] | None = None,
                   options: EmulatorOptions | None = None,
                   realtime: RealtimeOptions | None = None) -> EmulationSummary:
    """Serve the emulated rig's drive (and its plant) on a CAN bus in real time until stopped.

    What ``panto rig emulate`` does: an external master (``panto rig run`` in another process, or
    the rig's own software) on a shared bus, such as ``socketcan`` (``vcan0``) or
    ``udp_multicast``, finds a drive that answers like the real one (NMT, state machine,
    position stream, TxPDO replies after every SYNC) and moves the emulated slider, which
    drives the pantograph FMU at 500 Hz.

    Only the drive is on the bus. The rig's analogue I/O (force, pressure and laser sensors, the
    valve voltage, the LED) are lines to its DAQ, not CAN frames, so an external master cannot
    read or write them here: the bellow is held at ``options.pressure``, and the plant's force
    and pressure are only shown in the progress lines. For a complete emulated run in one
    process use :func:`run_virtual_profile_realtime`.

    Parameters
    ----------
    bus_or_config : can.BusABC or mapping
        A python-can bus (left open), or keyword arguments of :func:`panto.rig.drive.open_bus`, e.g.
        ``{"interface": "socketcan", "channel": "vcan0"}`` (opened and shut down here).
    fmu_path : str or pathlib.Path
        The pantograph FMU used as the plant.
    duration : float, optional
        Seconds to serve; default until `stop_event` is set or Ctrl-C.
    stop_event : threading.Event, optional
        Set it (from another thread) to stop.
    progress : callable, optional
        Receives a status line (drive state, slider position, force) every
        ``options.status_period`` s.
    options : EmulatorOptions, optional
        The plant, the drive and the reports (default: ``EmulatorOptions()``).
    realtime : RealtimeOptions, optional

    Returns
    -------
    EmulationSummary
    """
    options = options or EmulatorOptions()
    _check_serving_times(duration, options.status_period)
    settings = realtime or RealtimeOptions()
    drive_settings = drive_parameters(options.drive, lenient_timing=settings.lenient_timing)
    stop = stop_event if stop_event is not None else threading.Event()
    with _bus(bus_or_config) as bus:
        bed = _test_bed(fmu_path, options.imperfections, options.parameters, options.seed,
                        sample_period=0.002, keep_truth=False)
        with emulated_rig(bus, bed=bed, drive=drive_settings, settings=settings,
                          pressure=options.pressure, node_id=options.node_id) \
                as (plant, emulator, thread):
            if progress:
                progress(f"drive emulator node {options.node_id} serving on "
                         f"{bus.channel_info}; bellow held at {options.pressure:g} bar"
                         + ("" if duration is None else f"; for {duration:g} s"))
            started = time.monotonic()
            stopped_by = _wait_until_stopped(
                stop, started, duration, options.status_period, thread,
                lambda: progress(_status_line(plant, emulator, started)) if progress else None)
            seconds = time.monotonic() - started
    thread.check()
    summary = EmulationSummary(seconds=seconds, stopped_by=stopped_by,
                               plant_samples=plant.samples, main_state=int(emulator.main_state),
                               error_code=int(emulator.error_code),
                               malformed_frames=emulator.malformed_frames)
    if progress:
        progress(summary.message)
    return summary


def _check_serving_times(duration: float | None, status_period: float) -> None:
    """Refuse a duration or a status period that is not a finite number > 0 s."""
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be a finite number > 0 s or None, got {duration!r}")
    if not (math.isfinite(status_period) and status_period > 0):
        raise ValueError(f"status_period must be a finite number > 0 s, got {status_period!r}")


@contextlib.contextmanager
def _bus(bus_or_config: can.BusABC | Mapping[str, Any]) -> Iterator[can.BusABC]:
    """The given bus (left open) or one opened from a configuration (shut down at the end)."""
    if isinstance(bus_or_config, can.BusABC):
        yield bus_or_config
        return
    if not isinstance(bus_or_config, Mapping):
        raise ValueError("bus_or_config must be a python-can bus or a mapping of bus options "
                         f"(interface, channel, ...), got {bus_or_config!r}")
    bus = open_bus(**dict(bus_or_config))
    try:
        yield bus
    finally:
        bus.shutdown()


def _wait_until_stopped(stop: threading.Event, started: float, duration: float | None,
                        status_period: float, thread: EmulatorThread,
                        report: Callable[[], object]) -> str:
    """Wait on the main thread (so Ctrl-C arrives) and report; return what stopped it."""
    next_report = started + status_period
    try:
        while thread.alive:
            now = time.monotonic()
            if duration is not None and now - started >= duration:
                return "duration"
            end = math.inf if duration is None else started + duration
            if stop.wait(max(0.0, min(next_report, end) - now)):
                return "stop_event"
            if time.monotonic() >= next_report:
                report()
                next_report += status_period
    except KeyboardInterrupt:
        return "interrupt"
    return "error"


def _status_line(plant: SharedPlant, emulator: DriveEmulator, started: float) -> str:
    sensors = plant.latest.sensors
    return (f"  t = {time.monotonic() - started:8.1f} s  drive state {int(emulator.main_state)} "
            f"error 0x{int(emulator.error_code):02X}  slider "
            f"{emulator.slider_position * 1e3:+7.2f} mm  force {sensors['force']:7.1f} N  "
            f"pressure {sensors['pressure']:.2f} bar")
