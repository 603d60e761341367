"""Two- and three-mass oscillators as identification structures (thesis sections 2.6, 2.7, 4.6, 4.7).

The model is the one of :mod:`panto.fmu_src.oscillators` (masses numbered from the bottom; the top mass
is the head, tied to the input ``eta`` by the carbon-contact spring ``k_E``; the bellow force
``p_gain p + F_0`` acts on the lowest mass; springs relaxed at the height ``y_0``), with the
deflections ``z = x - y_0``::

    M z'' + C z' + K z = e_1 (p_gain p + F_0) + e_n k_E (eta - y_0) - F_f tanh(z' / v_eps)

    y_cb = z_{n-1} + y_0 + y_cb_offset,   xi = z_n + y_0,   F_c = k_E (z_n + y_0 - eta)

(``K`` and ``C`` the chain matrices, ``k_E`` added to ``K[n, n]``). The contact is bilateral as in
the thesis (eq. 2.33/2.34). ``y_cb_offset`` is the one parameter the FMU model lacks: the rig
measures the cross bar and the head at heights whose difference at rest is set by geometry (the
head suspension's rest length), which the oscillator's springs (all relaxed at ``y_0``) cannot
produce; it is zero for data simulated by the FMUs. This module assembles these matrices itself with numpy: the symbolic
model in :mod:`fmu_src` is the independent path the tests compare against.

Simulation (free run, initial state = static equilibrium at the first input sample):

- without friction the model is linear and is discretised exactly for inputs that are linear
  between samples (first-order hold, the FMUs' input convention; ``hold="zoh"`` for steps):
  the block exponential ``expm([[A, B, 0], [0, 0, I], [0, 0, 0]] T)`` gives ``Phi``, ``Gamma_0``,
  ``Gamma_1`` and ``x[k+1] = Phi x[k] + Gamma_0 u[k] + Gamma_1 (u[k+1] - u[k])`` (Franklin,
  Powell & Workman, *Digital Control of Dynamic Systems*, sec. 6.3). The recursion runs as one
  first-order IIR filter per eigenvalue of ``Phi`` (``scipy.signal.lfilter``'s operations,
  compiled).
- with Coulomb friction, Strang splitting on ``substeps`` sub-steps per sample: half a step of the
  friction flow, a full step of the exact linear flow (first-order hold on the sub-step), half a
  step of friction. The friction flow ``m v' = -F_f tanh(v / v_eps)`` has the closed-form solution
  ``sinh(v(t) / v_eps) = sinh(v(0) / v_eps) exp(-F_f t / (m v_eps))``, so the stiff friction
  term never limits the step: the scheme is second order and unconditionally stable. The
  sub-step loop is compiled C (:mod:`panto.identification.structures.friction_kernel`, its
  Python reference loop where no compiler is found).
"""
from __future__ import annotations

import math
from typing import Any, Callable, Mapping, Sequence

import numpy as np
from scipy import linalg

from panto.identification.estimation.base import (IdentificationData, IdentificationError, IdentificationResult,
                                 ModelStructure)
from panto.identification.structures import friction_kernel
from panto.identification.structures.linearisation import mode_filter

#: Model inputs and the outputs a structure can simulate.
INPUT_NAMES = ("eta", "p")
OUTPUT_NAMES = ("y_cb", "xi", "F_c")
#: The exact accelerations [m/s^2] of the bar's mass (``y_cb''``) and the head's (``xi''``) an
#: oscillator without friction simulates besides its outputs (``A x + B u`` at each sample; the
#: diagnosis' sensor mass follows them where the sensor's position is not measured but simulated).
ACCELERATIONS = ("y_cb''", "xi''")
#: Default fitted outputs (the thesis' two objectives).
DEFAULT_OUTPUTS = ("F_c", "y_cb")

#: Nominal values per number of masses (bottom to top); EN 50318 two-mass, Bruni three-mass.
_NOMINAL = {
    2: {"m": (15.0, 7.2), "k": (50.0, 4200.0), "c": (90.0, 10.0)},
    3: {"m": (6.0, 9.0, 7.5), "k": (160.0, 15500.0, 7000.0), "c": (100.0, 10.0, 10.0)},
}
#: Friction structures: integration sub-steps per sample (Strang splitting, see module notes).
SUBSTEPS = 16


class OscillatorStructure(ModelStructure):
    """An n-mass oscillator (n = 2 or 3), optionally with Coulomb friction on every mass.

    Parameters
    ----------
    masses : int
        2 or 3.
    friction : bool
        Add ``F_f,i tanh(v_i / v_eps)`` on every mass (eq. 2.35 smoothed).
    outputs : sequence of str
        Simulated outputs, any of ``("y_cb", "xi", "F_c")``.
    hold : {"foh", "zoh"}
        Input interpolation between samples (linear or held).
    substeps : int
        Friction structures: integration sub-steps per sample (Strang splitting).
    """

    input_names = INPUT_NAMES

    @property
    def simulable_outputs(self) -> tuple[str, ...]:
        """Every output the structure can simulate (``output_names`` picks the fitted ones):
        without friction also the exact accelerations :data:`ACCELERATIONS`."""
        return OUTPUT_NAMES + (() if self.friction else ACCELERATIONS)

    def __init__(self, masses: int, friction: bool = False, *,
                 outputs: Sequence[str] = DEFAULT_OUTPUTS, hold: str = "foh", substeps: int = SUBSTEPS):
        if masses not in _NOMINAL:
            raise IdentificationError(f"oscillator with {masses} masses is not defined (2 or 3)")
        unknown = [o for o in outputs if o not in OUTPUT_NAMES]
        if unknown or not outputs:
            raise IdentificationError(f"oscillator outputs {list(outputs)}: choose from {OUTPUT_NAMES}")
        if hold not in ("foh", "zoh"):
            raise IdentificationError(f"hold {hold!r}: choose 'foh' or 'zoh'")
        if substeps < 1:
            raise IdentificationError(f"substeps {substeps}: must be at least 1")
        self.masses = masses
        self.friction = bool(friction)
        self.hold = hold
        self.substeps = int(substeps)
        words = {2: "two", 3: "three"}[masses]
        self.name = f"{words}-mass" + ("-friction" if friction else "")
        self.output_names = tuple(outputs)
        names = [f"{s}{i + 1}" for s in ("m", "k", "c") for i in range(masses)]
        names += ["k_E", "p_gain", "F_0", "y_0", "y_cb_offset"]
        if friction:
            names += [f"F_f{i + 1}" for i in range(masses)] + ["v_eps"]
        self.parameter_names = tuple(names)

    @property
    def input_refinement(self) -> bool:
        """Continuous time, exact discretisation: refinable when inputs are linear between
        samples (``hold="foh"``)."""
        return self.hold == "foh"

    def nominal(self) -> dict[str, float]:
        """EN 50318 / Bruni values, a pressure gain of 100 N/bar and the relaxed height 2 m."""
        d = _NOMINAL[self.masses]
        values = {f"{s}{i + 1}": float(d[s][i]) for s in ("m", "k", "c") for i in range(self.masses)}
        values.update(k_E=50000.0, p_gain=100.0, F_0=-300.0, y_0=2.0, y_cb_offset=0.0)
        if self.friction:
            values.update({f"F_f{i + 1}": 1.0 for i in range(self.masses)}, v_eps=1e-3)
        return values

    def bounds(self) -> dict[str, tuple[float, float]]:
        """Physically plausible ranges (masses 0.1-500 kg, stiffness up to 1e6 N/m, ...).

        Masses, stiffnesses and dampers have positive lower bounds so that the estimator works
        on their logarithms (relative steps and uncertainties).
        """
        b: dict[str, tuple[float, float]] = {}
        for i in range(1, self.masses + 1):
            b.update({f"m{i}": (0.1, 500.0), f"k{i}": (0.1, 1e6), f"c{i}": (0.01, 1e4)})
        b.update(k_E=(1e3, 1e6), p_gain=(-1e4, 1e4), F_0=(-1e5, 1e5), y_0=(-10.0, 10.0),
                 y_cb_offset=(-1.0, 1.0))
        if self.friction:
            b.update({f"F_f{i}": (0.0, 500.0) for i in range(1, self.masses + 1)})
            b["v_eps"] = (1e-5, 0.1)
        return b

    def units(self) -> dict[str, str]:
        """Unit of every parameter (masses kg, springs N/m, dampers N s/m, ``p_gain`` N/bar, ...)."""
        kinds = {"m": "kg", "k": "N/m", "c": "N s/m", "F": "N"}
        fixed = {"k_E": "N/m", "p_gain": "N/bar", "F_0": "N", "y_0": "m", "y_cb_offset": "m",
                 "v_eps": "m/s"}
        return {n: fixed[n] if n in fixed else kinds[n[0]] for n in self.parameter_names}

    def default_free(self) -> tuple[str, ...]:
        """Masses, springs, dampers, ``p_gain``, ``F_0`` (+ ``y_cb_offset`` when ``y_cb`` is an
        output, + the friction forces).

        ``k_E`` stays at 50 000 N/m (EN 50318, section 4.5), ``v_eps`` at 1 mm/s, and ``y_0``
        at its start value: only ``F_0 + k_1 y_0`` is identifiable (shifting ``y_0`` by ``d``
        and ``F_0`` by ``-k_1 d`` moves every deflection by ``-d`` and leaves the outputs as
        they are, since only the base spring has its rest length at ``y_0``).
        """
        skip = {"k_E", "v_eps", "y_0"} | ({"y_cb_offset"} if "y_cb" not in self.output_names
                                          else set())
        return tuple(n for n in self.parameter_names if n not in skip)

    @property
    def model_name(self) -> str:
        """The fmu_src model (and FMU) of this structure: ``"TwoMass"`` or ``"ThreeMass"``."""
        return {2: "TwoMass", 3: "ThreeMass"}[self.masses]

    def fmu_parameters(self, parameters: Mapping[str, float]) -> dict[str, float]:
        """Values for the FMU / :class:`panto.fmu_src.models.Model` (``y_cb_offset`` is not a model
        parameter: subtract it from the simulated ``y_cb``). Without friction, ``F_f,i`` = 0."""
        values = self.values(parameters)
        values.pop("y_cb_offset")
        return values

    # --- model ------------------------------------------------------------------------------

    def values(self, parameters: Mapping[str, float]) -> dict[str, float]:
        """Nominal values overridden by `parameters`; unknown names and bad values raise."""
        names, nominal = self._defaults()
        if not names.issuperset(parameters):
            raise IdentificationError(f"{self.name}: unknown parameters "
                                      f"{sorted(set(parameters) - names)}")
        values = {**nominal, **{k: float(v) for k, v in parameters.items()}}
        bad = [k for k, v in values.items() if not math.isfinite(v)]
        bad += [f"m{i}" for i in range(1, self.masses + 1) if values[f"m{i}"] <= 0]
        if self.friction:
            bad += [f"F_f{i}" for i in range(1, self.masses + 1) if values[f"F_f{i}"] < 0]
            bad += ["v_eps"] if values["v_eps"] <= 0 else []
        if bad:
            raise IdentificationError(f"{self.name}: invalid parameter values "
                                      f"{ {k: values[k] for k in bad} }")
        return values

    def _defaults(self) -> tuple[frozenset, dict[str, float]]:
        """The parameter names and :meth:`nominal`, computed once per instance (read only: this
        runs for every column of the frequency mapping's Jacobians)."""
        cached = self.__dict__.get("_defaults_cache")
        if cached is None or cached[0] != self.parameter_names:
            cached = self.__dict__["_defaults_cache"] = (
                self.parameter_names, frozenset(self.parameter_names), self.nominal())
        return cached[1], cached[2]

    def matrices(self, parameters: Mapping[str, float]) -> tuple[np.ndarray, ...]:
        """Continuous ``(A, B, C, D)`` for the state ``[z; v]``, inputs ``(eta, p, 1)``, all outputs.

        The constant third input carries ``F_0`` and ``y_0``; ``C``, ``D`` rows are ``y_cb``,
        ``xi``, ``F_c``.
        """
        v = self.values(parameters)
        n = self.masses
        mass = [v[f"m{i + 1}"] for i in range(n)]
        stiffness = _chain_rows([v[f"k{i + 1}"] for i in range(n)])
        damping = _chain_rows([v[f"c{i + 1}"] for i in range(n)])
        k_e, y_0 = v["k_E"], v["y_0"]
        stiffness[-1][-1] += k_e
        forcing = [[0.0] * 3 for _ in range(n)]
        forcing[-1][0] = k_e
        forcing[0][1] = v["p_gain"]
        forcing[0][2] = v["F_0"]
        forcing[-1][2] -= k_e * y_0
        # assembled from Python floats, one array per matrix (numpy's small-array operations
        # cost more than the arithmetic: this runs for every column of the frequency mapping's
        # Jacobians); every entry is the same IEEE operation as the matrix form's, ``-K / m``
        # and ``-C / m`` row by row
        a = [[float(j == n + i) for j in range(2 * n)] for i in range(n)]
        a += [[-s / mass[i] for s in stiffness[i]] + [-c / mass[i] for c in damping[i]]
              for i in range(n)]
        b = [[0.0] * 3 for _ in range(n)] + [[f / mass[i] for f in forcing[i]] for i in range(n)]
        c = [[0.0] * (2 * n) for _ in range(3)]
        c[0][n - 2] = c[1][n - 1] = 1.0
        c[2][n - 1] = k_e
        d = [[0.0, 0.0, y_0 + v["y_cb_offset"]], [0.0, 0.0, y_0], [-k_e, 0.0, k_e * y_0]]
        return np.array(a), np.array(b), np.array(c), np.array(d)

    def linear_system(self, parameters: Mapping[str, float], data: IdentificationData
                      ) -> tuple[np.ndarray, ...]:
        """Continuous ``(A, B, C, D)`` from `data`'s inputs to `data`'s outputs (their units).

        The model without friction is linear; the constant input carrying ``F_0``, ``y_0`` and
        ``y_cb_offset`` only shifts the outputs and is left out (an affine offset does not change
        the frequency response). Raises NotImplementedError with friction (not linear).
        """
        if self.friction:
            raise NotImplementedError(f"{self.name}: Coulomb friction is not linear")
        a, b, c, d = self.matrices(parameters)
        inputs = [self._position(INPUT_NAMES, n, "input") for n in data.input_names]
        rows = [self._position(OUTPUT_NAMES + ACCELERATIONS, n, "output")
                for n in data.output_names]
        if any(row >= len(OUTPUT_NAMES) for row in rows):
            c, d = self._with_accelerations(a, b, c, d)
        return a, b[:, inputs], c[rows], d[rows][:, inputs]

    def _with_accelerations(self, a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray
                            ) -> tuple[np.ndarray, np.ndarray]:
        """``C``, ``D`` with the rows of :data:`ACCELERATIONS` below the outputs': the bar's and
        the head's velocity rows of ``A x + B u``."""
        rows = [2 * self.masses - 2, 2 * self.masses - 1]
        return np.concatenate((c, a[rows])), np.concatenate((d, b[rows]))

    def _position(self, names: Sequence[str], name: str, role: str) -> int:
        if name not in names:
            raise IdentificationError(f"{self.name}: no {role} {name!r} (has {list(names)})")
        return list(names).index(name)

    @staticmethod
    def _chain(values: Sequence[float]) -> np.ndarray:
        """Chain matrix of springs (or dampers) base-1, 1-2, ..., (n-1)-n."""
        return np.array(_chain_rows(values), float)

    def equilibrium(self, parameters: Mapping[str, float], eta: float, p: float) -> np.ndarray:
        """Static equilibrium state ``[z; 0]`` for constant inputs (friction is zero at rest)."""
        a, b, _, _ = self.matrices(parameters)
        return self._rest(a, b, eta, p)

    def _rest(self, a: np.ndarray, b: np.ndarray, eta: float, p: float) -> np.ndarray:
        """The linear model ``(a, b)``'s static state for constant inputs."""
        right = b @ np.array([eta, p, 1.0])
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(right))):
            raise IdentificationError(f"{self.name}: no static equilibrium (the matrices are not "
                                      "finite)")
        try:  # NumPy's solve: the same LAPACK routine as SciPy's without its checks (90 us)
            x0 = -np.linalg.solve(a, right)
        except np.linalg.LinAlgError as error:
            raise IdentificationError(f"{self.name}: no static equilibrium ({error})") from error
        return x0

    # --- simulation ---------------------------------------------------------------------------

    def simulate(self, parameters: Mapping[str, float], data: IdentificationData) -> np.ndarray:
        """Free-run outputs on `data`'s inputs, shape ``(len(data), len(self.output_names))``."""
        u = np.column_stack([data.input(name) for name in INPUT_NAMES] + [np.ones(len(data))])
        return self.simulate_inputs(parameters, u, data.sample_period)

    def states(self, parameters: Mapping[str, float], data: IdentificationData) -> np.ndarray:
        """The free run's states ``[z; z']`` (deflections [m], velocities [m/s], masses from the
        bottom) on `data`'s inputs, shape ``(len(data), 2 masses)``."""
        u = np.column_stack([data.input(name) for name in INPUT_NAMES] + [np.ones(len(data))])
        return self._states(parameters, u, data.sample_period)

    def _states(self, parameters: Mapping[str, float], u: np.ndarray, period: float,
                system: tuple[np.ndarray, ...] | None = None) -> np.ndarray:
        """The free run's states; `system`: ``self.matrices(parameters)`` when the caller has
        them already."""
        a, b, _, _ = self.matrices(parameters) if system is None else system
        v = self.values(parameters)
        # the linear model's own rest (a subclass with nonlinear springs rests elsewhere, and its
        # linear states would start moving)
        x0 = self._rest(a, b, u[0, 0], u[0, 1])
        if self.friction:
            friction = np.array([v[f"F_f{i + 1}"] / v[f"m{i + 1}"] for i in range(self.masses)])
            return _simulate_friction(a, b, u, x0, period, self.substeps, self.hold,
                                      friction, v["v_eps"])
        phi, gamma0, gamma1 = discretise(a, b, period, self.hold)
        drive = u[:-1] @ gamma0.T + np.diff(u, axis=0) @ gamma1.T
        return propagate(phi, drive, x0)

    def simulate_inputs(self, parameters: Mapping[str, float], u: np.ndarray,
                        period: float) -> np.ndarray:
        """Free run for input samples ``u`` (columns eta, p, 1) every `period` seconds."""
        a, b, c, d = system = self.matrices(parameters)
        v = self.values(parameters)
        states = self._states(parameters, u, period, system)
        if any(o in ACCELERATIONS for o in self.output_names):
            if self.friction:
                raise IdentificationError(f"{self.name}: no exact acceleration with friction")
            c, d = self._with_accelerations(a, b, c, d)
        rows = [(OUTPUT_NAMES + ACCELERATIONS).index(o) for o in self.output_names]
        y = states @ c[rows].T + u @ d[rows].T
        if not np.all(np.isfinite(y)):
            raise IdentificationError(f"{self.name}: simulation diverged for {dict(v)}")
        return y


def _chain_rows(values: Sequence[float]) -> list[list[float]]:
    """The chain matrix of springs (or dampers) base-1, 1-2, ..., (n-1)-n as nested lists (each
    value added to its two masses' diagonal entries and taken from their coupling entries; as
    Python floats where :meth:`OscillatorStructure.matrices` assembles from them)."""
    n = len(values)
    out = [[0.0] * n for _ in range(n)]
    out[0][0] = values[0]
    for i in range(1, n):
        out[i][i] += values[i]
        out[i - 1][i - 1] += values[i]
        out[i][i - 1] -= values[i]
        out[i - 1][i] -= values[i]
    return out


def discretise(a: np.ndarray, b: np.ndarray, period: float,
               hold: str = "foh") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact discretisation ``(Phi, Gamma_0, Gamma_1)`` for held or linearly interpolated inputs.

    ``x[k+1] = Phi x[k] + Gamma_0 u[k] + Gamma_1 (u[k+1] - u[k])``; ``Gamma_1 = 0`` for "zoh".
    """
    n, m = b.shape
    block = np.zeros((n + 2 * m, n + 2 * m))
    block[:n, :n] = a * period
    block[:n, n:n + m] = b * period
    block[n:n + m, n + m:] = np.eye(m)
    e = linalg.expm(block)
    gamma1 = e[:n, n + m:] if hold == "foh" else np.zeros((n, m))
    return e[:n, :n], e[:n, n:n + m], gamma1


def propagate(phi: np.ndarray, drive: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """States of ``x[k+1] = Phi x[k] + drive[k]`` from ``x0``, shape ``(len(drive) + 1, n)``.

    Runs as one first-order filter per eigenvalue of ``Phi`` (modal coordinates) when the
    eigenvectors are well conditioned, otherwise as a plain loop. The filter is
    :func:`~panto.identification.structures.linearisation.mode_filter` (compiled, bit for bit
    :func:`scipy.signal.lfilter`, which runs without a compiler) and the modal solves NumPy's
    (the same LAPACK routine as SciPy's without its checks): the same values as before, a third
    faster. :func:`~panto.identification.structures.linearisation.propagate` runs a complex pair
    once and is faster still, but its values differ in the last digits, and two seen diagnosis
    cases whose searches sit on a knife edge change their outcome with them (session 49: seen
    held-out three-mass/actuator_lag/2120 and three-mass/sign_blind_sensor/3477).
    """
    eigenvalues, vectors = linalg.eig(phi)
    if np.linalg.cond(vectors) < 1e8:
        modal_drive = np.linalg.solve(vectors, drive.T.astype(complex)).T
        z0 = np.linalg.solve(vectors, x0.astype(complex))
        modal = np.empty((len(drive) + 1, len(x0)), complex)
        for i, lam in enumerate(eigenvalues):
            modal[:, i] = mode_filter(lam, modal_drive[:, i], z0[i])
        return np.real(modal @ vectors.T)
    states = np.empty((len(drive) + 1, len(x0)))
    states[0] = x0
    for k in range(len(drive)):
        states[k + 1] = phi @ states[k] + drive[k]
    return states


def coulomb_flow(velocity: np.ndarray, decay: np.ndarray, v_eps: float) -> np.ndarray:
    """Exact flow of ``v' = -(F_f / m) tanh(v / v_eps)`` over a time ``t``.

    ``decay = F_f t / (m v_eps)``; ``sinh(v(t) / v_eps) = sinh(v(0) / v_eps) exp(-decay)``.
    Beyond ``|v| / v_eps = 700`` (where ``sinh`` overflows and ``tanh`` is 1 to machine
    precision) the velocity change of the flow started at 700 is used, which is then exact.
    """
    a = np.clip(np.asarray(velocity, float) / v_eps, -700.0, 700.0)
    return velocity + v_eps * (np.arcsinh(np.sinh(a) * np.exp(-decay)) - a)


def _simulate_friction(a: np.ndarray, b: np.ndarray, u: np.ndarray, x0: np.ndarray,
                       period: float, substeps: int, hold: str, friction: np.ndarray,
                       v_eps: float) -> np.ndarray:
    """Strang splitting ``F(h/2) L(h) F(h/2)`` per sub-step; adjacent half steps merged.

    The sub-step loop runs compiled when a C compiler is at hand
    (:mod:`panto.identification.structures.friction_kernel`), else in Python; both the same.
    """
    n = len(x0) // 2
    h = period / substeps
    phi, gamma0, gamma1 = discretise(a, b, h, hold)
    du = np.diff(u, axis=0) if hold == "foh" else np.zeros_like(u[:-1])
    fractions = np.arange(substeps) / substeps
    # drive[k, j] for sub-step j of sample interval k (inputs linear within the interval):
    # Gamma_0 (u_k + j/s du_k) + Gamma_1 du_k / s, as two products per sample and one sum
    level = u[:-1] @ gamma0.T + (du / substeps) @ gamma1.T
    slope = du @ gamma0.T
    drive = (level[:, None, :] + fractions[None, :, None] * slope[:, None, :]).reshape(-1, 2 * n)
    half = np.exp(-friction * (h / 2.0) / v_eps)
    full = half * half
    states = np.empty((len(u), 2 * n))
    states[0] = x0
    x = x0.copy()
    with np.errstate(divide="ignore"):  # half underflows to 0 for a friction far above
        # v_eps / h: -log(0) = inf, and the flow over an infinite decay stops the velocity
        x[n:] = coulomb_flow(x[n:], -np.log(half), v_eps)
    friction_kernel.run(phi, drive, x, substeps, half, full, v_eps, states)
    return states


# --- identification ---------------------------------------------------------------------------

def offset_start(structure: OscillatorStructure, data: IdentificationData,
                 parameters: Mapping[str, float] | None = None) -> dict[str, float]:
    """Start values of ``p_gain``, ``F_0``, ``y_cb_offset`` by linear least squares.

    The linear oscillator's outputs are affine in these three (with the other parameters at
    `parameters` or nominal): ``y = y_0 + p_gain y_p + F_0 y_F + y_cb_offset y_o``, so four simulations
    and one least-squares solve (residuals normalised per output as the fit metric) put the
    force level and the height where the data are before the nonlinear fit starts.
    """
    linear = OscillatorStructure(structure.masses, False, outputs=data.output_names)
    base = {k: v for k, v in {**linear.nominal(), **dict(parameters or {})}.items()
            if k in linear.parameter_names}
    unit = {"p_gain": 0.0, "F_0": 0.0, "y_cb_offset": 0.0}
    y_eta = linear.simulate({**base, **unit}, data)
    columns = [linear.simulate({**base, **unit, name: 1.0}, data) - y_eta for name in unit]
    y = data.outputs
    ok = np.all(np.isfinite(y), axis=1)
    scale = np.array([np.linalg.norm(y[ok, j] - y[ok, j].mean()) or 1.0 for j in range(y.shape[1])])
    regressors = np.column_stack([(c[ok] / scale).ravel() for c in columns])
    target = ((y[ok] - y_eta[ok]) / scale).ravel()
    solution, *_ = np.linalg.lstsq(regressors, target, rcond=None)
    return dict(zip(unit, solution.tolist()))


def identify_oscillator(data: IdentificationData, *, masses: int, friction: bool,
                        executor: Any = None, progress: Callable[[str], None] | None = None,
                        free: Sequence[str] | None = None,
                        fixed: Mapping[str, float] | None = None,
                        initial: Mapping[str, float] | None = None,
                        method: str = "lm", outputs: Sequence[str] | None = None,
                        hold: str = "foh", substeps: int = SUBSTEPS,
                        **options: Any) -> IdentificationResult:
    """Fit an oscillator structure (thesis 4.6, 4.7) to `data`.

    Parameters
    ----------
    data : IdentificationData
        Inputs ``eta`` [m], ``p`` [bar]; outputs among ``y_cb``, ``xi``, ``F_c``.
    masses : {2, 3}
    friction : bool
    free : sequence of str, optional
        Default :meth:`OscillatorStructure.default_free` (all but ``k_E`` and ``v_eps``).
    fixed : mapping, optional
        Values of parameters that are not estimated (e.g. ``{"k_E": 50000.0}``).
    initial : mapping, optional
        Start values; ``p_gain``, ``F_0``, ``y_cb_offset`` not given here or in `fixed` start
        from :func:`offset_start`; ``y_0`` defaults to the first ``eta`` sample.
    method : {"lm", "nsga2"}
        :func:`panto.identification.estimation.least_squares.fit_least_squares` or the Pareto search of
        :mod:`panto.identification.estimation.genetic` (picked knee solution, polished).
    outputs : sequence of str, optional
        Outputs to fit (default those of ``("F_c", "y_cb")`` present in `data`).
    hold, substeps
        See :class:`OscillatorStructure`.
    **options
        Passed to the estimator (``max_evaluations``, ``multistart``, ``rng``, ``global_fit``:
        :class:`~panto.identification.estimation.global_fit.GlobalFitOptions` for
        :func:`~panto.identification.estimation.global_fit.fit_global`, ...); ``adequacy=True``
        adds :func:`~panto.identification.structures.adequacy.with_adequacy` (``"lm"`` only;
        with ``global_fit`` its black box is fitted first and the data-driven starts match its
        response: :func:`~panto.identification.structures.adequacy.reference_for`).
    """
    outputs = tuple(outputs or [o for o in DEFAULT_OUTPUTS if o in data.output_names])
    structure = OscillatorStructure(masses, friction, outputs=outputs, hold=hold, substeps=substeps)
    data = data.select_outputs(outputs)
    fixed = dict(fixed or {})
    free = tuple(free) if free is not None else structure.default_free()
    clash = sorted(set(free) & set(fixed))
    if clash:
        raise IdentificationError(f"{structure.name}: parameter(s) {clash} are both free and fixed")
    start = {**fixed, **dict(initial or {})}
    start.setdefault("y_0", float(data.input("eta")[0]))  # F_0 is then the force at that height
    wanted = [n for n in ("p_gain", "F_0", "y_cb_offset") if n in free and n not in start]
    if wanted:
        guess = offset_start(structure, data, start)
        start.update({n: guess[n] for n in wanted})
        if progress:
            progress(f"{structure.name}: start " + ", ".join(f"{n} = {start[n]:.4g}" for n in wanted))
    bounds = structure.bounds()
    for name in wanted:  # widen a bound the static start falls outside of
        low, high = bounds[name]
        bounds[name] = (min(low, start[name]), max(high, start[name]))
    adequacy = bool(options.pop("adequacy", False))
    if method == "lm":
        from panto.identification.structures.adequacy import fit_checked

        result = fit_checked(structure, data, {**structure.nominal(), **start}, adequacy,
                             progress=progress, free=free, initial=start, bounds=bounds,
                             executor=executor, **options)
    elif method == "nsga2":
        result = _identify_pareto(structure, data, free, start, bounds, executor, progress,
                                  options)
    else:
        raise IdentificationError(f"unknown method {method!r}: 'lm' or 'nsga2'")
    return _with_levels(result)


def _with_levels(result: IdentificationResult) -> IdentificationResult:
    """The result saying how the levels are handled: physically, by ``y_0`` (the springs' rest
    height, held at its start: the first ``eta`` sample unless given) and the estimated
    ``F_0``, ``y_cb_offset``; nothing is removed from the data."""
    from dataclasses import replace

    level_names = [n for n in ("F_0", "y_cb_offset") if n in result.free]
    text = (f"levels kept in the data: y_0 = {result.parameters['y_0']:.6g} m "
            f"({'estimated' if 'y_0' in result.free else 'held'})"
            + (f", {' and '.join(level_names)} estimated" if level_names else ""))
    return replace(result, message=f"{result.message}; {text}",
                   details={**result.details, "levels": {"centred": False, "message": text}})


def _identify_pareto(structure: OscillatorStructure, data: IdentificationData,
                     free: Sequence[str], start: Mapping[str, float],
                     bounds: Mapping[str, tuple[float, float]], executor: Any,
                     progress: Callable[[str], None] | None,
                     options: dict[str, Any]) -> IdentificationResult:
    """NSGA-II front over the fits (panto.identification.estimation.genetic), knee solution, LM polish."""
    from panto.identification.estimation.genetic import fit_pareto

    pick = options.pop("pick", "knee")
    polish = options.pop("polish", True)
    pareto = fit_pareto(structure, data, free=free, executor=executor, progress=progress,
                        objectives=tuple(o for o in ("y_cb", "F_c") if o in data.output_names),
                        initial=start, bounds=bounds, **options)
    chosen = pareto.pick(rule=pick)
    return pareto.polish(chosen, data, executor=executor, progress=progress) if polish else chosen


def oscillator_from_data(data: IdentificationData, *, masses: int, friction: bool = False,
                         **options: Any) -> OscillatorStructure:
    """The nominal :class:`OscillatorStructure` on the outputs of `data` (options: its
    constructor's)."""
    return OscillatorStructure(masses, friction, outputs=data.output_names, **options)

__all__ = ["OscillatorStructure", "ACCELERATIONS", "identify_oscillator", "oscillator_from_data",
           "offset_start", "discretise",
           "propagate", "coulomb_flow", "SUBSTEPS", "INPUT_NAMES", "OUTPUT_NAMES"]
