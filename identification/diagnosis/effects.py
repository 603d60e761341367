"""Which effect's signature explains the gap: candidate regressors and their FROLS ranking.

Every candidate effect of the vocabulary :data:`EFFECTS` is represented by a few *physical*
regressor variants built from the inputs, the simulated (or measured) outputs and their
derivatives, never from lagged outputs (they would absorb everything and hide the physics). The
signatures follow the table of the diagnosis reference:

================  =====================================================================
effect            regressor variants ``phi(t)``
================  =====================================================================
coulomb_friction  ``sign(v)``, ``tanh(v / v_s)`` for a few ``v_s`` (relative to std v);
                  presliding ``(x - play_b(x)) / b`` (a joint that sticks at reversals)
cubic_stiffness   ``x~^3``, ``x~|x~|`` (``x~ = x - median x``)
dead_zone         ``dz(u~, b) - u~ = -clip(u~, -b, b)`` of actuators; backlash ``play_b(x) - x``
input_delay       ``u(t - d) - u(t)`` over delays ``d``
actuator_lag      ``L_T u - u``, ``L_T`` the first-order low-pass of time constant ``T``
sensor_inertia    acceleration of the sensor side (``x_s''``, :func:`sensor_acceleration`) or of
                  the head (``xi''``: load cells inside it)
extra_mode        ``(H_{f,zeta} - 1) w``: dynamic part of a 2nd-order mode driven by force/input
contact_loss      ``max(F, 0) - F`` of the simulated force
offset            ``1``
saturation        ``clip(s, q_lo, q_hi) - s`` at input/force quantiles
================  =====================================================================

Ranking: orthogonal forward regression (FROLS; Billings, *Nonlinear System Identification*, 2013,
chapter 3). The target ``r`` is either the free-run residual (each regressor then passed through
the nominal model's sensitivity ``S``: how an additive term reaches the output) or an
equation-error residual such as the force equation ``F - Phi_nom theta``. Base columns (the
nominal parameters' sensitivities, or the nominal regressors) are projected out first, so a
candidate is credited only with what the nominal parameters cannot absorb. The error reduction
ratio of an orthogonalised regressor ``w`` is ``ERR = (w^T r)^2 / (w^T w  r0^T r0)``, the share of
the (base-projected) target energy ``r0^T r0`` it removes. A step is significant when its
correlation ``w^T r / (|w| |r|)`` exceeds ``z sqrt(P / N)``, ``P = sum_{|k|<=M} rho_w(k) rho_r(k)``
(coloured signals), with ``z`` Bonferroni-corrected for the number of variants tried.

On a free-run residual the signatures are linearised about the nominal trajectory (regressors
from the simulated signals, passed through the sensitivity): reliable while the gap is moderate
(tested with residuals up to about 40 % of the output's spread). A much larger gap (a resonance
shifted by a strong nonlinearity) must be ranked after refitting, or in an equation-error form.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass

import numpy as np
from scipy import signal as sps
from scipy import stats

from panto.identification.estimation.base import IdentificationError

EFFECTS = ("coulomb_friction", "cubic_stiffness", "dead_zone", "input_delay", "actuator_lag",
           "sensor_inertia", "extra_mode", "contact_loss", "offset", "saturation")
#: The effects no linear model can express (:attr:`DiagnosisOptions.adequacy` holds them to a
#: black box's training fit).
NONLINEAR_EFFECTS = ("coulomb_friction", "cubic_stiffness", "dead_zone", "contact_loss",
                     "saturation")

Regressor = tuple[np.ndarray, dict]
"""A regressor variant: its samples and its setting (delay, time constant, width...)."""


@dataclass(frozen=True)
class SignalRoles:
    """Which named signal plays which physical part (defaults: the pantograph).

    Parameters
    ----------
    position : str or None
        Displacement of the moving part (pantograph: collector bar ``y_cb`` [m]).
    velocity, acceleration : str or None
        Named signals, or None to differentiate `position` (zero-phase filtered).
    force : str or None
        Force whose sign/level matters (pantograph: contact force ``F_c`` [N]).
    actuators : tuple of str
        Inputs that may be delayed, lagged, saturated or pass a dead zone (``eta``, ``p`` [bar]).
    mode_drive : str or None
        Signal driving an unmodelled mode; None: `force`, else the first actuator.
    sensor_position : str or None
        Position of the force sensor's moving side: a mass between the sensor and the structure
        moves with it (pantograph: the linear motor's bar height ``eta`` [m], the rig's aluminium
        bar, thesis chapter 3, ``F_sensor = F_c - m_bar eta''``; not the cross bar ``y_cb``, which
        the head suspension decouples from the bar above a few hertz). None, or a name absent from
        the data: `position`.
    head_position : str or None
        Position of the body that carries the contact strips, when the force is measured inside
        it (load cells under the strips, as on a measuring pantograph): the strips' mass above
        the cells moves with the head, ``F_sensor = F_c - m_s xi''`` (EN 50317 corrects the
        measured force for this inertia). A second placement of ``sensor_inertia`` beside
        `sensor_position`; the structure simulates it when the data do not measure it
        (:func:`~panto.identification.diagnosis.ranking.head_signal`). None: not tried.
    """

    position: str | None = "y_cb"
    velocity: str | None = None
    acceleration: str | None = None
    force: str | None = "F_c"
    actuators: tuple[str, ...] = ("eta", "p")
    mode_drive: str | None = None
    sensor_position: str | None = "eta"
    head_position: str | None = "xi"


PANTOGRAPH_ROLES = SignalRoles()


@dataclass(frozen=True)
class RegressorOptions:
    """Grids of the regressor variants (relative to the signals, so they suit any system)."""

    friction_widths: tuple[float, ...] = (0.0, 0.01, 0.03, 0.1, 0.3)
    """``v_s / std(v)``; 0 gives ``sign(v)``."""
    dead_zone_widths: tuple[float, ...] = (0.05, 0.1, 0.2, 0.4)
    """``b / max|s~|``."""
    zone_centres: tuple[float, ...] = (0.1, 0.25, 0.75, 0.9)
    """Quantile levels of an actuator input where narrow dead zones are tried besides its median
    and its first sample (an actuator at rest)."""
    narrow_zone: float = 0.02
    """``b / max|s~|`` of those narrow zones."""
    max_delay: int = 50
    """Longest delay tried [samples]."""
    n_delays: int = 12
    lag_samples: tuple[float, ...] = (1, 2, 4, 8, 16, 32, 64, 128)
    """Actuator time constants tried [samples]."""
    n_modes: int = 16
    mode_dampings: tuple[float, ...] = (0.02, 0.1)
    saturation_quantiles: tuple[float, ...] = (0.8, 0.9, 0.95, 0.99)
    """Upper clipping quantile ``q``; the lower one is ``1 - q``."""
    derivative_cutoff: float = 0.2
    """Low-pass cutoff of the differentiation, fraction of the Nyquist frequency."""


def differentiate(x: np.ndarray, sample_period: float, *, cutoff: float = 0.2) -> np.ndarray:
    """Zero-phase filtered derivative: 4th-order Butterworth at `cutoff` Nyquist, then centred
    differences (``np.gradient``)."""
    sos = sps.butter(4, cutoff, output="sos")
    return np.gradient(sps.sosfiltfilt(sos, np.asarray(x, float)), sample_period)


def sensor_acceleration(x: np.ndarray, sample_period: float) -> np.ndarray:
    """Acceleration of the force sensor's side: the compact second difference
    ``(x[k+1] - 2 x[k] + x[k-1]) / T^2`` (ends repeated), no further low-pass.

    Its response ``(2 sin(w T / 2) / T)^2`` stays within 13 % of ``w^2`` up to a fifth of the
    sampling rate (10 Hz at 50 Hz), where ``np.gradient`` applied twice,
    ``(sin(w T) / T)^2``, loses 43 %, and a further low-pass at 0.4 Nyquist more: a mass fitted
    on such an acceleration comes out too large by the lost share (1.77 instead of 1.5 kg for
    the rig's bar on 50 Hz data). The data are already band-limited by the anti-alias filter the
    force passed too, so the force's ``m a`` part and this acceleration share their band.
    """
    x = np.asarray(x, float)
    if len(x) < 3:
        return np.zeros(len(x))
    a = np.empty(len(x))
    a[1:-1] = (x[2:] - 2.0 * x[1:-1] + x[:-2]) / sample_period ** 2
    a[0], a[-1] = a[1], a[-2]
    return a


def sensor_signal(roles: SignalRoles, names: Sequence[str]) -> str | None:
    """The signal whose acceleration the force sensor's mass follows: ``roles.sensor_position``
    when `names` hold it, else ``roles.position`` (None when neither is there)."""
    for name in (roles.sensor_position, roles.position):
        if name is not None and name in names:
            return name
    return None


def _centred(x: np.ndarray) -> np.ndarray:
    return x - np.median(x)


def friction_regressors(v: np.ndarray, options: RegressorOptions = RegressorOptions()
                        ) -> dict[str, Regressor]:
    """``sign(v)`` and ``tanh(v / v_s)`` variants of a velocity `v` [m/s] (``v_s`` relative to its
    spread)."""
    scale = float(np.std(v)) or 1.0
    out = {}
    for w in options.friction_widths:
        out["sign(v)" if w == 0 else f"tanh(v/{w * scale:.3g})"] = (
            np.sign(v) if w == 0 else np.tanh(v / (w * scale)), {"v_s": w * scale})
    return out


def _presliding(x: np.ndarray, options: RegressorOptions) -> dict[str, Regressor]:
    """Friction that sticks: ``(x - play_b(x)) / b`` in ``[-1, 1]``, the elasto-plastic
    (presliding) friction law: the force grows with the displacement since the last reversal with
    the stiffness ``F_f / b`` and saturates at ``F_f`` once the joint slides. A joint driven
    through a compliance (the pantograph's hinge, moved by the wire through the head suspension)
    sticks for a while at each reversal, which ``tanh(v / v_s)`` of the nominal velocity misses."""
    spread = float(np.max(np.abs(_centred(x))))
    out = {}
    for w in options.dead_zone_widths:
        b = 0.5 * w * spread
        if b > 0:
            out[f"presliding(position, {b:.3g})"] = ((x - play_operator(x, b)) / b,
                                                     {"presliding": b})
    return out


def _dead_zones(signals: Mapping[str, np.ndarray], names: Sequence[str],
                options: RegressorOptions) -> dict[str, Regressor]:
    """Static dead zone of actuator inputs: ``dz(s~, b) - s~ = -clip(s~, -b, b)`` about the
    median, and narrow zones (:attr:`RegressorOptions.narrow_zone`) about the first sample and
    the quantiles :attr:`RegressorOptions.zone_centres`: a zone much narrower than the travel acts
    like a relay where the input crosses its centre, a signature the median's zones miss when the
    centre lies elsewhere."""
    out = {}
    for name in names:
        s = _centred(signals[name])
        for w in options.dead_zone_widths:
            b = w * float(np.max(np.abs(s)))
            out[f"dz({name}, {b:.3g})"] = (-np.clip(s, -b, b), {"signal": name, "width": b})
        u = np.asarray(signals[name], float)
        b = options.narrow_zone * float(np.max(np.abs(s)))
        centres = [float(u[0])] + [float(c) for c in np.quantile(u, options.zone_centres)]
        for c in centres if b > 0 else ():
            out[f"dz({name} - {c:.4g}, {b:.3g})"] = (-np.clip(u - c, -b, b),
                                                     {"signal": name, "width": b, "centre": c})
    return out


def play_operator(x: np.ndarray, half_width: float) -> np.ndarray:
    """Backlash (play) operator: ``p(t) = min(x + b, max(x - b, p(t - 1)))``, ``p(0) = x(0)``.

    ``p - x`` lies in ``[-b, b]`` and flips when the relative motion reverses: the burst a
    backlash adds (a static dead zone on a displacement would only mimic a stiffness change).
    """
    out = np.empty(len(x))
    p = float(x[0])
    for t, value in enumerate(np.asarray(x, float).tolist()):
        p = min(value + half_width, max(value - half_width, p))
        out[t] = p
    return out


def _backlash(x: np.ndarray, options: RegressorOptions) -> dict[str, Regressor]:
    spread = float(np.max(np.abs(_centred(x))))
    out = {}
    for w in options.dead_zone_widths:
        b = 0.5 * w * spread
        out[f"backlash(position, {b:.3g})"] = (play_operator(x, b) - x,
                                               {"signal": "position", "half_width": b})
    return out


def _delays(u: np.ndarray, name: str, options: RegressorOptions, dt: float) -> dict[str, Regressor]:
    delays = np.unique(np.round(np.geomspace(1, options.max_delay, options.n_delays)).astype(int))
    out = {}
    for d in delays[delays < len(u)]:
        shifted = np.r_[np.full(d, u[0]), u[:-d]]
        out[f"{name}(t-{d})"] = (shifted - u, {"input": name, "delay_samples": int(d),
                                              "delay_s": d * dt})
    return out


def first_order_lag(u: np.ndarray, time_constant: float, sample_period: float) -> np.ndarray:
    """``w`` of ``T w' + w = u`` at the samples of `u`, exact for an input linear between samples
    (first-order hold, the structures' input convention), started at rest at ``u[0]``.

    With ``a = exp(-h / T)``: ``w_k = a w_(k-1) + b0 u_k + b1 u_(k-1)``, ``b0 = 1 - (T / h)(1 - a)``,
    ``b1 = (T / h)(1 - a) - a``. (A zero-order-hold filter ``w_k = a w_(k-1) + (1 - a) u_k`` delays
    a lag shorter than a sample by ``h a / (1 - a)`` instead of ``T``: a 4 ms lag at 100 Hz came
    out as 1 ms, so that a delay imitated it better than the lag itself.) ``T`` in s, ``h`` the
    sample period in s; ``T`` below a millionth of ``h`` returns `u`."""
    u = np.asarray(u, float)
    if not time_constant > 1e-6 * sample_period:
        return u.copy()
    a = math.exp(-sample_period / time_constant)
    ratio = time_constant / sample_period * (1.0 - a)
    b = [1.0 - ratio, ratio - a]
    return sps.lfilter(b, [1.0, -a], u, zi=sps.lfilter_zi(b, [1.0, -a]) * u[0])[0]


def _lags(u: np.ndarray, name: str, options: RegressorOptions, dt: float) -> dict[str, Regressor]:
    out = {}
    for samples in options.lag_samples:
        filtered = first_order_lag(u, samples * dt, dt)
        out[f"lag({name}, {samples * dt:.3g} s)"] = (filtered - u, {"input": name,
                                                                  "time_constant_s": samples * dt})
    return out


def _modes(w: np.ndarray, name: str, options: RegressorOptions, dt: float) -> dict[str, Regressor]:
    w = _centred(w)
    nyquist = 0.5 / dt
    low = max(4.0 / (len(w) * dt), nyquist / 500)
    out = {}
    for f in np.geomspace(low, 0.8 * nyquist, options.n_modes):
        for zeta in options.mode_dampings:
            omega = 2 * np.pi * f
            b, a = sps.bilinear([omega ** 2], [1, 2 * zeta * omega, omega ** 2], 1 / dt)
            response = sps.lfilter(b, a, w, zi=sps.lfilter_zi(b, a) * w[0])[0]
            out[f"mode({name}, {f:.3g} Hz, {zeta})"] = (response - w, {
                "drive": name, "frequency_hz": float(f), "damping": zeta})
    return out


def _saturations(signals: Mapping[str, np.ndarray], names: Sequence[str],
                 options: RegressorOptions, one_sided: Sequence[str] = ()) -> dict[str, Regressor]:
    """Clips of each signal at its quantiles on both sides, and those in `one_sided` on one side
    only as well (a force sensor's range limits the side the force's operating point is near;
    a clip of the other tail too spoils the regressor: seen held-out three-mass/saturation/2155,
    a force clipped at 149 N on 13 % of the samples, not ranked). A one-sided clip's other limit
    starts beyond the signal's range by the range. Not for the inputs: there a one-sided clip
    took a dead zone's refit (tuning three-mass/dead_zone/48, named right before, then
    `unexplained`)."""
    out = {}
    for name in names:
        s = signals[name]
        below, above = float(np.min(s)), float(np.max(s))
        room = max(above - below, 1e-12)
        for q in options.saturation_quantiles:
            lo, hi = (float(v) for v in np.quantile(s, [1 - q, q]))
            clips = [(f"sat({name}, {q})", lo, hi)]
            if name in one_sided:
                clips += [(f"sat({name} <= q{q})", below - room, hi),
                          (f"sat({name} >= q{1 - q:.2g})", lo, above + room)]
            for label, low, high in clips:
                out[label] = (np.clip(s, low, high) - s, {"signal": name, "low": low,
                                                          "high": high})
    return out


def _signal(signals: Mapping[str, np.ndarray], name: str, n: int) -> np.ndarray:
    if name not in signals:
        raise IdentificationError(f"signal role names {name!r}, not among {sorted(signals)}")
    x = np.asarray(signals[name], float).ravel()
    if len(x) != n or not np.all(np.isfinite(x)):
        raise IdentificationError(f"signal {name!r}: need {n} finite samples")
    return x


def name_signals(inputs: np.ndarray, input_names: Sequence[str], simulated: np.ndarray,
                 output_names: Sequence[str]) -> dict[str, np.ndarray]:
    """``{name: samples}`` of the inputs and the nominal model's free-run outputs (the signals the
    regressors are built from: simulated, so the measurement noise stays out of them)."""
    inputs = np.asarray(inputs, float).reshape(len(inputs), -1)
    simulated = np.asarray(simulated, float).reshape(len(inputs), -1)
    named = dict(zip(input_names, inputs.T))
    named.update(zip(output_names, simulated.T))
    return named


def build_candidate_regressors(signals: Mapping[str, np.ndarray], sample_period: float, *,
                               roles: SignalRoles = PANTOGRAPH_ROLES,
                               options: RegressorOptions = RegressorOptions()
                               ) -> dict[str, dict[str, Regressor]]:
    """Regressor variants per effect from named signals (roles absent from `signals` are skipped).

    Returns ``{effect: {variant label: (samples, setting)}}``; effects whose roles are missing
    (e.g. no force for contact_loss) are left out.
    """
    n = len(next(iter(signals.values())))
    get = lambda name: _signal(signals, name, n)
    has = lambda name: name is not None and name in signals
    dt, cutoff = sample_period, options.derivative_cutoff
    actuators = [a for a in roles.actuators if has(a)]
    position = get(roles.position) if has(roles.position) else None
    velocity = get(roles.velocity) if has(roles.velocity) else (
        differentiate(position, dt, cutoff=cutoff) if position is not None else None)
    out: dict[str, dict[str, Regressor]] = {"offset": {"constant": (np.ones(n), {})}}
    if velocity is not None:
        out["coulomb_friction"] = friction_regressors(velocity, options)
        if position is not None:
            out["coulomb_friction"].update(_presliding(position, options))
    if position is not None:
        x = _centred(position)
        out["cubic_stiffness"] = {"x^3": (x ** 3, {}), "x|x|": (x * np.abs(x), {})}
    zones = _dead_zones({a: get(a) for a in actuators}, actuators, options)
    if position is not None:
        zones.update(_backlash(position, options))
    if zones:
        out["dead_zone"] = zones
    if actuators:
        out["input_delay"] = {k: v for a in actuators for k, v in _delays(get(a), a, options, dt).items()}
        out["actuator_lag"] = {k: v for a in actuators for k, v in _lags(get(a), a, options, dt).items()}
    sensor = sensor_signal(roles, list(signals))
    if has(roles.acceleration) and sensor in (None, roles.position):  # the position's, named
        out["sensor_inertia"] = {roles.acceleration: (get(roles.acceleration), {"signal": sensor})}
    elif sensor is not None:
        out["sensor_inertia"] = {f"{sensor}''": (sensor_acceleration(get(sensor), dt),
                                                 {"signal": sensor})}
    head = roles.head_position
    if has(head) and head != sensor:  # the strips' mass above load cells inside the head
        out.setdefault("sensor_inertia", {})[f"{head}''"] = (sensor_acceleration(get(head), dt),
                                                             {"signal": head})
    drive = roles.mode_drive or (roles.force if has(roles.force) else (actuators or [None])[0])
    if drive is not None and has(drive):
        out["extra_mode"] = _modes(get(drive), drive, options, dt)
    if has(roles.force):
        force = get(roles.force)
        out["contact_loss"] = {"max(F,0)-F": (np.maximum(force, 0) - force, {})}
    clipped = actuators + ([roles.force] if has(roles.force) else [])
    if clipped:
        out["saturation"] = _saturations({c: get(c) for c in clipped}, clipped, options,
                                         one_sided=[roles.force] if has(roles.force) else [])
    return out


@dataclass(frozen=True)
class EffectScore:
    """One effect's best regressor variant at one FROLS step."""

    effect: str
    variant: str
    setting: Mapping[str, float | int | str]
    err: float
    correlation: float
    bound: float
    significant: bool
    coefficient: float = math.nan
    """Least-squares weight of the variant (target units per regressor unit), selected steps only."""


@dataclass(frozen=True)
class EffectRanking:
    """FROLS ranking of candidate effects on a residual.

    Attributes
    ----------
    steps : tuple of EffectScore
        Forward-selected effects in order (``significant`` says whether each step passed).
    first_step : tuple of EffectScore
        Every effect's best variant scored alone on the base-projected target, best first.
    target_rms, remaining_rms : float
        RMS of the base-projected target and of what the significant steps leave.
    """

    steps: tuple[EffectScore, ...]
    first_step: tuple[EffectScore, ...]
    target_rms: float
    remaining_rms: float
    n_samples: int

    @property
    def selected(self) -> tuple[str, ...]:
        """Effects of the leading significant steps (empty: nothing explains the residual)."""
        names = []
        for step in self.steps:
            if not step.significant:
                break
            names.append(step.effect)
        return tuple(names)

    @property
    def ranking(self) -> tuple[str, ...]:
        """Selected effects, then the others by their first-step ERR."""
        rest = [s.effect for s in self.first_step if s.effect not in self.selected]
        return self.selected + tuple(rest)

    def err(self, effect: str) -> float:
        """First-step ERR of `effect` (NaN when it had no regressor)."""
        return next((s.err for s in self.first_step if s.effect == effect), math.nan)

    def to_dict(self) -> dict:
        """JSON-ready: ranking, selected, per-step and per-effect scores."""
        clean = lambda s: {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                           for k, v in asdict(s).items()}
        return {"ranking": list(self.ranking), "selected": list(self.selected),
                "steps": [clean(s) for s in self.steps],
                "candidates": [clean(s) for s in self.first_step],
                "target_rms": self.target_rms, "remaining_rms": self.remaining_rms,
                "n_samples": self.n_samples}


def _autocorrelation(x: np.ndarray, max_lag: int) -> np.ndarray:
    """Uncentred ``rho(k) = sum x(t) x(t-k) / sum x^2`` for ``k = 0..M`` (regression through 0)."""
    size = 1 << int(np.ceil(np.log2(2 * len(x))))
    spectrum = np.fft.rfft(x, size)
    r = np.fft.irfft(np.abs(spectrum) ** 2, size)[:max_lag + 1]
    return r / r[0] if r[0] > 0 else np.zeros(max_lag + 1)


def _project_out(matrix: np.ndarray | None, x: np.ndarray) -> np.ndarray:
    return x if matrix is None or matrix.shape[1] == 0 else x - matrix @ (matrix.T @ x)


@dataclass(frozen=True)
class RankingOptions:
    """How far :func:`rank_effects` selects and when a step is significant."""

    max_steps: int = 3
    """Forward-selection steps recorded."""
    z: float = 2.58
    """Two-sided normal quantile of the per-test level; Bonferroni-corrected over the tests."""
    min_err: float = 0.01
    """Smallest error-reduction ratio (share of the target's energy, 0..1) of a significant step."""
    max_lag: int = 100
    """Lags [samples] in ``P = sum rho_w(k) rho_r(k)``."""


def rank_effects(target: np.ndarray, regressors: Mapping[str, Mapping[str, Regressor]], *,
                 base: np.ndarray | None = None,
                 sensitivity: Callable[[np.ndarray], np.ndarray] | None = None,
                 options: RankingOptions = RankingOptions()) -> EffectRanking:
    """Rank candidate effects by the share of `target` their signature explains (FROLS/ERR).

    Parameters
    ----------
    target : ndarray, shape (N,)
        Free-run residual ``y - y_hat`` of one output, or an equation-error residual/target.
    regressors : mapping
        :func:`build_candidate_regressors` output (or any ``{effect: {variant: (x, setting)}}``).
    base : ndarray, shape (N, p), optional
        Columns projected out first (nominal-parameter sensitivities ``dy_hat/dtheta`` or nominal
        regressors).
    sensitivity : callable, optional
        ``S(phi) -> phi_out``: how an additive term reaches the output (e.g. the nominal model's
        filter from its input); applied to every regressor (not to `base`).
    options : RankingOptions
        Steps recorded; significance ``|corr| > z_B sqrt(P / N)`` (``z_B`` Bonferroni-corrected
        from the two-sided level of ``z``) and ``ERR >= min_err``; lags in ``P``.
    """
    r = np.asarray(target, float).ravel()
    n = len(r)
    q_base = None
    if base is not None and np.size(base):
        q_base, _ = np.linalg.qr(np.asarray(base, float).reshape(n, -1))
    r = _project_out(q_base, r)
    energy0 = _dot(r, r)
    if energy0 <= 0:
        raise IdentificationError("target is explained entirely by the base columns")
    columns = _columns(regressors, sensitivity, q_base, n)
    steps, first, raw = _forward_selection(columns, r, energy0, options)
    steps = _with_coefficients(steps, raw, np.asarray(target, float).ravel(), q_base)
    kept = [i for i, s in enumerate(steps) if s.effect in _leading(steps)]
    remaining = _project_out(q_base, np.asarray(target, float).ravel())
    if kept:
        basis = np.column_stack([raw[i] for i in kept])
        coefficients, *_ = np.linalg.lstsq(basis, remaining, rcond=None)
        remaining = remaining - basis @ coefficients
    return EffectRanking(tuple(steps), tuple(first), math.sqrt(energy0 / n),
                         float(np.sqrt(np.mean(remaining ** 2))), n)


def _columns(regressors: Mapping[str, Mapping[str, Regressor]],
             sensitivity: Callable[[np.ndarray], np.ndarray] | None, q_base: np.ndarray | None,
             n: int) -> dict[tuple[str, str], tuple[np.ndarray, dict, float]]:
    """Per (effect, variant): the regressor through `sensitivity`, the base projected out, its
    setting and its squared norm before the projection."""
    columns = {}
    for effect, variants in regressors.items():
        for label, (x, setting) in variants.items():
            x = np.asarray(x, float).ravel()
            x = sensitivity(x) if sensitivity else x
            if len(x) != n:
                raise IdentificationError(f"{effect} regressor {label!r}: {len(x)} samples, "
                                          f"target has {n}")
            columns[(effect, label)] = (_project_out(q_base, x), dict(setting), _dot(x, x))
    return columns


def _forward_selection(columns: Mapping[tuple[str, str], tuple[np.ndarray, dict, float]],
                       r: np.ndarray, energy0: float, options: RankingOptions
                       ) -> tuple[list[EffectScore], list[EffectScore], list[np.ndarray]]:
    """FROLS: the best effect per step on what the steps before leave; returns the steps, the
    first step's scores of every effect (best first) and the steps' projected regressors."""
    alpha = 2 * stats.norm.sf(options.z)
    steps, chosen, raw = [], [], []
    first: list[EffectScore] = []
    for step in range(options.max_steps):
        scores = _score_all(columns, chosen, r, energy0, alpha, options.max_lag)
        if step == 0:
            first = sorted(scores.values(), key=lambda s: -s.err)
        candidates = [s for s in scores.values() if s.effect not in {c.effect for c in steps}]
        if not candidates:
            break
        best = max(candidates, key=lambda s: s.err)
        best = _with_significance(best, options.min_err)
        w = _orthogonal(columns[(best.effect, best.variant)][0], chosen)
        r = r - w * _dot(w, r) / _dot(w, w)
        chosen.append(w / math.sqrt(_dot(w, w)))
        raw.append(columns[(best.effect, best.variant)][0])
        steps.append(best)
    return steps, first, raw


def _leading(steps: Sequence[EffectScore]) -> set[str]:
    names = set()
    for s in steps:
        if not s.significant:
            break
        names.add(s.effect)
    return names


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """Inner product without BLAS threads (they thrash when cores are shared)."""
    return float(np.einsum("i,i->", a, b))


def _orthogonal(x: np.ndarray, chosen: Sequence[np.ndarray]) -> np.ndarray:
    for q in chosen:
        x = x - q * _dot(q, x)
    return x


def _score_all(columns: Mapping[tuple[str, str], tuple[np.ndarray, dict, float]],
               chosen: Sequence[np.ndarray], r: np.ndarray, energy0: float, alpha: float,
               max_lag: int) -> dict[str, EffectScore]:
    """Best variant per effect: ERR of each orthogonalised variant on the current residual."""
    best: dict[str, tuple[float, str, np.ndarray, dict]] = {}
    for (effect, label), (x, setting, norm2) in columns.items():
        w = _orthogonal(x, chosen)
        ww = _dot(w, w)
        if ww <= 1e-8 * max(norm2, 1e-300):
            continue
        err = _dot(w, r) ** 2 / (ww * energy0)
        if effect not in best or err > best[effect][0]:
            best[effect] = (err, label, w, setting)
    n_tests = max(1, sum(1 for _ in columns))
    z_corrected = float(stats.norm.isf(alpha / (2 * n_tests)))
    rho_r = _autocorrelation(r, max_lag)
    scores = {}
    for effect, (err, label, w, setting) in best.items():
        corr = _dot(w, r) / math.sqrt(_dot(w, w) * max(_dot(r, r), 1e-300))
        rho_w = _autocorrelation(w, max_lag)
        p = max(1.0, float(rho_w[0] * rho_r[0] + 2 * np.sum(rho_w[1:] * rho_r[1:])))
        bound = z_corrected * math.sqrt(p / len(r))
        scores[effect] = EffectScore(effect, label, setting, err, corr, bound, abs(corr) > bound)
    return scores


def _with_significance(score: EffectScore, min_err: float) -> EffectScore:
    return EffectScore(score.effect, score.variant, score.setting, score.err, score.correlation,
                       score.bound, score.significant and score.err >= min_err)


def _with_coefficients(steps: list[EffectScore], raw: list[np.ndarray], target: np.ndarray,
                       q_base: np.ndarray | None) -> list[EffectScore]:
    if not steps:
        return steps
    basis = np.column_stack([_project_out(q_base, x) for x in raw])
    coefficients, *_ = np.linalg.lstsq(basis, _project_out(q_base, target), rcond=None)
    return [EffectScore(s.effect, s.variant, s.setting, s.err, s.correlation, s.bound,
                        s.significant, float(c)) for s, c in zip(steps, coefficients)]


def filter_sensitivity(numerator: Sequence[float], denominator: Sequence[float]
                       ) -> Callable[[np.ndarray], np.ndarray]:
    """``S(phi) = B(q)/A(q) phi`` from rest: the path of an additive input-side term to the output
    of a linear (e.g. output-error) nominal model."""
    b, a = np.asarray(numerator, float), np.asarray(denominator, float)
    return lambda x: sps.lfilter(b, a, x)


def output_error_sensitivities(numerator: Sequence[float], denominator: Sequence[float],
                               u: np.ndarray) -> np.ndarray:
    """``dy_hat/dtheta`` of the OE model ``y_hat = B(q)/F(q) u``, ``B = sum_k b_k q^-k`` (k from 0),
    ``F = 1 + sum_k f_k q^-k``: ``q^-k u / F`` per ``b_k`` and ``-q^-k y_hat / F`` per ``f_k``.

    Use as the `base` of :func:`rank_effects` on the residual of a linear OE nominal model.
    """
    b, f = np.asarray(numerator, float), np.asarray(denominator, float)
    u = np.asarray(u, float).ravel()
    y_hat = sps.lfilter(b, f, u)
    u_f, y_f = sps.lfilter([1.0], f, u), sps.lfilter([1.0], f, y_hat)
    shift = lambda x, k: np.r_[np.zeros(k), x[:len(x) - k]]
    columns = [shift(u_f, k) for k in range(len(b)) if b[k] != 0 or k > 0]
    columns += [-shift(y_f, k) for k in range(1, len(f))]
    return np.column_stack(columns)
