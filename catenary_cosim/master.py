"""The co-simulation master: a pantograph FMU (fmpy) running along the finite-difference catenary.

Coupling (explicit, Gauss-Seidel, pantograph first)
    At communication point :math:`t_n` the pantograph is at :math:`x_n = x_0 + v t_n` and the
    wire's height there is :math:`w_n = h_w(x_n, t_n)`. One communication step :math:`H`:

    1. the FMU gets :math:`\\eta_n = w_n + \\Delta` (held over the step) and advances to
       :math:`t_{n+1}` (``doStep``, or CVODE for Model Exchange); its output is the contact
       force :math:`F_{n+1} = k_c\\,(\\xi_{n+1} - \\eta_n)` (zero when the head is below the
       wire: unilateral contact);
    2. the catenary advances over the same interval in :math:`m = H / \\Delta t` implicit time
       steps with the force :math:`F_{n+1}` acting at the moving contact point
       :math:`x_n + v\\,j\\,\\Delta t`, :math:`j = 1..m`;
    3. :math:`w_{n+1} = h_w(x_{n+1}, t_{n+1})` is read for the next step.

    The only approximation of the coupling is the lag of the wire height over one step, a
    first-order error :math:`O(H)` that vanishes as the step shrinks (shown by the tests).

Stability of the stiff contact
    A perturbation :math:`\\delta w` of the wire height changes the force by
    :math:`-k_c\\,\\delta w` one step later. Seen from the contact point over more than a few
    time steps a taut wire hit by a point force is a dashpot of impedance
    :math:`Z = 2\\sqrt{T\\rho}` (waves run away to both sides; 329 N s/m for the EN 50318
    contact wire), so the force moves it by :math:`-k_c H / Z\\,\\delta w` per step:
    :math:`\\delta w_{n+1} = (1 - g)\\,\\delta w_n` with the **coupling gain**
    :math:`g = k_c H / Z`. The lag is stable for :math:`g < 2` and free of overshoot for
    :math:`g < 1`; for the 50 kN/m contact, :math:`g = 0.015` at :math:`H = 10^{-4}` s and
    0.076 at the default :math:`H = 5 \\cdot 10^{-4}` s.
    (Within a single step the wire is mass-like, and the head's own mass and the pantograph's
    damping only add margin.) :math:`k_c` is measured before the run as the FMU's feed-through
    :math:`|\\partial F/\\partial\\eta|`, :math:`g` is reported in the settings, and a gain
    above :data:`MAX_COUPLING_GAIN` is refused unless ``check_coupling=False``.

Loop
    For an FMI 2.0 Co-Simulation FMU on a catenary with its compiled step the loop runs in C
    (`panto.catenary_cosim.coupling_kernel`: the FMU's ``fmi2SetReal``/``fmi2DoStep``/
    ``fmi2GetReal`` called directly, the same operations in the same order as the Python
    loop, which gives the same run bit for bit); otherwise, or with ``compiled_loop=False``,
    the Python loop through fmpy. ``settings["loop"]`` says which ran.

Start
    The pantograph starts at ``start_position`` (default: the first support) in static
    equilibrium with the static wire (the project's FMUs start in equilibrium with their inputs)
    and runs at constant speed to ``stop_position`` (default: the last support). The force
    steps on at the start; the analysed section (default: the line's analysed spans, the two
    central spans of ten) is far enough away for that transient to have passed.
"""
from __future__ import annotations

import math
import time as clock
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .coupling_kernel import compiled_loop_available, run_loop
from .pantographs import PantographSetup, pantograph_setup
from .plots import plot_contact_force, plot_uplift
from .statistics import ContactStatistics, compute_statistics, lowpass_filter, sample_rate

#: Default catenary time step and communication step (s).
DEFAULT_TIME_STEP = 5e-4
#: Largest coupling gain accepted (see module notes).
MAX_COUPLING_GAIN = 0.5


@dataclass(frozen=True)
class CosimulationResult:
    """Time series, settings, counters and timings of one co-simulation run.

    Attributes
    ----------
    time : numpy.ndarray
        Communication points (s), from 0.
    position : numpy.ndarray
        Contact point x (m, 0 at the first support).
    contact_force : numpy.ndarray
        Raw contact force (N), 0 during contact loss.
    wire_height : numpy.ndarray
        Contact-wire height at the contact point (m, absolute).
    static_wire_height : numpy.ndarray
        Static contact-wire height at the contact point (m).
    head_height : numpy.ndarray
        Collector-head height mapped back to the line's heights (m); NaN without a head output.
    support_uplift : numpy.ndarray, shape (n, k)
        Uplift (m) of the contact wire at each of the k supports over time.
    support_positions : numpy.ndarray
        x of the supports (m).
    section : tuple of float
        Analysed section (m).
    settings : dict
        Line, pantograph, speed, steps, interface, coupling gain, FMU path, ...
    counters : dict
        Communication steps, catenary steps, FMU calls, contact-loss samples and events.
    timing : dict
        Wall seconds: ``setup``, ``catenary``, ``fmu``, ``python`` (rest of the loop), ``loop``,
        ``total``; ``loop_cpu``: CPU seconds of the process over the loop; simulated seconds
        per wall and per CPU second of the loop.
    success : bool
    message : str
    """

    time: np.ndarray
    position: np.ndarray
    contact_force: np.ndarray
    wire_height: np.ndarray
    static_wire_height: np.ndarray
    head_height: np.ndarray
    support_uplift: np.ndarray
    support_positions: np.ndarray
    section: tuple[float, float]
    settings: dict[str, Any] = field(default_factory=dict)
    counters: dict[str, int] = field(default_factory=dict)
    timing: dict[str, float] = field(default_factory=dict)
    success: bool = True
    message: str = ""

    @property
    def in_section(self) -> np.ndarray:
        """Boolean mask of the samples inside the analysed section."""
        return (self.position >= self.section[0]) & (self.position <= self.section[1])

    @property
    def section_supports(self) -> np.ndarray:
        """Indices of the supports inside the analysed section (ends included)."""
        low, high = self.section
        tol = 1e-9 * max(1.0, high)
        return np.flatnonzero((self.support_positions >= low - tol)
                              & (self.support_positions <= high + tol))

    def statistics(self) -> ContactStatistics:
        """EN 50318 statistics over the analysed section (:mod:`.statistics`)."""
        return compute_statistics(self.time, self.contact_force, section=self.in_section,
                                  support_uplift=self.support_uplift[:, self.section_supports])

    def filtered_force(self) -> np.ndarray:
        """The contact force low-pass filtered at 20 Hz (zero phase)."""
        return lowpass_filter(self.contact_force, sample_rate(self.time))

    def to_response(self, every: int = 1) -> Any:
        """The time series as a :class:`panto.fmu_src.response.TimeResponse` (every n-th sample)."""
        from panto.fmu_src.response import TimeResponse

        rows = slice(None, None, max(1, int(every)))
        signals = {"position": self.position, "contact_force": self.contact_force,
                   "contact_force_20Hz": self.filtered_force(), "wire_height": self.wire_height,
                   "wire_uplift": self.wire_height - self.static_wire_height,
                   "head_height": self.head_height}
        units = {"position": "m", "contact_force": "N", "contact_force_20Hz": "N",
                 "wire_height": "m", "wire_uplift": "m", "head_height": "m"}
        for i, x in enumerate(self.support_positions):
            signals[f"uplift_support_{i}"] = self.support_uplift[:, i]
            units[f"uplift_support_{i}"] = "m"
        signals = {name: values[rows] for name, values in signals.items()}
        metadata = {"settings": self.settings, "counters": self.counters,
                    "timing": self.timing, "section_m": list(self.section),
                    "support_positions_m": self.support_positions.tolist(),
                    "statistics": self.statistics().to_dict()}
        return TimeResponse(self.time[rows], signals, units=units, metadata=metadata)

    def _repr_html_(self) -> str:
        """A notebook's view: line, pantograph and speed, then the EN 50318 statistics over the
        analysed section with their units."""
        from panto.fmu_src.display import html_block, html_table

        units = {"uplift_max_mm": "mm", "loss_pct": "%"}
        rows = [[key, value, units.get(key, "N")]
                for key, value in self.statistics().to_dict().items()]
        pantograph = self.settings.get("pantograph") or {}
        setting = (f"line {self.settings.get('line', '?')}, pantograph "
                   f"{pantograph.get('name', '?')}, {self.settings.get('speed_kmh', math.nan):g} "
                   f"km/h, section {self.section[0]:g} to {self.section[1]:g} m")
        table = html_table(["statistic", "value", "unit"], rows)
        return html_block("Co-simulation", table, lines=[
            setting, f"{'success' if self.success else 'FAILED'}: {self.message}"])

    def to_csv(self, path: str | Path, every: int = 1) -> Path:
        """Write the time series (CSV, units in the header) and ``<path>.json`` metadata."""
        return self.to_response(every).to_csv(path)

    def save_plots(self, folder: str | Path, stem: str = "cosim") -> list[Path]:
        """Write ``<stem>_force.png`` and ``<stem>_uplift.png``; return the paths."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        return [plot_contact_force(self, folder / f"{stem}_force.png"),
                plot_uplift(self, folder / f"{stem}_uplift.png")]


# --- the run ----------------------------------------------------------------------------------

@dataclass
class _Clocks:
    catenary: float = 0.0
    fmu: float = 0.0
    cpu: float = 0.0  # CPU seconds of this process over the loop


@dataclass(frozen=True, kw_only=True)
class CosimOptions:
    """How a co-simulation run is discretised, where on the line it runs and how the FMU is driven.

    Parameters
    ----------
    time_step : float
        Catenary time step :math:`\\Delta t` [s] (ignored for a ready :class:`Catenary`).
    communication_step : float or None
        :math:`H` [s], an integer multiple of `time_step` (None: equal to it).
    element_length : float or None
        Catenary element length [m] (None: the catenary's; ignored for a ready catenary).
    damping : bool
        Structural (Rayleigh) damping of the line (ignored for a ready catenary).
    start_position, stop_position : float or None
        Where the run starts and ends [m] (None: first and last support).
    section : (float, float) or None
        Analysed section [m] (None: the line's analysed spans).
    interface : {"CS", "ME"}
        How the FMU is driven (:class:`panto.build_fmu.stepping.FmuStepper`).
    fmu_cache : path or None
        Folder for project FMUs built on demand.
    check_coupling : bool
        Refuse a coupling gain above :data:`MAX_COUPLING_GAIN` (module notes).
    compiled_loop : bool
        Run the loop in C (`panto.catenary_cosim.coupling_kernel`: the same operations, the
        FMU's FMI functions called directly) when the FMU is FMI 2.0 Co-Simulation and the
        catenary has its compiled step; False: the Python loop through fmpy.
    """

    time_step: float = DEFAULT_TIME_STEP
    communication_step: float | None = None
    element_length: float | None = None
    damping: bool = True
    start_position: float | None = None
    stop_position: float | None = None
    section: tuple[float, float] | None = None
    interface: str = "CS"
    fmu_cache: str | Path | None = None
    check_coupling: bool = True
    compiled_loop: bool = True


def cosimulate(line: Any, pantograph: PantographSetup | str, *, speed_kmh: float,
               options: CosimOptions | None = None,
               progress: Callable[[str], None] | None = None,
               **settings: Any) -> CosimulationResult:
    """Run a pantograph FMU along an overhead line at constant speed.

    Parameters
    ----------
    line : LineDefinition, str or Catenary
        A line (or its name / JSON file), or a ready :class:`Catenary` (then the time step,
        element length and damping are its own).
    pantograph : PantographSetup or str
        A setup or the name of one (:data:`.pantographs.PANTOGRAPH_NAMES`).
    speed_kmh : float
        Running speed (km/h), positive and below the contact wire's wave speed.
    options : CosimOptions, optional
        Steps, travel, section, interface (default: ``CosimOptions()``).
    progress : callable, optional
        Called with a line of text about ten times per run.
    **settings
        Fields of :class:`CosimOptions` (e.g. ``time_step=2e-4``), each replacing the one of
        `options`.

    Returns
    -------
    CosimulationResult
    """
    options = replace(options or CosimOptions(), **settings)
    say = progress or (lambda text: None)
    setup = pantograph_setup(pantograph) if isinstance(pantograph, str) else pantograph
    started = clock.perf_counter()
    if isinstance(line, (str, Path)):  # a bad speed is refused before the catenary is built
        from .lines import load_line

        _checked_speed(speed_kmh, load_line(line))
    catenary = _catenary(line, options.time_step, options.element_length, options.damping, say)
    definition = catenary.line
    speed = _checked_speed(speed_kmh, definition)
    substeps, step = _communication(catenary.time_step, options.communication_step)
    start, stop = _travel(catenary, options.start_position, options.stop_position)
    section = _section(definition, options.section)
    fmu_path = setup.resolve_fmu(options.fmu_cache, progress=say)
    offset = setup.eta_offset(definition.contact_wire_height)
    with _stepper(setup, fmu_path, step, options.interface, definition, speed_kmh) as stepper:
        catenary.reset()
        inputs = np.array([catenary.contact_wire_height(start) + offset]
                          + [value for _, value in setup.constant_inputs])
        stepper.initialise(inputs)
        gain = _checked_coupling_gain(catenary, stepper, inputs, step, options.check_coupling)
        setup_seconds = clock.perf_counter() - started
        say(f"co-simulating {definition.name} with {setup.name} at {speed_kmh:g} km/h "
            f"({(stop - start) / speed:.2f} s simulated, H = {step:g} s, gain {gain:.3f})")
        compiled = options.compiled_loop and compiled_loop_available(catenary, stepper)
        record, clocks, loop_seconds = _run(catenary, stepper, inputs, offset, start, stop,
                                            speed, substeps, bool(setup.head_output), say,
                                            compiled)
    run_settings = {
        "line": definition.name, "line_source": getattr(definition, "source", ""),
        "pantograph": setup.to_dict(), "fmu": str(fmu_path), "interface": options.interface,
        "speed_kmh": float(speed_kmh), "time_step_s": catenary.time_step,
        "communication_step_s": step, **_catenary_settings(catenary, line, options),
        "start_m": start, "stop_m": stop,
        "section_m": list(section), "eta_offset_m": offset, "coupling_gain": gain,
        "coupling": "explicit Gauss-Seidel, pantograph first, wire height held over a step",
        "loop": "compiled" if compiled else "python"}
    return _result(record, catenary, section, run_settings, clocks, setup_seconds, loop_seconds)


def _stepper(setup: PantographSetup, fmu_path: Path, step: float, interface: str,
             definition: Any, speed_kmh: float) -> Any:
    """The FMU stepper of the run (its parameters set for the line's wire height and the speed)."""
    from panto.build_fmu.stepping import FmuStepper

    return FmuStepper(fmu_path, step_size=step, inputs=setup.input_names(),
                      outputs=setup.output_names(), interface=interface,
                      parameters=setup.fmu_parameters(definition.contact_wire_height, speed_kmh))


def _catenary_settings(catenary: Any, line: Any, options: CosimOptions) -> dict[str, Any]:
    """Element length and damping as used: the catenary's own, else as asked."""
    return {"element_length_m": getattr(catenary, "element_length", options.element_length),
            "damping": getattr(catenary, "damping",
                               None if catenary is line else options.damping)}


def _catenary(line: Any, time_step: float, element_length: float | None, damping: bool,
              say: Callable[[str], None]) -> Any:
    if hasattr(line, "advance") and hasattr(line, "contact_wire_height"):
        return line  # a ready catenary (or anything with its interface)
    from .catenary import Catenary
    from .lines import load_line

    definition = load_line(line) if isinstance(line, (str, Path)) else line
    if not (math.isfinite(time_step) and time_step > 0.0):
        raise ValueError(f"time_step must be a positive number of seconds, got {time_step!r}")
    options = {} if element_length is None else {"element_length": element_length}
    say(f"building the {definition.name} catenary and its static state")
    return Catenary(definition, time_step=time_step, damping=damping, progress=say, **options)


def _checked_speed(speed_kmh: float, line: Any) -> float:
    """Speed in m/s; refuses non-positive speeds and speeds at or above the wave speed."""
    if not (isinstance(speed_kmh, (int, float)) and math.isfinite(speed_kmh) and speed_kmh > 0):
        raise ValueError(f"speed must be a positive number of km/h, got {speed_kmh!r}")
    wire = getattr(line, "contact_wire", None)
    if wire is not None:
        wave = math.sqrt(wire.tension / wire.mass_per_length)
        if speed_kmh / 3.6 >= wave:
            raise ValueError(f"speed {speed_kmh:g} km/h is not below the contact wire's wave "
                             f"speed sqrt(T/rho) = {3.6 * wave:.0f} km/h of line {line.name!r}")
    return speed_kmh / 3.6


def _communication(time_step: float, communication_step: float | None) -> tuple[int, float]:
    if communication_step is None:
        return 1, time_step
    ratio = communication_step / time_step
    substeps = int(round(ratio))
    if substeps < 1 or abs(ratio - substeps) > 1e-9 * ratio:
        raise ValueError(f"communication_step {communication_step!r} s must be an integer "
                         f"multiple of the catenary time step {time_step!r} s")
    return substeps, substeps * time_step


def _travel(catenary: Any, start: float | None, stop: float | None) -> tuple[float, float]:
    supports = np.asarray(catenary.support_positions, dtype=float)
    start = float(supports[0]) if start is None else float(start)
    stop = float(supports[-1]) if stop is None else float(stop)
    if not 0.0 <= start < stop <= catenary.length:
        raise ValueError(f"the run must satisfy 0 <= start ({start}) < stop ({stop}) <= the "
                         f"line's length ({catenary.length}) m")
    return start, stop


def _section(line: Any, section: tuple[float, float] | None) -> tuple[float, float]:
    if section is None:
        section = getattr(line, "analysed_section", None)
    if section is None:
        raise ValueError("give the analysed section (the line defines none)")
    low, high = float(section[0]), float(section[1])
    if not low < high:
        raise ValueError(f"the analysed section must have start < end, got {section!r}")
    return low, high


def _checked_coupling_gain(catenary: Any, stepper: Any, inputs: np.ndarray, step: float,
                           check: bool) -> float:
    """The coupling gain; refused above :data:`MAX_COUPLING_GAIN` if `check`."""
    gain = _coupling_gain(catenary, stepper, inputs, step)
    if check and gain > MAX_COUPLING_GAIN:
        raise ValueError(f"coupling gain k_c H / Z = {gain:.2f} > {MAX_COUPLING_GAIN} at the "
                         f"communication step {step:g} s: choose a smaller step")
    return gain


def _coupling_gain(catenary: Any, stepper: Any, inputs: np.ndarray, step: float) -> float:
    """:math:`g = k_c H / (2\\sqrt{T\\rho})` (module notes); NaN if the line has no wire data.

    :math:`k_c` is the FMU's feed-through :math:`|\\partial F / \\partial \\eta|`, probed with a
    0.1 mm change of the height input (inputs restored afterwards).
    """
    wire = getattr(catenary.line, "contact_wire", None)
    if wire is None:
        return math.nan
    probe = 1e-4
    force = stepper.outputs()[0]
    shifted = inputs.copy()
    shifted[0] += probe
    stepper.set_inputs(shifted)
    stiffness = abs(stepper.outputs()[0] - force) / probe
    stepper.set_inputs(inputs)
    return float(stiffness * step / (2.0 * math.sqrt(wire.tension * wire.mass_per_length)))


def _run(catenary: Any, stepper: Any, inputs: np.ndarray, offset: float, start: float,
         stop: float, speed: float, substeps: int, has_head: bool,
         say: Callable[[str], None],
         compiled: bool = False) -> tuple[dict[str, np.ndarray], _Clocks, float]:
    """The loop (module notes), in C if `compiled` (:func:`.coupling_kernel.run_loop`).

    Returns the records, the clocks and the loop's wall time.
    """
    dt = catenary.time_step
    steps = int(math.floor((stop - start) / (speed * dt * substeps) + 1e-9))
    n_supports = len(catenary.support_positions)
    rec = {name: np.empty(steps + 1) for name in ("position", "force", "wire", "head")}
    rec["uplift"] = np.empty((steps + 1, n_supports))
    y = stepper.outputs()
    x, wire = start, inputs[0] - offset
    rec["position"][0], rec["force"][0], rec["wire"][0] = x, max(y[0], 0.0), wire
    rec["head"][0] = y[1] - offset if has_head else math.nan
    rec["uplift"][0] = catenary.support_uplift()
    clocks, now = _Clocks(), clock.perf_counter
    advance, height, uplift, fmu_step = (catenary.advance, catenary.contact_wire_height,
                                         catenary.support_uplift, stepper.step)
    report = max(1, steps // 10)
    loop_start, cpu_start = now(), clock.process_time()
    if compiled:
        clocks.fmu, clocks.catenary = run_loop(
            catenary, stepper, inputs, rec, offset=offset, start=start, stop=stop, speed=speed,
            substeps=substeps, has_head=has_head, report_every=report,
            report=lambda n, x, force: say(f"  {100 * n // steps:3d} %  x = {x:7.1f} m  "
                                           f"F = {force:6.1f} N"))
        clocks.cpu = clock.process_time() - cpu_start
        return rec, clocks, now() - loop_start
    for n in range(1, steps + 1):
        t0 = now()
        y = fmu_step(inputs)
        t1 = now()
        force = y[0] if y[0] > 0.0 else 0.0
        for j in range(1, substeps + 1):
            advance(force, min(x + speed * dt * j, stop))  # min: no round-off past the end
        x = min(start + speed * dt * substeps * n, stop)
        wire = height(x)
        t2 = now()
        clocks.fmu += t1 - t0
        clocks.catenary += t2 - t1
        inputs[0] = wire + offset
        rec["position"][n], rec["force"][n], rec["wire"][n] = x, force, wire
        rec["head"][n] = y[1] - offset if has_head else math.nan
        rec["uplift"][n] = uplift()
        if n % report == 0 or n == steps:
            say(f"  {100 * n // steps:3d} %  x = {x:7.1f} m  F = {force:6.1f} N")
    clocks.cpu = clock.process_time() - cpu_start
    return rec, clocks, now() - loop_start


def _result(rec: dict[str, np.ndarray], catenary: Any, section: tuple[float, float],
            settings: dict[str, Any], clocks: _Clocks, setup_seconds: float,
            loop_seconds: float) -> CosimulationResult:
    steps = rec["force"].size - 1
    substeps = int(round(settings["communication_step_s"] / catenary.time_step))
    time = settings["communication_step_s"] * np.arange(steps + 1)
    lost = rec["force"][1:] <= 0.0
    events = int(np.count_nonzero(np.diff(np.concatenate([[False], lost]).astype(int)) == 1))
    static = np.asarray(catenary.static_contact_wire_height(rec["position"]), dtype=float)
    timing = {"setup": setup_seconds, "catenary": clocks.catenary, "fmu": clocks.fmu,
              "python": loop_seconds - clocks.catenary - clocks.fmu, "loop": loop_seconds,
              "total": setup_seconds + loop_seconds, "loop_cpu": clocks.cpu,
              "simulated_seconds_per_wall_second": float(time[-1] / loop_seconds)
              if loop_seconds > 0 else math.inf,
              "simulated_seconds_per_cpu_second": float(time[-1] / clocks.cpu)
              if clocks.cpu > 0 else math.inf}
    counters = {"communication_steps": steps, "catenary_steps": steps * substeps,
                "fmu_steps": steps, "contact_loss_samples": int(lost.sum()),
                "contact_loss_events": events}
    message = (f"{steps} steps; contact lost in {int(lost.sum())} samples ({events} events)"
               if lost.any() else f"{steps} steps; no contact loss")
    return CosimulationResult(
        time=time, position=rec["position"], contact_force=rec["force"], wire_height=rec["wire"],
        static_wire_height=static, head_height=rec["head"], support_uplift=rec["uplift"],
        support_positions=np.asarray(catenary.support_positions, dtype=float), section=section,
        settings=settings, counters=counters, timing=timing, success=True, message=message)


__all__ = ["cosimulate", "CosimOptions", "CosimulationResult",
           "DEFAULT_TIME_STEP", "MAX_COUPLING_GAIN"]
