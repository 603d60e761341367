"""A round's candidate refits in worker processes (issue 24, speed): the same verdict, fits and
progress as in-process; workers limited to one BLAS thread; one worker inside a worker process."""
from __future__ import annotations

import dataclasses
import re
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest
from scipy import signal as sps

from panto.identification.diagnosis import parallel
from panto.identification.diagnosis.pipeline import DiagnosisOptions, diagnose
from panto.identification.estimation.base import IdentificationData, IdentificationError

DT = 0.005


def _run(force: np.ndarray, seed: int) -> IdentificationData:
    """A 2 Hz oscillator with a hardening spring (semi-implicit Euler), 1 % output noise."""
    k, c = (2 * np.pi * 2.0) ** 2, 2 * 0.1 * 2 * np.pi * 2.0
    x = v = previous = 0.0
    out = np.empty(len(force))
    for t, f in enumerate(force.tolist()):
        out[t] = x
        v += DT * (previous - c * v - k * x - 3.0e3 * x ** 3)
        x += DT * v
        previous = f
    noisy = out + 0.01 * np.std(out) * np.random.default_rng(seed).normal(size=len(out))
    return IdentificationData(np.arange(len(out)) * DT, force[:, None], noisy[:, None], ("F",),
                              ("x",), source="synthetic oscillator")


def _force(n: int, seed: int) -> np.ndarray:
    b, a = sps.butter(2, 0.1)
    return 40.0 * sps.lfilter(b, a, np.random.default_rng(seed).normal(size=n))


def test_parallel_refits_give_the_serial_verdict_fits_and_progress():
    train, validation = _run(_force(1500, 1), 3), _run(_force(1500, 2), 4)
    runs = {}
    for workers in (1, 2):
        lines: list[str] = []
        options = DiagnosisOptions(workers=workers, max_effects=1, max_refits=3)
        runs[workers] = (diagnose(train, validation, structure="linear-2", options=options,
                                  progress=lines.append), lines)
    (serial, serial_lines), (pooled, pooled_lines) = runs[1], runs[2]
    assert len(serial.rounds[0]["tried"]) >= 2  # a round the pool really shares out
    assert pooled.verdict == serial.verdict and pooled.effects == serial.effects
    for name in ("fit_before", "fit_after", "fit_train"):
        assert getattr(pooled, name) == pytest.approx(getattr(serial, name), rel=1e-9, abs=1e-9)
    assert pooled.final_parameters == pytest.approx(serial.final_parameters, rel=1e-9)
    tried = [[(t["effect"], t["accepted"]) for t in r["tried"]] for r in serial.rounds]
    assert tried == [[(t["effect"], t["accepted"]) for t in r["tried"]] for r in pooled.rounds]
    assert _untimed(pooled_lines) == _untimed(serial_lines)  # the refits' lines, in order


def _untimed(lines: list[str]) -> list[str]:
    return [re.sub(r"[0-9.]+ s\b", "T s", line) for line in lines]


def _say_twice(model, candidate, current, search):
    search.say(f"{candidate} first")
    search.say(f"{candidate} second")
    return model * candidate + current


def _blas_threads(*_):
    from threadpoolctl import threadpool_info

    return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]


@dataclasses.dataclass(frozen=True)
class _Search:
    say: object
    fit_options: dict


def test_map_trials_keeps_the_order_and_replays_each_task_s_lines():
    lines: list[str] = []
    search = _Search(lines.append, {"executor": "not picklable in a task", "x": 1})
    with parallel.trial_pool(2) as pool:
        results = parallel.map_trials(_say_twice, 10, [3, 1, 2], 0.5, search, pool)
    assert results == [30.5, 10.5, 20.5]
    assert lines == ["3 first", "3 second", "1 first", "1 second", "2 first", "2 second"]


def test_workers_run_one_blas_thread_and_nest_no_pool(monkeypatch):
    pytest.importorskip("threadpoolctl")
    monkeypatch.delenv(parallel.WORKERS_VARIABLE, raising=False)
    with ProcessPoolExecutor(1, initializer=parallel.limit_threads) as pool:
        threads = pool.submit(_blas_threads).result()
        nested = pool.submit(parallel.resolve_workers, None).result()
    assert threads and all(t == 1 for t in threads)
    assert nested == 1  # inside a worker process the search stays in-process
    assert parallel.resolve_workers(None) == parallel.available_cpus()
    assert parallel.resolve_workers(3) == 3


def test_the_environment_caps_the_default_workers_and_a_bad_value_is_named(monkeypatch):
    monkeypatch.setenv(parallel.WORKERS_VARIABLE, "1")
    assert parallel.resolve_workers(None) == 1
    assert parallel.resolve_workers(2) == 2  # an explicit request is not capped
    monkeypatch.setenv(parallel.WORKERS_VARIABLE, "64")
    assert parallel.resolve_workers(None) == parallel.available_cpus()
    for bad in ("two", "0", "-1"):
        monkeypatch.setenv(parallel.WORKERS_VARIABLE, bad)
        with pytest.raises(ValueError, match=f"PANTO_WORKERS={bad!r}.*at least 1"):
            parallel.resolve_workers(None)


def test_workers_below_one_are_refused():
    with pytest.raises(IdentificationError, match="workers"):
        DiagnosisOptions(workers=0)
