"""Unilateral contact in a linear(ised) model: the head leaves the wire and flies (contact loss).

The contact element of the project's pantograph models is the carbon-contact spring between the
head and the wire (slider) height ``eta``: ``g = k_ph (xi - eta)`` in the physical model (thesis
section 2.5, :mod:`panto.fmu_src.pantograph`), ``g = k_E (z_n + y_0 - eta)`` on the top mass of the
two-/three-mass oscillators (eq. 2.33/2.34). It carries no damper. A bilateral model lets the
wire pull the head (``g < 0``); the real contact can only push. With the contact force acting on
the states through the column ``b_c`` (``M^-1`` times the generalised-force direction of the head
coordinate), the bilateral linear(ised) model ``x' = A x + B u`` holds the term ``-b_c g``
(``g = c_F x + d_F u``); the wire's real push ``max(g, 0)`` in its place gives

    x' = A x + B u + b_c (g - max(g, 0)) = A x + B u + b_c min(g, 0),     F_c = max(g, 0),

i.e. a switched pair of linear systems: in contact (``g >= 0``) the model itself; in flight
(``g < 0``) the contact element removed, ``A_f = A + b_c c_F``, ``B_f = B + b_c d_F`` (the wire
input then drops out of the dynamics; a static contact force ``F_0`` of the linearisation point
becomes the constant upward push ``b_c F_0`` that the wire no longer takes up). The state is
continuous across a switch and so is the right-hand side (the spring force is zero at the
switch), so the switched system is Lipschitz and its solution unique.

``b_c`` need not be derived separately: the wire input enters only through the contact spring,
``B[:, eta] = b_c k`` and ``d_F[eta] = -k``, so ``b_c = -B[:, eta] / d_F[eta]``. For the
physical model linearised about an in-contact equilibrium the flight matrices are the
linearisation of the contact-free model about the same point (the spring is linear, and the
head's inertia ``m_c`` is decoupled from the arms', so the acceleration the removed force leaves
adds no ``dM/dq a`` term).

Simulation (:func:`simulate_switched`): exact discretisation of both modes for inputs linear
between samples (first-order hold; or held, ``"zoh"``) on ``M`` sub-steps per sample from the
block exponential ``E(h) = expm([[A, B, 0], [0, 0, I], [0, 0, 0]] h)`` of the state, input and
input-slope (``E(j h) = E(h)^j``: Franklin, Powell & Workman, *Digital Control of Dynamic
Systems*, sec. 6.3). Each sample is first tried whole in the current mode; the contact force
predicted at its ``M`` sub-step instants costs one ``M x n`` product. When the force keeps its
sign the whole-sample step is taken, otherwise the sample is run sub-step by sub-step, the mode
chosen by the sign of ``g`` at each sub-step's start (the whole-sample steps between switches
are taken a stretch at a time, :func:`_run_switched`). The switch is placed inside its sub-step:
the instant ``tau`` where ``g`` crosses zero by linear interpolation between the sub-step
instants, and the new mode's term ``+-b_c g`` over the rest of the sub-step added to the state
to second order (:func:`_within`). Because the right-hand side is continuous (the spring force
is zero at the switch), this leaves a local error of order ``h^3`` per switch (rounding the
switch to the sub-step grid left ``h^2``, and a state that jumps with the parameters whenever a
switch moves across a grid point). A flight shorter than one sub-step, beginning and ending
inside it, is not seen. The run in contact and the switched recursion run compiled where a C
compiler is available (:mod:`panto.identification.diagnosis.contact_kernel`: the same
recursion to rounding, ~4 times faster; ``PANTO_CONTACT_KERNEL=0`` keeps the NumPy path).

Sub-step length (:class:`UnilateralContact`): ``M`` is :data:`SUBSTEPS`, or large enough that
``h`` is at most ``max_substep`` when one is given (at most :data:`MOST_SUBSTEPS` per sample). A head that bounces on the wire (the contact spring's mode,
``sqrt(k / m_head)``, 10-20 Hz for a carbon contact of 50 kN/m) meets it again after every
flight, and the timing error of each impact shifts all later ones: on a 50 Hz record of an
oscillator bouncing for a quarter of the time (``benchmarks/effect_plants.py``, case
``three-mass/contact_loss/23`` of the quick tuning split, validation run), the force simulated
at the plant's true parameters fitted a reference integration of the same plant (RK4, 25 us)
by 71 % with ``h = T / 32 = 0.63 ms`` and by 99 % with ``h = 0.1 ms`` (99.6 % and more
against this module's own run with ``h = 5 us`` from ``h = 0.16 ms`` down; the grid-rounded
switch had scattered between 65 and 98 % without converging down to ``h = 0.02 ms``).
:data:`MAX_SUBSTEP` is nevertheless unbounded by default: 0.1 ms made every candidate refit on a
contact model 2.5-6 times slower (200 sub-steps per 50 Hz sample; the diagnosis speed benchmark's
rounds after an accepted contact loss carry most of its time), changed no verdict on the four
tuning cases measured (8, 23, 53, 113), and against the benchmark plant's own records (RK4 at
0.5 ms) the 32-sub-step run at the true parameters fits as well or better (validation F_c on
cases 23 / 53 / 113: 95.1 / 87.6 / 97.9 % against 71.0 / 87.6 / 97.7 %). Pass ``max_substep``
where a bouncing head must be followed accurately.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from panto.identification.diagnosis import contact_kernel
from panto.identification.estimation.base import IdentificationError, ModelStructure
from panto.identification.structures.linearisation import expm, propagate

#: Sub-steps per sample where the contact switches, at least (module notes).
SUBSTEPS = 32
#: Longest sub-step [s] of :class:`UnilateralContact` by default: unbounded, the sub-steps are
#: :data:`SUBSTEPS` (module notes: 1e-4 follows a bouncing head, at 2.5-6 times the cost).
MAX_SUBSTEP = math.inf
#: Most sub-steps per sample that :data:`MAX_SUBSTEP` asks for (a slowly sampled record).
MOST_SUBSTEPS = 256
IN_CONTACT, IN_FLIGHT = 0, 1


@dataclass(frozen=True)
class SwitchedRun:
    """Result of :func:`simulate_switched`.

    Attributes
    ----------
    states : ndarray, shape (n_samples, n_states)
    force : ndarray, shape (n_samples,)
        Contact force ``max(g, 0)`` at the samples: exactly zero in flight.
    in_contact : ndarray of bool, shape (n_samples,)
    switched : bool
        Whether the contact was ever lost (otherwise the run is the linear model's own).
    """

    states: np.ndarray
    force: np.ndarray
    in_contact: np.ndarray
    switched: bool


@dataclass(frozen=True, eq=False)
class ContactModel:
    """A linear(ised) model with its contact force, for :func:`simulate_switched` (module notes).
    Units: those of the model's states and inputs; the force in newtons."""

    a: np.ndarray
    """``A`` in contact (bilateral), shape (n, n)."""
    b: np.ndarray
    """``B`` in contact, shape (n, m)."""
    c_force: np.ndarray
    """State row of the contact force ``g = c_F x + d_F u``, shape (n,)."""
    d_force: np.ndarray
    """Input row of the contact force, shape (m,); a constant part goes in a constant input."""
    column: np.ndarray
    """``b_c`` (:func:`contact_column`): state derivative per newton of contact force, (n,)."""


def contact_column(b: np.ndarray, d_force: np.ndarray, wire: int) -> np.ndarray:
    """``b_c = -B[:, wire] / d_F[wire]``: the state derivative per newton of contact force.

    The wire input reaches the dynamics only through the contact spring (module notes), so its
    input column is the contact column times the spring's stiffness ``k = -d_F[wire]``.
    """
    stiffness = -float(d_force[wire])
    if not stiffness > 0.0:
        raise IdentificationError(f"unilateral contact: the contact force does not grow as the "
                                  f"head presses on the wire (dF/deta = {-stiffness:g})")
    return np.asarray(b, float)[:, wire] / stiffness


def _modes(model: ContactModel) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """``(A, B)`` in contact and in flight (contact element removed)."""
    a, b, column = model.a, model.b, model.column
    return (a, b), (a + np.outer(column, model.c_force), b + np.outer(column, model.d_force))


def _tables(a: np.ndarray, b: np.ndarray, period: float, substeps: int) -> np.ndarray:
    """``E(j h)``, ``j = 1..M``, of the state/input/slope block (module notes), shape (M, N, N)."""
    n, m = b.shape
    block = np.zeros((n + 2 * m, n + 2 * m))
    block[:n, :n] = a
    block[:n, n:n + m] = b
    block[n:n + m, n + m:] = np.eye(m)
    step = expm(block * (period / substeps))
    tables = np.empty((substeps,) + step.shape)
    tables[0] = step
    for j in range(1, substeps):
        tables[j] = tables[j - 1] @ step
    return tables


@dataclass
class _Mode:
    """Pre-computed maps of one mode (internal); ``z = [x, u, du/dt]`` at a sub-step instant."""

    maps: np.ndarray      # (M, n, n + 2m): x((j + 1) h) = maps[j] @ z
    rows: np.ndarray      # (M, n + 2m): c_F maps[j], the force's state part at those instants
    drive: np.ndarray | None    # (N - 1, n): the whole sample's input part (None: lazy)
    offsets: np.ndarray | None  # (N - 1, M): the rest of g at the sub-step instants (None: lazy)
    phi: np.ndarray       # (n, n): the whole sample's state transition
    rows_x: np.ndarray    # (M, n): the state part of `rows`
    kick: np.ndarray      # (n, 2): b_c and A b_c, the switch's share of a sub-step (_within)


def _prepare(matrices: tuple[np.ndarray, np.ndarray], model: ContactModel, u: np.ndarray,
             slope: np.ndarray, period: float, substeps: int, lazy: bool = False) -> _Mode:
    """One mode's maps for `matrices` ``(A, B)``, inputs `u` and their slopes (per second);
    `lazy`: without ``drive`` and ``offsets`` (the compiled kernel computes the samples it
    needs)."""
    a, b = matrices
    c_force, d_force = model.c_force, model.d_force
    n, m = b.shape
    maps = _tables(a, b, period, substeps)[:, :n, :]
    rows = c_force @ maps
    kick = np.column_stack([model.column, a @ model.column])
    if lazy:
        return _Mode(maps, rows, None, None, maps[-1, :, :n].copy(), rows[:, :n].copy(), kick)
    instants = np.arange(1, substeps + 1) * (period / substeps)
    offsets = (u[:-1] @ (rows[:, n:n + m] + d_force).T + slope @ rows[:, n + m:].T
               + (slope @ d_force)[:, None] * instants[None, :])
    drive = u[:-1] @ maps[-1, :, n:n + m].T + slope @ maps[-1, :, n + m:].T
    return _Mode(maps, rows, drive, offsets, maps[-1, :, :n].copy(), rows[:, :n].copy(), kick)


def simulate_switched(model: ContactModel, u: np.ndarray, x0: np.ndarray, period: float, *,
                      hold: str = "foh", substeps: int = SUBSTEPS) -> SwitchedRun:
    """Free run of ``x' = A x + B u + b_c min(g, 0)``, ``g = c_F x + d_F u`` (module notes).

    Parameters
    ----------
    model : ContactModel
        ``A``, ``B`` in contact, the contact force's rows ``c_F``, ``d_F`` and ``b_c``.
    u : ndarray, shape (N, m)
        Input samples every `period` seconds.
    x0 : ndarray
        State at the first sample.
    hold : {"foh", "zoh"}
        Inputs linear between samples or held.
    substeps : int
        ``M`` (module notes).
    """
    u, x0 = np.asarray(u, float), np.asarray(x0, float)
    if hold not in ("foh", "zoh") or substeps < 1 or len(u) < 2:
        raise IdentificationError(f"switched simulation: hold {hold!r}, substeps {substeps}, "
                                  f"{len(u)} samples")
    slope = np.diff(u, axis=0) / period if hold == "foh" else np.zeros((len(u) - 1, u.shape[1]))
    matrices = _modes(model)
    contact = _prepare(matrices[IN_CONTACT], model, u, slope, period, substeps)
    c_force, d_force = model.c_force, model.d_force
    with np.errstate(over="ignore", invalid="ignore"):  # a diverging run is refused below
        states = contact_kernel.propagate(contact.phi, contact.drive, x0)
        if states is None:
            states = propagate(contact.phi, contact.drive, x0)
        inside = states[:-1] @ contact.rows_x.T + contact.offsets
    g = states @ c_force + u @ d_force
    lost = np.flatnonzero((inside < 0.0).any(axis=1) | (g[:-1] < 0.0))
    if len(lost) == 0:
        return SwitchedRun(states, np.maximum(g, 0.0), np.ones(len(u), bool), False)
    lazy = contact_kernel.active_backend() == "compiled"  # the flight's tables where needed
    modes = [contact, _prepare(matrices[IN_FLIGHT], model, u, slope, period, substeps, lazy)]
    with np.errstate(over="ignore", invalid="ignore"):
        _run_switched(modes, states, u, slope, int(lost[0]), c_force, d_force, period / substeps)
    g = states @ c_force + u @ d_force
    return SwitchedRun(states, np.maximum(g, 0.0), g >= 0.0, True)


#: Samples :func:`_run_switched` advances at once in contact and in flight.
STRETCH, FLIGHT_STRETCH = 64, 16


def _run_switched(modes: list[_Mode], states: np.ndarray, u: np.ndarray, slope: np.ndarray,
                  start: int, c_force: np.ndarray, d_force: np.ndarray, h: float) -> None:
    """Overwrite ``states[start + 1:]`` by the switched recursion (module notes).

    `states` holds on entry the whole run in contact, ``X`` (a solution of the contact mode's
    recursion ``x[k+1] = Phi x[k] + drive[k]``), so any stretch in contact from state ``x`` at
    sample ``k`` is ``x[k+j] = X[k+j] + Phi^j (x - X[k])`` (the mode is stable: ``X`` stays
    bounded); in flight (which need not be stable) ``x[k+j] = Phi^j x + sum_{i<j} Phi^{j-1-i}
    drive[k+i]`` over at most :data:`FLIGHT_STRETCH` samples (:func:`_convolution`). A stretch is
    taken at once, the force at the sub-step instants of all its samples checked at once, and
    the stretch kept up to the first sample whose force changes sign, which :func:`_within` runs
    across the switch. The same recursion as sample after sample, to rounding, without a Python
    step per sample. The compiled kernel (:mod:`~panto.identification.diagnosis.contact_kernel`)
    runs the same recursion where it is available, else :func:`_switched_numpy`."""
    powers = _powers(modes[IN_CONTACT].phi, STRETCH), _powers(modes[IN_FLIGHT].phi, FLIGHT_STRETCH)
    if not contact_kernel.run_switched(modes, states, u, slope, start, c_force, d_force, h, powers):
        _switched_numpy(modes, states, u, slope, start, c_force, d_force, h, powers)
    if not np.all(np.isfinite(states)):
        raise IdentificationError("switched simulation diverged (unilateral contact)")


def _switched_numpy(modes: list[_Mode], states: np.ndarray, u: np.ndarray, slope: np.ndarray,
                    start: int, c_force: np.ndarray, d_force: np.ndarray, h: float,
                    powers: tuple[np.ndarray, np.ndarray]) -> None:
    """The NumPy loop of :func:`_run_switched` with the powers ``Phi^j`` of both modes: the
    reference the compiled kernel follows."""
    n, last = states.shape[1], len(u) - 1
    bilateral = states.copy()
    powers, flight_powers = powers
    convolution = _convolution(flight_powers)
    x = states[start].copy()
    mode = IN_CONTACT if float(c_force @ x + d_force @ u[start]) >= 0.0 else IN_FLIGHT
    k = start
    while k < last:
        current = modes[mode]
        if mode == IN_CONTACT:
            end = min(k + STRETCH, last)
            run = bilateral[k:end + 1] + powers[:end - k + 1] @ (x - bilateral[k])
        else:
            end = min(k + FLIGHT_STRETCH, last)
            m = end - k
            run = flight_powers[:m + 1] @ x
            run[1:] += np.einsum("jiab,ib->ja", convolution[:m, :m], current.drive[k:end])
        g = run[:-1] @ current.rows_x.T + current.offsets[k:end]
        wrong = g < 0.0 if mode == IN_CONTACT else g >= 0.0
        switching = np.flatnonzero(wrong.any(axis=1))
        if len(switching) == 0:
            states[k + 1:end + 1], x, k = run[1:], run[-1], end
            continue
        i = int(switching[0])
        states[k + 1:k + i + 1] = run[1:i + 1]
        z = np.concatenate([run[i], u[k + i], slope[k + i]])
        x, mode = _within(modes, mode, z, int(np.argmax(wrong[i])), g[i], c_force, d_force, h, n)
        k += i + 1
        states[k] = x


def _powers(phi: np.ndarray, count: int) -> np.ndarray:
    """``Phi^j``, ``j = 0..count``, shape (count + 1, n, n)."""
    powers = np.empty((count + 1,) + phi.shape)
    powers[0] = np.eye(len(phi))
    for j in range(count):
        powers[j + 1] = phi @ powers[j]
    return powers


def _convolution(powers: np.ndarray) -> np.ndarray:
    """From ``Phi^j``, ``j = 0..count`` (:func:`_powers`), the convolution ``T[j - 1, i] =
    Phi^(j-1-i)`` for ``i < j`` (zero otherwise), ``j = 1..count``: ``x[k+j] = Phi^j x[k] +
    sum_i T[j-1, i] drive[k+i]``."""
    count = len(powers) - 1
    lag = np.arange(count)[:, None] - np.arange(count)[None, :]
    return np.where((lag >= 0)[:, :, None, None], powers[np.clip(lag, 0, count)], 0.0)


def _within(modes: list[_Mode], mode: int, z: np.ndarray, first: int, g: np.ndarray,
            c_force: np.ndarray, d_force: np.ndarray, h: float, n: int) -> tuple[np.ndarray, int]:
    """One sample across its switches: from sub-step instant ``j``, the current mode runs to the
    end of the sub-step in which ``g`` first changes sign, at ``tau`` (linear interpolation
    between the instants), and the new mode's extra term ``+-b_c g`` over the rest ``r`` of that
    sub-step is added, ``+-(b_c r^2 / 2 + A b_c r^3 / 6) g'`` (``g' `` the slope between the
    instants; ``+`` into flight): the switch is placed within the sub-step, not on its grid, so
    the state is continuous in the parameters; then the mode toggles; until the sample's end."""
    count = len(modes[IN_CONTACT].maps)
    m = (len(z) - n) // 2
    u_start, slope = z[n:n + m], z[n + m:]
    j = 0
    while True:
        before = float(c_force @ z[:n] + d_force @ z[n:n + m]) if first == 0 else g[first - 1]
        share = before / (before - g[first]) if before != g[first] else 1.0
        steps, rest, rate = first + 1, (1.0 - share) * h, (g[first] - before) / h
        z = np.concatenate([modes[mode].maps[steps - 1] @ z, u_start + slope * ((j + steps) * h),
                            slope])
        sign = 1.0 if mode == IN_CONTACT else -1.0  # into flight the wire's pull is given back
        z[:n] += sign * rate * (modes[1 - mode].kick @ np.array([rest ** 2 / 2, rest ** 3 / 6]))
        j += steps
        if j >= count:  # the next sample starts in the mode of its first force
            end = float(c_force @ z[:n] + d_force @ z[n:n + m])
            return z[:n], IN_CONTACT if end >= 0.0 else IN_FLIGHT
        mode = 1 - mode
        ramp = (d_force @ slope) * h * np.arange(1, count - j + 1)
        g = modes[mode].rows[:count - j] @ z + ramp + d_force @ z[n:n + m]
        wrong = g < 0.0 if mode == IN_CONTACT else g >= 0.0
        if not wrong.any():
            return modes[mode].maps[count - j - 1] @ z, mode
        first = int(np.argmax(wrong))


# --- the structure --------------------------------------------------------------------------

def supports_unilateral(nominal: ModelStructure) -> bool:
    """Whether `nominal` is a linear(ised) pantograph structure whose contact element this module
    can make unilateral: ``physical-linear``, or a two-/three-mass oscillator without friction."""
    from panto.identification.structures.oscillators import OscillatorStructure
    from panto.identification.structures.physical import PhysicalLinear

    return type(nominal) is PhysicalLinear or (type(nominal) is OscillatorStructure
                                               and not nominal.friction)


class UnilateralContact(ModelStructure):
    """A linear(ised) pantograph structure with its carbon contact made unilateral.

    Same parameters, inputs and outputs as `nominal` (no new parameter: the contact's stiffness
    is the nominal's ``k_ph`` or ``k_E``); :meth:`simulate` runs :func:`simulate_switched`.

    Parameters
    ----------
    nominal : PhysicalLinear or OscillatorStructure
        See :func:`supports_unilateral`.
    substeps : int
        Sub-steps per sample at a switch, at least (module notes).
    max_substep : float
        Longest sub-step [s] (module notes); ``math.inf``: `substeps` per sample.
    """

    def __init__(self, nominal: ModelStructure, *, substeps: int = SUBSTEPS,
                 max_substep: float = MAX_SUBSTEP) -> None:
        if not supports_unilateral(nominal):
            raise IdentificationError(f"unilateral contact: no linear contact element in "
                                      f"{nominal.name!r}")
        self.nominal_structure = nominal
        self.substeps = int(substeps)
        self.max_substep = float(max_substep)
        if not self.max_substep > 0.0:
            raise IdentificationError(f"unilateral contact: max_substep {max_substep} s must be "
                                      f"positive")
        self.name = f"{nominal.name}+contact_loss"
        self.input_names, self.output_names = nominal.input_names, nominal.output_names
        self.parameter_names = tuple(nominal.parameter_names)
        self.difference_step = getattr(nominal, "difference_step", 1e-6)

    #: What :meth:`simulate` gives (the oscillator's exact accelerations are not among them:
    #: the contact switches its dynamics; a sensor mass on the head then takes the second
    #: difference of the head, as on any structure without them).
    simulable_outputs = ("y_cb", "xi", "F_c")

    def __getattr__(self, name: str):
        if name.startswith("__") or "nominal_structure" not in self.__dict__:
            raise AttributeError(name)
        return getattr(self.nominal_structure, name)  # fixed, hold, default_free, ...

    def nominal(self) -> dict[str, float]:
        return self.nominal_structure.nominal()

    def bounds(self) -> dict[str, tuple[float, float]]:
        return self.nominal_structure.bounds()

    def substeps_for(self, period: float) -> int:
        """Sub-steps per sample of `period` [s]: at least :attr:`substeps`, and enough for sub-steps
        of at most :attr:`max_substep` (up to :data:`MOST_SUBSTEPS`; module notes)."""
        needed = math.ceil(period / self.max_substep - 1e-9) if math.isfinite(
            self.max_substep) else 1
        return max(self.substeps, min(needed, MOST_SUBSTEPS))

    def run(self, parameters, data) -> tuple[SwitchedRun, np.ndarray, np.ndarray, np.ndarray]:
        """The switched run on `data`, with the output maps ``(C, D)`` for inputs ``u`` extended
        by a constant column (all outputs ``(y_cb, xi, F_c)``)."""
        a, b, c, d, u, x0, hold = self._linear_form(parameters, data)
        model = ContactModel(a, b, c[2], d[2], contact_column(b, d[2], 0))
        run = simulate_switched(model, u, resting_state(model, x0, u[0]), data.sample_period,
                                hold=hold, substeps=self.substeps_for(data.sample_period))
        return run, c, d, u

    def simulate(self, parameters, data) -> np.ndarray:
        """Free run with the unilateral contact: the force output is ``max(g, 0)``."""
        run, c, d, u = self.run(parameters, data)
        rows = [("y_cb", "xi", "F_c").index(o) for o in self.output_names]
        y = run.states @ c[rows].T + u @ d[rows].T
        if "F_c" in self.output_names:
            y[:, self.output_names.index("F_c")] = run.force
        if not np.all(np.isfinite(y)):
            raise IdentificationError(f"{self.name}: non-finite outputs for {dict(parameters)}")
        return y

    def _linear_form(self, parameters, data):
        """``(A, B, C, D, u, x0, hold)`` with a constant last input column (any static part)."""
        nominal = self.nominal_structure
        if hasattr(nominal, "deviation_model"):  # physical-linear: deviations from u0
            a, b, c, d, y0, du, x0 = nominal.deviation_model(parameters, data)
            _check_stable(a, nominal.name, parameters)
            b = np.hstack([b, np.zeros((len(b), 1))])
            d = np.hstack([d, y0[:, None]])
            return a, b, c, d, np.column_stack([du, np.ones(len(du))]), x0, nominal.hold
        a, b, c, d = nominal.matrices(parameters)  # oscillators: inputs (eta, p, 1)
        _check_stable(a, nominal.name, parameters)
        u = np.column_stack([data.input("eta"), data.input("p"), np.ones(len(data))])
        return a, b, c, d, u, nominal.equilibrium(parameters, u[0, 0], u[0, 1]), nominal.hold


def resting_state(model: ContactModel, x0: np.ndarray, u0: np.ndarray) -> np.ndarray:
    """The state at rest for the first input `u0`: `x0` (the bilateral model's equilibrium) where
    its contact force is not negative, else the equilibrium in flight (the head held by its
    suspension alone, ``(A + b_c c_F) x + (B + b_c d_F) u0 = 0``): a unilateral contact cannot
    pull, so a run that starts with the head below the wire's reach starts off it."""
    if float(model.c_force @ x0 + model.d_force @ u0) >= 0.0:
        return x0
    a = model.a + np.outer(model.column, model.c_force)
    b = model.b + np.outer(model.column, model.d_force)
    try:
        return -np.linalg.solve(a, b @ u0)
    except np.linalg.LinAlgError as error:
        raise IdentificationError(f"unilateral contact: no equilibrium in flight ({error})") \
            from error


def _check_stable(a: np.ndarray, name: str, parameters) -> None:
    """The model in contact must be stable (as its bilateral structure requires); in flight it
    need not be: a pantograph without its wire rises under the uplift until it meets it."""
    if not np.all(np.isfinite(a)) or np.max(np.linalg.eigvals(a).real) > 1e-9:
        raise IdentificationError(f"{name}: unstable linear model for {dict(parameters)}")


__all__ = ["SwitchedRun", "ContactModel", "UnilateralContact", "contact_column", "resting_state",
           "simulate_switched",
           "supports_unilateral", "SUBSTEPS", "MAX_SUBSTEP", "MOST_SUBSTEPS"]
