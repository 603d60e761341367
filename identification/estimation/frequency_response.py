"""The frequency response the data hold, and a state-space model's, sample for sample.

- :func:`best_linear_approximation`: the H1 estimate from Welch cross-spectra for several inputs
  (``H = G_yu G_uu^-1`` per frequency), its multiple coherence, the standard error of each element
  and where it can be trusted (module notes of
  :mod:`panto.identification.estimation.global_fit`).
- :func:`discrete_frequency_response`: the response of the exact discretisation (first- or
  zero-order hold) of a continuous ``(A, B, C, D)``, comparable with the H1 estimate up to the
  Nyquist frequency; :func:`modal_frequency_responses`: the same for several systems at once.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
from scipy import linalg, signal

from panto.identification.estimation.base import IdentificationData, IdentificationError

#: Variance inflation of Welch averages with a Hann window at 50 % overlap (Welch 1967).
HANN_OVERLAP_INFLATION = 1.056


@dataclass(frozen=True)
class BestLinearApproximation:
    """The frequency response the data hold, without any structure (H1 estimate).

    Attributes
    ----------
    frequency : ndarray, shape (n_f,)
        Frequencies [Hz].
    response : ndarray, shape (n_f, n_outputs, n_inputs), complex
        H1 estimate, in output units per input unit.
    std : ndarray, shape (n_f, n_outputs, n_inputs)
        Standard error of each element (root mean square of the complex error).
    coherence : ndarray, shape (n_f, n_outputs)
        Multiple coherence of each output with all inputs (0-1).
    trusted : ndarray of bool, shape (n_f, n_outputs, n_inputs)
        Elements whose relative error and coherence pass the thresholds.
    period : float
        Sample period of the data [s].
    averages : float
        Equivalent number of independent averages ``n_d``.
    input_names, output_names : tuple of str
    """

    frequency: np.ndarray
    response: np.ndarray
    std: np.ndarray
    coherence: np.ndarray
    trusted: np.ndarray
    period: float
    averages: float
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]

    def summary(self) -> dict[str, Any]:
        """Trusted band and counts per output/input pair, for reports (JSON-ready)."""
        out: dict[str, Any] = {"averages": self.averages, "pairs": {}}
        for i, o in enumerate(self.output_names):
            for j, u in enumerate(self.input_names):
                f = self.frequency[self.trusted[:, i, j]]
                out["pairs"][f"{u}->{o}"] = {
                    "trusted_bins": int(len(f)),
                    "band_Hz": [float(f.min()), float(f.max())] if len(f) else None}
        return out


# --- best linear approximation ----------------------------------------------------------------

def best_linear_approximation(data: IdentificationData, *, segment: int | None = None,
                              min_coherence: float = 0.5, max_relative_error: float = 0.3,
                              max_frequency: float | None = None) -> BestLinearApproximation:
    """H1 estimate of the frequency response from all inputs to every output (module notes of
    :mod:`panto.identification.estimation.global_fit`).

    Parameters
    ----------
    data : IdentificationData
        Missing output samples (NaN) are interpolated linearly for the spectra.
    segment : int, optional
        Welch segment length [samples] (default the power of two giving about eight segments).
    min_coherence : float
        Multiple coherence below which an output's bins are not trusted.
    max_relative_error : float
        Relative standard error above which an element is not trusted.
    max_frequency : float, optional
        Highest trusted frequency [Hz] (default 0.8 times the Nyquist frequency).
    """
    n, m = data.inputs.shape
    nperseg = int(segment or 2 ** int(np.floor(np.log2(max(n / 4.5, 16)))))
    if nperseg > n or nperseg < 16:
        raise IdentificationError(f"{data.source or 'data'}: {n} samples are too few for a "
                                  f"spectral estimate with segments of {nperseg}")
    step = nperseg // 2
    segments = 1 + (n - nperseg) // step
    averages = segments / HANN_OVERLAP_INFLATION
    if averages <= m + 1:
        raise IdentificationError(f"{data.source or 'data'}: {segments} segments are too few for "
                                  f"{m} inputs; use a shorter segment or a longer record")
    u = data.inputs
    y = np.column_stack([_filled(col) for col in data.outputs.T])
    fs = 1.0 / data.sample_period

    def cross(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return signal.csd(a, b, fs=fs, window="hann", nperseg=nperseg, noverlap=step,
                          detrend="constant")

    freq, _ = cross(u[:, 0], u[:, 0])
    g_uu = np.empty((len(freq), m, m), complex)
    for k in range(m):
        for j in range(m):
            g_uu[:, k, j] = cross(u[:, j], u[:, k])[1]
    g_yu = np.stack([np.stack([cross(u[:, j], y[:, i])[1] for j in range(m)], -1)
                     for i in range(y.shape[1])], 1)
    g_yy = np.stack([cross(y[:, i], y[:, i])[1].real for i in range(y.shape[1])], 1)
    with np.errstate(all="ignore"):
        inverse = np.linalg.pinv(g_uu, rcond=1e-12, hermitian=True)
        response = g_yu @ inverse
        explained = np.einsum("fij,fjk,fik->fi", response, g_uu, response.conj()).real
        coherence = np.clip(explained / g_yy, 0.0, 1.0)
        diag = np.real(np.einsum("fjj->fj", inverse))
        variance = ((1 - coherence) * g_yy)[:, :, None] * diag[:, None, :] / (averages - m)
        std = np.sqrt(np.maximum(variance, 0.0))
        top = 0.8 * fs / 2 if max_frequency is None else float(max_frequency)
        trusted = (std <= max_relative_error * np.abs(response)) & \
            (coherence >= min_coherence)[:, :, None] & \
            ((freq > 0) & (freq <= top))[:, None, None] & np.isfinite(std) & \
            (diag > 0)[:, None, :]  # an input not excited (constant) is dropped by pinv
    return BestLinearApproximation(freq, response, std, coherence, trusted, data.sample_period,
                                   float(averages), data.input_names, data.output_names)


def _filled(column: np.ndarray) -> np.ndarray:
    ok = np.isfinite(column)
    if ok.all() or not ok.any():
        return np.nan_to_num(column)
    index = np.arange(len(column))
    return np.interp(index, index[ok], column[ok])


# --- the structure's frequency response ------------------------------------------------------

def discrete_frequency_response(system: Sequence[np.ndarray], frequency: np.ndarray,
                                period: float, hold: str = "foh", *,
                                stable: bool = False) -> np.ndarray:
    """Frequency response of the exact discretisation of ``(A, B, C, D)`` (module notes of
    :mod:`panto.identification.estimation.global_fit`).

    Parameters
    ----------
    system : (A, B, C, D)
        Continuous state-space model.
    frequency : ndarray
        Frequencies [Hz].
    period : float
        Sample period [s].
    hold : {"foh", "zoh"}
        Inputs linear between samples or held.
    stable : bool
        Raise :class:`IdentificationError` when ``A`` has an eigenvalue with a non-negative real
        part (the response of an unstable model means nothing for a free run).

    Returns
    -------
    ndarray, shape (n_f, n_outputs, n_inputs), complex
    """
    a, b, c, d = _matrices(system)
    lam, vectors = np.linalg.eig(a)
    if stable and np.max(lam.real) >= 0:
        raise IdentificationError("unstable linear system")
    if np.linalg.cond(vectors) < 1e8:
        return _modal_responses(lam[None], vectors[None], b[None], c[None], d[None], frequency,
                                period, hold)[0]
    z = np.exp(2j * np.pi * np.asarray(frequency, float) * period)
    n, m = b.shape
    block = np.zeros((n + 2 * m, n + 2 * m))
    block[:n, :n], block[:n, n:n + m] = a * period, b * period
    block[n:n + m, n + m:] = np.eye(m)
    e = linalg.expm(block)
    phi, gamma0 = e[:n, :n], e[:n, n:n + m]
    gamma1 = e[:n, n + m:] if hold == "foh" else np.zeros((n, m))
    drive = gamma0[None] + (z[:, None, None] - 1) * gamma1[None]
    return c @ np.linalg.solve(z[:, None, None] * np.eye(n) - phi, drive) + d


def modal_frequency_responses(systems: Sequence[Sequence[np.ndarray]], frequency: np.ndarray,
                              period: float, hold: str = "foh", *, stable: bool = False
                              ) -> list[np.ndarray | None]:
    """:func:`discrete_frequency_response` of several systems of the same shapes at once, bit
    for bit, where it takes the modal path: the eigen decompositions, condition numbers, solves
    and products are stacked (numpy calls the same LAPACK or BLAS routine for every matrix of a
    stack), the rest is elementwise.

    Returns
    -------
    list of ndarray or None
        The response of each system, or None where :func:`discrete_frequency_response` must
        answer: a defective, unstable (with `stable`) or non-finite ``A``, one with real
        eigenvalues only (numpy's stacked ``eig`` returns them as complex numbers among systems
        with complex ones, which the single call does not; alone, its real eigenvectors come as
        a strided view that a stack copies, and the product ``C V`` of one output row then sums
        in another order).
    """
    matrices = [_matrices(system) for system in systems]
    if not matrices or len({tuple(x.shape for x in m) for m in matrices}) > 1:
        return [None] * len(matrices)
    a, b, c, d = (np.stack(x) for x in zip(*matrices))
    try:
        lam, vectors = np.linalg.eig(a)
    except np.linalg.LinAlgError:  # a non-finite A, or no convergence for one of them
        return [None] * len(matrices)
    take = np.linalg.cond(vectors) < 1e8
    if stable:
        take &= np.max(lam.real, axis=1) < 0
    if not np.iscomplexobj(lam):
        return [None] * len(matrices)
    take &= np.any(lam.imag != 0, axis=1)
    responses: list[np.ndarray | None] = [None] * len(matrices)
    if take.any():
        for k, response in zip(np.flatnonzero(take), _modal_responses(
                lam[take], vectors[take], b[take], c[take], d[take], frequency, period, hold)):
            responses[k] = response
    return responses


def _matrices(system: Sequence[np.ndarray]) -> tuple[np.ndarray, ...]:
    """``(A, B, C, D)`` as two-dimensional float arrays (a matrix that is one already is
    returned itself, as ``np.atleast_2d(np.asarray(x, float))`` returns it, without their cost:
    this runs for every column of the frequency mapping's Jacobians)."""
    return tuple(x if type(x) is np.ndarray and x.ndim == 2 and x.dtype == np.float64
                 else np.atleast_2d(np.asarray(x, float)) for x in system)


def _modal_responses(lam: np.ndarray, vectors: np.ndarray, b: np.ndarray, c: np.ndarray,
                     d: np.ndarray, frequency: np.ndarray, period: float, hold: str) -> np.ndarray:
    """Responses of a stack of systems from their eigen decompositions ``A = V diag(lambda)
    V^-1`` (module notes of :mod:`panto.identification.estimation.global_fit`), shape
    ``(n_systems, n_f, n_outputs, n_inputs)``."""
    z = np.exp(2j * np.pi * np.asarray(frequency, float) * period)
    x = lam * period
    small = np.abs(x) < 1e-4
    safe = np.where(small, 1.0, x)
    mu = np.exp(x)
    g0 = np.where(small, period * (1 + x / 2 + x * x / 6), (mu - 1) / safe * period)
    g1 = np.where(small, period * (0.5 + x / 6 + x * x / 24),
                  (mu - 1 - x) / (safe * safe) * period)
    if hold != "foh":
        g1 = np.zeros_like(g1)
    modal_b = np.linalg.solve(vectors, b.astype(complex))
    modal_c = c @ vectors
    weights = (g0[:, None] + (z[:, None] - 1) * g1[:, None]) / (z[:, None] - mu[:, None])
    return np.stack([(weights * modal_c[:, None, i]) @ modal_b
                     for i in range(modal_c.shape[1])], 2) + d[:, None]


__all__ = ["BestLinearApproximation", "best_linear_approximation",
           "discrete_frequency_response", "modal_frequency_responses", "HANN_OVERLAP_INFLATION"]
