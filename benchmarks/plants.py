"""Plants with known truth for the identification recovery benchmark, written apart from the code
under test.

Run by hand through ``benchmarks/identification_recovery.py``; the oscillator plants are also
checked against the identification structures by ``tests/test_recovery_plants.py``.

Oscillator plants (thesis sections 2.6-2.7, EN 50318)
    ``n`` masses (2 or 3) numbered from the bottom, absolute heights ``x_i`` [m], velocities
    ``v_i`` [m/s]. Every spring is relaxed when all masses are at the height ``y_0``; the base
    spring ``k_1`` and damper ``c_1`` tie mass 1 to the ground, ``k_i``, ``c_i`` tie mass ``i``
    to mass ``i - 1``; the bellow force ``p_gain p + F_0`` acts on mass 1 and the carbon contact
    ``k_E`` ties the head (mass ``n``) to the wire height ``eta``. Newton's law per mass, written
    force by force (no matrices)::

        m_1 v_1' = -k_1 (x_1 - y_0) - c_1 v_1 + k_2 (x_2 - x_1) + c_2 (v_2 - v_1) + p_gain p + F_0
        m_i v_i' = -k_i (x_i - x_{i-1}) - c_i (v_i - v_{i-1})
                   + k_{i+1} (x_{i+1} - x_i) + c_{i+1} (v_{i+1} - v_i)        (1 < i < n)
        m_n v_n' = -k_n (x_n - x_{n-1}) - c_n (v_n - v_{n-1}) + k_E (eta - x_n)

    Outputs ``y_cb = x_{n-1} + y_cb_offset`` (the frame under the head), ``xi = x_n`` and the
    contact force ``F_c = k_E (x_n - eta)``. The run starts at rest in static equilibrium for the
    first input sample; the inputs are interpolated linearly between samples and the equations
    are integrated by :func:`scipy.integrate.solve_ivp` (DOP853, tight tolerances, restarted at
    every sample where an input's slope changes, so that no kink lies inside a step; the force balance is evaluated once per unit perturbation to read off
    its affine coefficients, so each solver stage is one matrix product). Nothing here imports the identification structures, the FMU builder
    or the symbolic models.

Truth per seed
    Masses, springs and dampers log-uniform within a factor ``spread`` (default 1.3, i.e. +-30 %)
    around the EN 50318 two-mass pantograph (m = 15, 7.2 kg; k = 50, 4200 N/m; c = 90, 10 N s/m)
    and the Bruni et al. three-mass one (m = 6, 9, 7.5 kg; k = 160, 15 500, 7000 N/m;
    c = 100, 10, 10 N s/m; its zero head dampers replaced by 10 N s/m so that the modes decay);
    the bellow gain ``p_gain`` log-uniform around 100 N/bar and ``F_0`` around -300 N (about
    150 N uplift at 4.5 bar); ``y_cb_offset`` uniform in +-5 mm. ``k_E`` = 50 000 N/m (EN 50318)
    and ``y_0`` = 2 m are conventions the structures hold fixed, not drawn.

Excitations (:data:`EXCITATIONS`)
    ``aprbs``: amplitude-modulated PRBS on ``eta`` (levels +-2 cm about 2 m, holds 0.05-1.5 s)
    with pressure steps (3.5-5.5 bar, holds 3-8 s), 200 Hz, 60 s. ``multisine``: random-phase
    multisine on ``eta`` (0.1-20 Hz, 5 mm rms) and a slow one on ``p`` (0.05-1 Hz, 0.3 bar rms),
    100 Hz, 30 s. ``chirp``: logarithmic chirp on ``eta`` (0.1-20 Hz, 5 mm) at a constant
    4.5 bar, 100 Hz, 40 s: ``p_gain`` and ``F_0`` cannot be told apart from it (only
    ``4.5 p_gain + F_0`` acts), which the benchmark must mark rather than count as a failure.

Noise
    White Gaussian noise on every output at a stated signal-to-noise ratio ``snr_db``: the
    noise's standard deviation is the output's own standard deviation times ``10^(-snr/20)``.

The physical pantograph (:func:`pantograph_case`)
    The virtual test bed (:func:`panto.rig.virtual.run_virtual_profile`) with no imperfections
    (:meth:`panto.rig.imperfections.RigImperfections.none`), the true parameters those given to
    the FMU (Table 4.1 drawn per seed within ``spread``), mapped to identification data by
    :func:`panto.identification.data.datasets.pantograph_data`. This family is **not
    independent** of the model under test: the FMU is generated from the same symbolic model as
    the ``physical-linear`` structure (which linearises it about the equilibrium), so it checks
    the estimator and the data path, not the model.
"""
from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np
from scipy.integrate import solve_ivp

#: Contact stiffness [N/m] (EN 50318) and relaxed height [m]: conventions, not drawn.
CONTACT_STIFFNESS = 50000.0
RELAXED_HEIGHT = 2.0
#: Centre of each oscillator family's truth (masses bottom to top).
CENTRES = {
    2: {"m": (15.0, 7.2), "k": (50.0, 4200.0), "c": (90.0, 10.0)},
    3: {"m": (6.0, 9.0, 7.5), "k": (160.0, 15500.0, 7000.0), "c": (100.0, 10.0, 10.0)},
}
#: Identification structure fitted to each family.
STRUCTURE_OF_FAMILY = {"two-mass": "two-mass", "three-mass": "three-mass",
                       "pantograph": "physical-linear"}
MASSES_OF_FAMILY = {"two-mass": 2, "three-mass": 3}


@dataclass(frozen=True)
class Excitation:
    """One excitation of the oscillator plants.

    Parameters
    ----------
    name : str
        ``"aprbs"``, ``"multisine"`` or ``"chirp"``.
    rate : float
        Sample rate [Hz].
    duration : float
        Length [s].
    profile : str
        The virtual test bed's rig profile used for the physical pantograph.
    profile_duration : float
        Length [s] of that rig run (the profile's own when it is shorter).
    """

    name: str
    rate: float
    duration: float
    profile: str
    profile_duration: float


#: The excitations by name.
EXCITATIONS = {
    "aprbs": Excitation("aprbs", 200.0, 60.0, "aprbs_training", 40.0),
    "multisine": Excitation("multisine", 100.0, 30.0, "multisine_odd", 30.0),
    "chirp": Excitation("chirp", 100.0, 40.0, "chirp_log", 70.0),
}


@dataclass(frozen=True)
class PlantRecord:
    """A simulated experiment with its truth.

    Parameters
    ----------
    time : ndarray
        Sample times [s].
    inputs : dict of str to ndarray
        ``eta`` [m], ``p`` [bar].
    outputs : dict of str to ndarray
        Noisy ``F_c`` [N], ``y_cb`` [m] (and ``xi`` [m]).
    clean : dict of str to ndarray
        The same outputs without noise.
    truth : dict of str to float
        The plant's parameters.
    notes : dict
        Family, excitation, seed, SNR, noise standard deviations.
    """

    time: np.ndarray
    inputs: dict[str, np.ndarray]
    outputs: dict[str, np.ndarray]
    clean: dict[str, np.ndarray]
    truth: dict[str, float]
    notes: dict[str, Any] = field(default_factory=dict)


# --- truth ------------------------------------------------------------------------------------

def _log_uniform(rng: np.random.Generator, centre: float, spread: float) -> float:
    return float(centre * math.exp(rng.uniform(-math.log(spread), math.log(spread))))


def draw_oscillator_truth(masses: int, rng: np.random.Generator,
                          spread: float = 1.3) -> dict[str, float]:
    """True parameters of an `masses`-mass plant, drawn around the family's centre (module notes).

    Parameters
    ----------
    masses : {2, 3}
    rng : numpy.random.Generator
    spread : float
        Factor of the log-uniform draw (1.3: within +-30 %).

    Returns
    -------
    dict
        ``m_i`` [kg], ``k_i`` [N/m], ``c_i`` [N s/m], ``k_E`` [N/m], ``p_gain`` [N/bar],
        ``F_0`` [N], ``y_0`` [m], ``y_cb_offset`` [m].
    """
    centre = CENTRES[masses]
    truth = {f"{kind}{i + 1}": _log_uniform(rng, centre[kind][i], spread)
             for kind in ("m", "k", "c") for i in range(masses)}
    truth.update(k_E=CONTACT_STIFFNESS, y_0=RELAXED_HEIGHT,
                 p_gain=_log_uniform(rng, 100.0, spread),
                 F_0=-_log_uniform(rng, 300.0, spread),
                 y_cb_offset=float(rng.uniform(-0.005, 0.005)))
    return truth


# --- excitations ------------------------------------------------------------------------------

def _aprbs(rng: np.random.Generator, time: np.ndarray, low: float, high: float,
           hold: tuple[float, float]) -> np.ndarray:
    """Piecewise-constant levels uniform in [low, high], holds uniform in `hold` [s]."""
    out = np.empty_like(time)
    start = 0
    while start < len(time):
        stop = np.searchsorted(time, time[start] + rng.uniform(*hold))
        out[start:max(stop, start + 1)] = rng.uniform(low, high)
        start = max(stop, start + 1)
    return out


def _multisine(rng: np.random.Generator, time: np.ndarray, band: tuple[float, float],
               rms: float) -> np.ndarray:
    """Random-phase multisine on the record's frequency grid within `band` [Hz], scaled to `rms`."""
    resolution = 1.0 / (time[-1] - time[0] + (time[1] - time[0]))
    lines = np.arange(max(1, math.ceil(band[0] / resolution)), math.floor(band[1] / resolution) + 1)
    phases = rng.uniform(0.0, 2.0 * math.pi, len(lines))
    signal = np.sum(np.cos(2.0 * math.pi * resolution * lines[:, None] * time[None, :]
                           + phases[:, None]), axis=0)
    return rms * signal / np.sqrt(np.mean(signal ** 2))


def _chirp(time: np.ndarray, band: tuple[float, float], amplitude: float) -> np.ndarray:
    """Logarithmic sine sweep from band[0] to band[1] [Hz] over the record."""
    length = time[-1] - time[0]
    ratio = band[1] / band[0]
    phase = 2.0 * math.pi * band[0] * length / math.log(ratio) * (ratio ** (time / length) - 1.0)
    return amplitude * np.sin(phase)


def excitation_inputs(name: str, rng: np.random.Generator, *, rate: float | None = None,
                      duration: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sample times [s], ``eta`` [m] and ``p`` [bar] of excitation `name` (module notes).

    Parameters
    ----------
    name : {"aprbs", "multisine", "chirp"}
    rng : numpy.random.Generator
    rate, duration : float, optional
        Override the excitation's sample rate [Hz] and length [s].
    """
    spec = EXCITATIONS[name]
    rate = spec.rate if rate is None else rate
    duration = spec.duration if duration is None else duration
    time = np.arange(int(round(duration * rate))) / rate
    if name == "aprbs":
        eta = RELAXED_HEIGHT + _aprbs(rng, time, -0.02, 0.02, (0.05, 1.5))
        pressure = _aprbs(rng, time, 3.5, 5.5, (3.0, 8.0))
    elif name == "multisine":
        eta = RELAXED_HEIGHT + _multisine(rng, time, (0.1, 20.0), 0.005)
        pressure = 4.5 + _multisine(rng, time, (0.05, 1.0), 0.3)
    elif name == "chirp":
        eta = RELAXED_HEIGHT + _chirp(time, (0.1, 20.0), 0.005)
        pressure = np.full_like(time, 4.5)
    else:
        raise ValueError(f"unknown excitation {name!r}; choose from {sorted(EXCITATIONS)}")
    return time, eta, pressure


# --- oscillator plant -------------------------------------------------------------------------

def _forces(truth: Mapping[str, float], masses: int, x: np.ndarray, v: np.ndarray,
            eta: float, p: float) -> np.ndarray:
    """Net force [N] on every mass (module notes), spring by spring."""
    force = np.zeros(masses)
    y_0 = truth["y_0"]
    force[0] += -truth["k1"] * (x[0] - y_0) - truth["c1"] * v[0] + truth["p_gain"] * p + truth["F_0"]
    for i in range(1, masses):
        link = truth[f"k{i + 1}"] * (x[i] - x[i - 1]) + truth[f"c{i + 1}"] * (v[i] - v[i - 1])
        force[i] -= link
        force[i - 1] += link
    force[-1] += truth["k_E"] * (eta - x[-1])
    return force


def _equilibrium(truth: Mapping[str, float], masses: int, eta: float, p: float) -> np.ndarray:
    """Heights [m] at rest: the forces are affine in the heights, so one linear solve is exact."""
    rest = np.zeros(masses)
    base = _forces(truth, masses, np.full(masses, truth["y_0"]), rest, eta, p)
    columns = [_forces(truth, masses, truth["y_0"] + np.eye(masses)[j], rest, eta, p) - base
               for j in range(masses)]
    return truth["y_0"] + np.linalg.solve(np.column_stack(columns), -base)


def _affine_flow(truth: Mapping[str, float], masses: int) -> tuple[np.ndarray, np.ndarray]:
    """``(F, G)`` with ``d/dt [x; v] = F [x; v] + G [eta, p, 1]``, read off the force balance
    (:func:`_forces` is affine in heights, velocities and inputs, so unit perturbations give
    its coefficients exactly); saves the interpreted force loop at every solver stage."""
    mass = np.array([truth[f"m{i + 1}"] for i in range(masses)])
    zero = np.zeros(masses)

    def acceleration(x: np.ndarray, v: np.ndarray, eta: float, p: float) -> np.ndarray:
        return _forces(truth, masses, x, v, eta, p) / mass

    base = acceleration(zero, zero, 0.0, 0.0)
    unit = np.eye(masses)
    by_x = [acceleration(unit[j], zero, 0.0, 0.0) - base for j in range(masses)]
    by_v = [acceleration(zero, unit[j], 0.0, 0.0) - base for j in range(masses)]
    by_u = [acceleration(zero, zero, 1.0, 0.0) - base, acceleration(zero, zero, 0.0, 1.0) - base,
            base]
    flow = np.block([[np.zeros((masses, masses)), np.eye(masses)],
                     [np.column_stack(by_x), np.column_stack(by_v)]])
    forcing = np.vstack([np.zeros((masses, 3)), np.column_stack(by_u)])
    return flow, forcing


def simulate_oscillator(truth: Mapping[str, float], time: np.ndarray, eta: np.ndarray,
                        pressure: np.ndarray, *, rtol: float = 1e-10,
                        atol: float = 1e-12) -> dict[str, np.ndarray]:
    """Clean outputs of the oscillator plant for sampled inputs (linear between samples).

    Parameters
    ----------
    truth : mapping
        Parameters as :func:`draw_oscillator_truth` gives them; the number of masses is that of
        the ``m_i`` keys.
    time : ndarray
        Sample times [s].
    eta : ndarray
        Wire height [m] at the sample times.
    pressure : ndarray
        Bellow pressure [bar] at the sample times.
    rtol, atol : float
        Tolerances of :func:`scipy.integrate.solve_ivp` (DOP853); ``atol`` in metres and m/s.

    Returns
    -------
    dict
        ``y_cb`` [m], ``xi`` [m], ``F_c`` [N] at the sample times.
    """
    masses = sum(1 for name in truth if name.startswith("m") and name[1:].isdigit())
    x0 = _equilibrium(truth, masses, float(eta[0]), float(pressure[0]))
    flow, forcing = _affine_flow(truth, masses)
    period = float(time[1] - time[0])
    inputs = np.column_stack([eta, pressure, np.ones_like(eta)])
    slopes = np.vstack([np.diff(inputs, axis=0) / period, np.zeros((1, 3))])

    kinks = np.flatnonzero(np.any(np.diff(slopes[:-1], axis=0) != 0.0, axis=1)) + 1
    edges = np.unique(np.concatenate([[0], kinks, [len(time) - 1]]))
    states = np.empty((2 * masses, len(time)))
    states[:, 0] = np.concatenate([x0, 0 * x0])
    for first, last in zip(edges[:-1], edges[1:]):  # inputs linear within: no kink inside
        start, slope = inputs[first], slopes[first]

        def rhs(t: float, state: np.ndarray, t0: float = time[first], start: np.ndarray = start,
                slope: np.ndarray = slope) -> np.ndarray:
            return flow @ state + forcing @ (start + (t - t0) * slope)

        solution = solve_ivp(rhs, (float(time[first]), float(time[last])), states[:, first],
                             method="DOP853", t_eval=time[first + 1:last + 1], rtol=rtol,
                             atol=atol, first_step=period * (1.0 - 1e-9))
        if not solution.success:
            raise RuntimeError(f"oscillator plant: integration failed ({solution.message})")
        states[:, first + 1:last + 1] = solution.y
    x = states[:masses]
    return {"y_cb": x[masses - 2] + truth["y_cb_offset"], "xi": x[masses - 1],
            "F_c": truth["k_E"] * (x[masses - 1] - eta)}


def add_noise(clean: Mapping[str, np.ndarray], snr_db: float,
              rng: np.random.Generator) -> tuple[dict[str, np.ndarray], dict[str, float]]:
    """White Gaussian noise on every output at `snr_db` [dB] (of the output's own standard
    deviation); returns the noisy outputs and the noise standard deviations (output units)."""
    sigma = {name: float(np.std(y)) * 10.0 ** (-snr_db / 20.0) for name, y in clean.items()}
    noisy = {name: y + rng.normal(0.0, sigma[name], len(y)) for name, y in clean.items()}
    return noisy, sigma


def oscillator_case(family: str, excitation: str, seed: int, *, snr_db: float = 30.0,
                    spread: float = 1.3, duration: float | None = None) -> PlantRecord:
    """One noisy experiment of the ``"two-mass"`` or ``"three-mass"`` family (module notes).

    Parameters
    ----------
    family : {"two-mass", "three-mass"}
    excitation : {"aprbs", "multisine", "chirp"}
    seed : int
        Seeds the truth, the excitation and the noise.
    snr_db : float
        Signal-to-noise ratio [dB] of every output.
    spread : float
        Factor of the truth's log-uniform draw.
    duration : float, optional
        Override the excitation's length [s].
    """
    rng = np.random.default_rng([seed, MASSES_OF_FAMILY[family],
                                 sorted(EXCITATIONS).index(excitation)])
    truth = draw_oscillator_truth(MASSES_OF_FAMILY[family], rng, spread)
    time, eta, pressure = excitation_inputs(excitation, rng, duration=duration)
    clean = simulate_oscillator(truth, time, eta, pressure)
    clean = {name: clean[name] for name in ("F_c", "y_cb")}
    noisy, sigma = add_noise(clean, snr_db, rng)
    rate = float(1.0 / (time[1] - time[0]))
    notes = {"family": family, "excitation": excitation, "seed": seed, "snr_db": snr_db,
             "rate_hz": rate, "duration_s": len(time) / rate, "noise_std": sigma,
             "independent": True}
    return PlantRecord(time, {"eta": eta, "p": pressure}, noisy, clean, truth, notes)


def record_to_data(record: PlantRecord, data_class: Callable[..., Any]) -> Any:
    """The record as identification data (`data_class`: the library's ``IdentificationData``).

    Inputs ``eta`` [m], ``p`` [bar]; outputs ``F_c`` [N], ``y_cb`` [m].
    """
    names = tuple(record.outputs)
    return data_class(record.time, np.column_stack([record.inputs["eta"], record.inputs["p"]]),
                      np.column_stack([record.outputs[n] for n in names]), ("eta", "p"), names,
                      {"eta": "m", "p": "bar", "F_c": "N", "y_cb": "m"},
                      f"{record.notes['family']}/{record.notes['excitation']}/seed {record.notes['seed']}")


# --- the physical pantograph on the virtual test bed -----------------------------------------

#: Table 4.1's parameters drawn for the physical pantograph's truth.
PANTOGRAPH_DRAWN = ("m1", "m2", "m3", "m4", "m_c", "c1", "c2", "c3", "c_c", "k", "k_c", "k_ph", "k_p")


def draw_pantograph_truth(rng: np.random.Generator, spread: float = 1.3) -> dict[str, float]:
    """Table 4.1 (the FMU's defaults) with its 13 parameters drawn log-uniform within `spread`."""
    from panto.fmu_src.models import default_parameters

    values = default_parameters("Pantograph").values
    return {name: _log_uniform(rng, float(values[name]), spread) for name in PANTOGRAPH_DRAWN}


def pantograph_case(excitation: str, seed: int, *, spread: float = 1.3, rate: float = 100.0,
                    folder: str | Path | None = None) -> tuple[Any, dict[str, float], dict[str, Any]]:
    """Identification data from the virtual test bed without imperfections (module notes).

    Parameters
    ----------
    excitation : {"aprbs", "multisine", "chirp"}
        Picks the rig profile (``aprbs_training``, ``multisine_odd``, ``chirp_log``).
    seed : int
        Seeds the truth (and the bed, which has no noise here).
    spread : float
        Factor of the truth's log-uniform draw around Table 4.1.
    rate : float
        Identification rate [Hz] of :func:`pantograph_data`.
    folder : path, optional
        Where the run is recorded (default a fresh temporary folder).

    Returns
    -------
    data : IdentificationData
        Inputs ``eta`` [m], ``p`` [bar]; outputs ``F_c`` [N], ``y_cb`` [m].
    truth : dict
        The 13 drawn parameters.
    notes : dict
    """
    from panto.build_fmu.project import project_fmu
    from panto.identification.data.datasets import pantograph_data
    from panto.rig.imperfections import RigImperfections
    from panto.rig.profiles import load_profile
    from panto.rig.virtual import run_virtual_profile

    spec = EXCITATIONS[excitation]
    rng = np.random.default_rng([seed, 13, sorted(EXCITATIONS).index(excitation)])
    truth = draw_pantograph_truth(rng, spread)
    profiles = Path(__file__).resolve().parent.parent / "rig" / "profiles"
    profile = load_profile(profiles / f"{spec.profile}.json")
    profile = replace(profile, duration=min(profile.duration, spec.profile_duration))
    folder = Path(folder) if folder is not None else \
        Path(tempfile.mkdtemp(prefix="panto-recovery-")) / "run"
    run_virtual_profile(profile, fmu_path=project_fmu("Pantograph"), folder=folder,
                        imperfections=RigImperfections.none(), parameters=truth, seed=seed)
    data = pantograph_data(folder, rate=rate)
    notes = {"family": "pantograph", "excitation": excitation, "seed": seed, "snr_db": None,
             "rate_hz": rate, "duration_s": float(data.time[-1] - data.time[0]),
             "profile": spec.profile, "run_folder": str(folder), "independent": False}
    return data, truth, notes
