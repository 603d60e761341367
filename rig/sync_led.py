"""The synchronisation LED: a seeded pseudo-random binary sequence with random hold times.

The thesis' real-time unit drove an LED seen by the camera with a pseudo-random binary sequence,
hold times between 5 ms and 30 ms, sampled at 500 Hz; the camera (50 Hz, 2 ms shutter) records
the same sequence coarsely, and cross-correlation aligns the two time bases (thesis section 3.2,
Figs. 3.7-3.8). Here each hold is a whole number of samples drawn uniformly from
``ceil(min_hold * fs) .. floor(max_hold * fs)`` (at 500 Hz and 5-30 ms: 3 to 15 samples, i.e.
6 ms to 30 ms, since 5 ms is not a whole number of 2 ms samples), and the bit toggles after each
hold, starting with the LED off.

:func:`generate_led_bits` gives a whole run at once, :class:`LedStream` one bit per call; both
draw the hold times from the generator in the same blocks, so they give identical bits.
"""
from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

_BLOCK = 256  # hold times drawn per call to the generator (same in both forms)


@dataclass(frozen=True, kw_only=True)
class LedOptions:
    """Settings of the LED sequence.

    Parameters
    ----------
    enabled : bool
        Drive the LED (``False``: it stays off).
    min_hold, max_hold : float
        Shortest and longest hold time [s] (thesis section 3.2: 5 ms and 30 ms).
    """

    enabled: bool = True
    min_hold: float = 0.005
    max_hold: float = 0.030

    def __post_init__(self) -> None:
        if not (math.isfinite(self.min_hold) and self.min_hold > 0.0):
            raise ValueError(f"min_hold = {self.min_hold!r}: must be > 0 s")
        if not (math.isfinite(self.max_hold) and self.max_hold >= self.min_hold):
            raise ValueError(f"max_hold = {self.max_hold!r}: must be >= min_hold = "
                             f"{self.min_hold} s")

    def hold_samples(self, sample_rate: float) -> tuple[int, int]:
        """Shortest and longest hold in whole samples at `sample_rate` [Hz]."""
        low = max(1, math.ceil(self.min_hold * sample_rate - 1e-9))
        high = math.floor(self.max_hold * sample_rate + 1e-9)
        if low > high:
            raise ValueError(f"max_hold = {self.max_hold}: no whole number of samples at "
                             f"{sample_rate} Hz lies in [{self.min_hold}, {self.max_hold}] s")
        return low, high


def _hold_blocks(rng: np.random.Generator, low: int, high: int) -> Iterator[np.ndarray]:
    while True:
        yield rng.integers(low, high, size=_BLOCK, endpoint=True)


class LedStream:
    """The LED sequence one sample at a time, for the real-time loop.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the hold times (seeded by the profile).
    options : LedOptions, optional
    sample_rate : float, optional
        Samples per second [Hz] (500 Hz as the thesis' real-time unit).

    Examples
    --------
    >>> import numpy as np
    >>> stream = LedStream(np.random.default_rng(3))
    >>> bits = [stream.next() for _ in range(1000)]
    >>> bits == generate_led_bits(1000, np.random.default_rng(3)).tolist()
    True
    """

    def __init__(self, rng: np.random.Generator, options: LedOptions | None = None, *,
                 sample_rate: float = 500.0) -> None:
        self.options = options or LedOptions()
        low, high = self.options.hold_samples(sample_rate)
        self._blocks = _hold_blocks(rng, low, high)
        self._holds = iter(())
        self._bit = 1  # toggled to 0 before the first hold
        self._left = 0

    def next(self) -> int:
        """The next bit (0 or 1)."""
        if not self.options.enabled:
            return 0
        if self._left == 0:
            try:
                self._left = int(next(self._holds))
            except StopIteration:
                self._holds = iter(next(self._blocks))
                self._left = int(next(self._holds))
            self._bit ^= 1
        self._left -= 1
        return self._bit

    def __iter__(self) -> "LedStream":
        return self

    def __next__(self) -> int:
        return self.next()


def generate_led_bits(count: int, rng: np.random.Generator, options: LedOptions | None = None,
                      *, sample_rate: float = 500.0) -> np.ndarray:
    """The first `count` bits of the LED sequence (``uint8`` array of 0 and 1).

    Identical to `count` calls of :meth:`LedStream.next` on a generator in the same state.
    """
    options = options or LedOptions()
    if not options.enabled:
        return np.zeros(count, dtype=np.uint8)
    low, high = options.hold_samples(sample_rate)
    holds: list[np.ndarray] = []
    total = 0
    for block in _hold_blocks(rng, low, high):
        if total >= count:
            break
        holds.append(block)
        total += int(block.sum())
    lengths = np.concatenate(holds) if holds else np.zeros(0, dtype=np.int64)
    bits = (np.arange(lengths.size) % 2).astype(np.uint8)
    return np.repeat(bits, lengths)[:count]


def run_lengths(bits: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values and lengths [samples] of the runs of equal consecutive values in `bits`."""
    bits = np.asarray(bits)
    if bits.size == 0:
        return bits[:0], np.zeros(0, dtype=np.int64)
    edges = np.flatnonzero(np.diff(bits) != 0) + 1
    starts = np.concatenate([[0], edges])
    ends = np.concatenate([edges, [bits.size]])
    return bits[starts], ends - starts
