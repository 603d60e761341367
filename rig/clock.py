"""Clocks for the rig's cyclic loops: the wall clock on the rig, a simulated clock in tests.

The linear-motor stream runs at 250 Hz: a setpoint and a SYNC frame every :math:`T = 4` ms. A loop
that sleeps a fixed :math:`T` after each cycle accumulates its processing time and drifts; this
module's loops wait for absolute deadlines :math:`t_k = t_0 + k\\,T` instead, so the mean period
stays exactly :math:`T` and a late cycle does not shift the later ones (:class:`Ticker`).

:class:`RealClock` reads ``time.monotonic`` and sleeps. :class:`SimulatedClock` advances only when
told (``advance``/``sleep_until``), so tests and the lock-step virtual test bed run as fast as the
computer allows and never depend on wall-clock timing; before its time moves on, it runs the hooks
registered with :meth:`SimulatedClock.add_hook` (for example the drive emulator's
``process_pending``), which is how a master that waits for a reply lets the emulated drive answer.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Protocol, runtime_checkable


@runtime_checkable
class Clock(Protocol):
    """What the driver, the emulator and the run loop need of a clock (seconds, monotonic)."""

    def now(self) -> float:
        """Current time [s]."""
        ...

    def sleep_until(self, deadline: float) -> None:
        """Return at (or as soon as possible after) `deadline` [s]; at once if it has passed."""
        ...


class RealClock:
    """Wall clock: ``time.monotonic`` and sleeping until absolute deadlines.

    Parameters
    ----------
    spin_margin
        The last `spin_margin` seconds before a deadline are busy-waited instead of slept, which
        trades CPU time for less wake-up jitter. 0 (default) never spins.
    """

    def __init__(self, *, spin_margin: float = 0.0) -> None:
        if not (math.isfinite(spin_margin) and spin_margin >= 0.0):
            raise ValueError(f"spin_margin must be a finite number >= 0, got {spin_margin!r}")
        self._spin_margin = spin_margin

    def now(self) -> float:
        """``time.monotonic()`` [s]."""
        return time.monotonic()

    def sleep_until(self, deadline: float) -> None:
        """Sleep until `deadline` (a ``time.monotonic`` value); never returns early."""
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0.0:
                return
            if remaining > self._spin_margin:
                time.sleep(remaining - self._spin_margin)


class SimulatedClock:
    """A clock whose time moves only when told: for tests and lock-step emulation.

    Parameters
    ----------
    start
        Initial time [s].

    Notes
    -----
    :meth:`sleep_until` and :meth:`advance` first run the registered hooks *at the current time*
    (everything due now is handled before time moves on), then set the time. A hook must not
    move the clock itself.
    """

    def __init__(self, start: float = 0.0) -> None:
        if not math.isfinite(start):
            raise ValueError(f"start must be finite, got {start!r}")
        self._time = float(start)
        self._hooks: list[Callable[[], object]] = []
        self._in_hooks = False

    def now(self) -> float:
        """Current simulated time [s]."""
        return self._time

    def add_hook(self, hook: Callable[[], object]) -> None:
        """Run `hook()` every time before the clock advances (e.g. ``emulator.process_pending``)."""
        self._hooks.append(hook)

    def remove_hook(self, hook: Callable[[], object]) -> None:
        """Stop running `hook`."""
        self._hooks.remove(hook)

    def run_hooks(self) -> None:
        """Run the hooks at the current time without advancing."""
        if self._in_hooks:
            raise RuntimeError("a SimulatedClock hook tried to move the clock")
        self._in_hooks = True
        try:
            for hook in list(self._hooks):
                hook()
        finally:
            self._in_hooks = False

    def sleep_until(self, deadline: float) -> None:
        """Run the hooks, then jump to `deadline` (time never goes backwards)."""
        if not math.isfinite(deadline):
            raise ValueError(f"deadline must be finite, got {deadline!r}")
        self.run_hooks()
        self._time = max(self._time, float(deadline))

    def advance(self, duration: float) -> None:
        """Run the hooks, then move the time forward by `duration` >= 0 [s]."""
        if not (math.isfinite(duration) and duration >= 0.0):
            raise ValueError(f"duration must be a finite number >= 0, got {duration!r}")
        self.sleep_until(self._time + duration)


class Ticker:
    """Absolute deadlines :math:`t_k = t_0 + k\\,T` of a cyclic loop.

    Parameters
    ----------
    clock
        The clock to read and sleep on.
    period
        :math:`T` [s], > 0.
    start
        :math:`t_0`; default: ``clock.now()`` at construction.

    Examples
    --------
    >>> ticker = Ticker(SimulatedClock(), 0.004)
    >>> ticker.wait()   # returns the lateness of the wake-up, 0.0 on a simulated clock
    0.0
    """

    def __init__(self, clock: Clock, period: float, *, start: float | None = None) -> None:
        if not (math.isfinite(period) and period > 0.0):
            raise ValueError(f"period must be a finite number > 0, got {period!r}")
        self._clock = clock
        self._period = float(period)
        self._start = clock.now() if start is None else float(start)
        self._cycle = 0

    @property
    def period(self) -> float:
        """:math:`T` [s]."""
        return self._period

    @property
    def cycle(self) -> int:
        """Index :math:`k` of the last deadline waited for (0 before the first wait)."""
        return self._cycle

    @property
    def next_deadline(self) -> float:
        """:math:`t_{k+1}`, the deadline the next :meth:`wait` sleeps until."""
        return self._start + (self._cycle + 1) * self._period

    def wait(self) -> float:
        """Sleep until the next deadline; return the lateness ``now - deadline`` [s] (>= 0).

        A late wake-up does not shift later deadlines; after a long stall the following waits
        return at once until the loop has caught up.
        """
        deadline = self.next_deadline
        self._clock.sleep_until(deadline)
        self._cycle += 1
        return max(0.0, self._clock.now() - deadline)
