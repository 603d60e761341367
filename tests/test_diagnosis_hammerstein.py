"""An input saturation in front of fast linear dynamics, measured on a generic output (no contact
force, so the challenge may refit a clip-shaped kink of the output: challenge.a_clip's
`clippable` is empty). The output is then nearly a clipped copy of the linear response, the case
where the challenge's out-of-vocabulary kink comes closest to the vocabulary's saturation: the
saturation must still be named, with its limits, and stand against the challenge (a risk noted in
session 51; written here as an independent Hammerstein plant, not one of the benchmark's)."""
import numpy as np
import pytest
from scipy import signal

from panto.identification.diagnosis.pipeline import diagnose
from panto.identification.estimation.base import IdentificationData

FS = 100.0  # Hz
SAMPLES = 2000


def _hammerstein(seed: int, low: float, high: float) -> IdentificationData:
    """A random-phase multisine of 39 lines 0.05-1.95 Hz (unit standard deviation), clipped to
    ``[low, high]``, through a 40 Hz, damping 0.5 second-order low-pass (unit static gain,
    first-order hold), 2 % output noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(SAMPLES) / FS
    u = sum(np.cos(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
            for f in np.arange(1, 40) * 0.05)
    u = u / np.std(u)
    w = 2 * np.pi * 40.0
    b, a, _ = signal.cont2discrete(([w * w], [1, 2 * 0.5 * w, w * w]), 1 / FS, method="foh")
    y = signal.lfilter(b.ravel(), a, np.clip(u, low, high))
    y = y + 0.02 * np.std(y) * rng.standard_normal(SAMPLES)
    return IdentificationData(t, u[:, None], y[:, None], ("u",), ("y",), source=f"seed {seed}")


@pytest.mark.parametrize("low, high", [(-1.2, 1.2), (-99.0, 0.8)], ids=["both", "upper"])
def test_an_input_saturation_before_fast_dynamics_is_named_and_stands_against_the_output_clip(
        low, high):
    lines: list[str] = []
    result = diagnose(_hammerstein(1, low, high), _hammerstein(2, low, high),
                      structure="linear-2", progress=lines.append)
    assert result.verdict == "effect"
    assert result.effects == ("saturation",)
    limits = result.steps[0].parameters
    assert limits["saturation:u:high"] == pytest.approx(high, rel=0.05)
    if low > -10:  # the lower limit is reached only where it lies inside the signal's range
        assert limits["saturation:u:low"] == pytest.approx(low, rel=0.05)
    # the gap closes to the noise (2 %: a fit of at most about 98 %)
    assert result.fit_before["y"] < 80.0
    assert result.fit_after["y"] > 96.0
    # the challenge ran against it and its best term gained less
    assert any("challenging it with out-of-vocabulary terms on y" in line for line in lines)
    assert any(line.startswith("diagnose: the accepted effects stand") for line in lines)
