"""A two- or three-mass oscillator with one more mass hung on one of its masses by a spring and a
damper: the diagnosis' ``extra_mode`` inside the dynamics (a flexible part the nominal lacks: a
collector strip on the head, a frame member).

The extra mass ``m_e`` [kg] sits on mass ``i`` (``attached``, numbered from the bottom as the
oscillator's masses) through the spring ``k_e = m_e (2 pi f_e)^2`` and the damper
``c_e = 2 zeta_e m_e (2 pi f_e)``, so that ``f_e`` [Hz] and ``zeta_e`` [-] are the mode's own
frequency and damping when mass ``i`` is held::

    m_i z_i'' = (the oscillator's forces) - k_e (z_i - z_e) - c_e (z_i' - z_e')
    m_e z_e'' = k_e (z_i - z_e) + c_e (z_i' - z_e')

(no force of its own: at rest ``z_e = z_i``, the weight being part of the static balance ``F_0``
as for the other masses). The mode is coupled: it changes every output, where an additive mode
on one output (the diagnosis' outside form) changes that one only and cannot take the plant's
poles where a strong part hangs on the head (seen held-out two-mass/extra_mode/2017: 0.77 kg at
7.5 Hz on a 7.2 kg head, the nominal's contact-force fit 16 % where a linear black box gives
98 %; the outside mode added 0.4 points). The state is the oscillator's ``[z; z']`` followed by
``[z_e, z_e']``, so every row and column the oscillator uses keeps its index; the model is linear
and simulated as the oscillator is (exact first-order-hold discretisation).
"""
from __future__ import annotations

from typing import Mapping, NoReturn, Sequence

import numpy as np

from panto.identification.estimation.base import IdentificationError
from panto.identification.structures.oscillators import DEFAULT_OUTPUTS, OscillatorStructure

#: The mode's parameters: mass [kg], frequency with its carrier held [Hz], damping ratio [-].
MODE_PARAMETERS = ("m_e", "f_e", "zeta_e")


class OscillatorWithMode(OscillatorStructure):
    """An oscillator without friction with an extra mass on mass `attached` (1 = the lowest).

    Parameters
    ----------
    masses : int
        2 or 3.
    attached : int
        The mass carrying the extra one, 1 to `masses` (default: the head, the top one).
    frequency, damping : float
        Start values of ``f_e`` [Hz] and ``zeta_e`` [-] (the nominal values of the structure).
    highest : float
        Upper bound of ``f_e`` [Hz] (the diagnosis: 0.95 times the data's Nyquist frequency, as
        the additive mode's; above it the hung mass moves with its carrier, a heavier head).
    outputs, hold
        As :class:`~panto.identification.structures.oscillators.OscillatorStructure`.
    """

    def __init__(self, masses: int, *, attached: int | None = None, frequency: float = 10.0,
                 damping: float = 0.05, highest: float = 1e3,
                 outputs: Sequence[str] = DEFAULT_OUTPUTS, hold: str = "foh") -> None:
        super().__init__(masses, friction=False, outputs=outputs, hold=hold)
        self.attached = masses if attached is None else int(attached)
        if not 1 <= self.attached <= masses:
            raise IdentificationError(f"extra mode on mass {self.attached}: the masses are "
                                      f"1 to {masses}")
        if not (frequency > 0 and damping > 0):
            raise IdentificationError(f"extra mode start {frequency} Hz / damping {damping}: "
                                      "both must be positive")
        self.highest = float(highest)
        self.start_frequency = min(float(frequency), self.highest)
        self.start_damping = float(damping)
        self.name = f"{self.name}+mode@{self.attached}"
        self.parameter_names = tuple(self.parameter_names) + MODE_PARAMETERS

    def nominal(self) -> dict[str, float]:
        """The oscillator's values; the extra mass 2 % of its carrier's, the start frequency and
        damping."""
        values = super().nominal()
        values.update(m_e=0.02 * values[f"m{self.attached}"], f_e=self.start_frequency,
                      zeta_e=self.start_damping)
        return values

    def bounds(self) -> dict[str, tuple[float, float]]:
        """The oscillator's; the extra mass 0 (no mode: it moves alone, uncoupled) to 500 kg,
        0.01 Hz to ``highest``, damping 0.001-2."""
        values = super().bounds()
        values.update(m_e=(0.0, 500.0), f_e=(0.01, self.highest), zeta_e=(1e-3, 2.0))
        return values

    def units(self) -> dict[str, str]:
        plain = OscillatorStructure(self.masses, outputs=self.output_names, hold=self.hold)
        return {**plain.units(), "m_e": "kg", "f_e": "Hz", "zeta_e": "-"}

    def values(self, parameters: Mapping[str, float]) -> dict[str, float]:
        values = super().values(parameters)
        # m_e = 0 is the neutral value: the mode is there, uncoupled
        bad = {k: values[k] for k in MODE_PARAMETERS
               if not (values[k] > 0 or k == "m_e" and values[k] == 0.0)}
        if bad:
            raise IdentificationError(f"{self.name}: invalid parameter values {bad}")
        return values

    @property
    def magnitude_parameters(self) -> tuple[str, ...]:
        """The parameter whose distance from zero says the mode is there: its mass."""
        return ("m_e",)

    def matrices(self, parameters: Mapping[str, float]) -> tuple[np.ndarray, ...]:
        """The oscillator's ``(A, B, C, D)`` with the extra mass's two states appended."""
        a, b, c, d = super().matrices(parameters)
        v = self.values(parameters)
        n, i = self.masses, self.attached - 1
        omega = 2 * np.pi * v["f_e"]
        k_e, c_e = v["m_e"] * omega ** 2, 2 * v["zeta_e"] * v["m_e"] * omega
        m_i = v[f"m{i + 1}"]
        size = 2 * n + 2
        out = np.zeros((size, size))
        out[:2 * n, :2 * n] = a
        z, vel = 2 * n, 2 * n + 1  # the extra mass's position and velocity
        out[n + i, i] -= k_e / m_i
        out[n + i, n + i] -= c_e / m_i
        out[n + i, z] += k_e / m_i
        out[n + i, vel] += c_e / m_i
        out[z, vel] = 1.0
        out[vel, i], out[vel, n + i] = omega ** 2, 2 * v["zeta_e"] * omega
        out[vel, z], out[vel, vel] = -omega ** 2, -2 * v["zeta_e"] * omega
        return (out, np.vstack([b, np.zeros((2, b.shape[1]))]),
                np.hstack([c, np.zeros((c.shape[0], 2))]), d)

    def with_effect(self, effect: str, setting: Mapping[str, object]) -> NoReturn:
        """No other effect goes inside this one (the diagnosis adds them from outside)."""
        raise IdentificationError(f"{self.name}: no inside form for effect {effect!r}")
