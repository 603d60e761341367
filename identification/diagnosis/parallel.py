"""A round's candidate refits in parallel worker processes (:attr:`~panto.identification.
diagnosis.pipeline.DiagnosisOptions.workers`).

Each candidate of a round is refitted and judged independently of the others
(:func:`~panto.identification.diagnosis.pipeline.diagnose`, step 3), so the round maps one task
per candidate onto a process pool and collects the results in the candidates' order: the
verdict is the serial one. A worker runs the same code on the same data; its progress lines are
recorded and replayed in the parent in the candidates' order.

Workers are limited to one BLAS/OpenMP thread each (:func:`limit_threads`, ``threadpoolctl`` and
the ``*_NUM_THREADS`` variables): two processes with two BLAS threads each on two cores would
oversubscribe them. Inside a worker process (a benchmark running its cases in parallel already
uses the cores) the default is one process, the search in-process.
"""
from __future__ import annotations

import dataclasses
import functools
import multiprocessing
import os
from concurrent.futures import Executor, ProcessPoolExecutor
from contextlib import contextmanager
from typing import Any, Callable, Iterator, Sequence

#: Environment variables of the thread pools a worker is limited to one thread of.
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
                    "BLIS_NUM_THREADS", "NUMEXPR_NUM_THREADS", "VECLIB_MAXIMUM_THREADS")

_LIMITS: Any = None  # the worker's threadpoolctl limits (kept alive for the worker's lifetime)


def available_cpus() -> int:
    """CPUs this process may run on (its affinity mask; ``os.cpu_count`` where unknown)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


#: Environment variable capping the default number of worker processes (a machine shared with
#: other jobs; a test runner whose processes already take one core each sets it to 1).
WORKERS_VARIABLE = "PANTO_WORKERS"


def resolve_workers(requested: int | None) -> int:
    """Worker processes for the refits: `requested`, or by default the CPUs available (at most
    :data:`WORKERS_VARIABLE` where set), but one inside a worker process (whose parent already
    spreads its work over the cores) or a daemon process (which may not start children)."""
    if requested is not None:
        return max(1, int(requested))
    if multiprocessing.parent_process() is not None or multiprocessing.current_process().daemon:
        return 1
    cap = os.environ.get(WORKERS_VARIABLE, "").strip()
    if not cap:
        return available_cpus()
    if not cap.isdigit() or int(cap) < 1:
        raise ValueError(f"environment variable {WORKERS_VARIABLE}={cap!r}: expected a whole "
                         "number of worker processes, at least 1")
    return min(available_cpus(), int(cap))


def limit_threads() -> None:
    """One BLAS/OpenMP thread in this process (a worker's initializer): the environment for
    libraries loaded later, ``threadpoolctl`` for those already loaded (when installed)."""
    global _LIMITS
    for name in THREAD_VARIABLES:
        os.environ[name] = "1"
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl comes with scikit-learn
        return
    _LIMITS = threadpool_limits(limits=1)


@contextmanager
def trial_pool(workers: int, executor: Executor | None = None) -> Iterator[Executor | None]:
    """The executor a search's rounds submit their refits to: None (in-process) for one worker,
    else `executor` when one is given (it is not shut down here), else a process pool of
    `workers` started on first use."""
    if workers <= 1 or executor is not None:
        yield None if workers <= 1 else executor
        return
    pool = _LazyPool(workers)
    try:
        yield pool
    finally:
        pool.shutdown()


class _LazyPool(Executor):
    """A process pool started on the first submission (a diagnosis whose rounds have a single
    candidate each never starts one); each worker limited to one BLAS thread."""

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self._pool: ProcessPoolExecutor | None = None

    def submit(self, fn: Callable, /, *args: Any, **kwargs: Any):
        """Submit to the pool (started now if it is not yet)."""
        if self._pool is None:
            self._pool = ProcessPoolExecutor(max_workers=self.workers, initializer=limit_threads)
        return self._pool.submit(fn, *args, **kwargs)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Shut the pool down when it was started."""
        if self._pool is not None:
            self._pool.shutdown(wait=wait, cancel_futures=cancel_futures)
            self._pool = None


def map_trials(function: Callable, model: Any, candidates: Sequence[Any], current: Any,
               search: Any, pool: Executor | None) -> list[Any]:
    """``[function(model, c, current, search) for c in candidates]``, on `pool` when there is
    one and more than one candidate; ``search.say`` receives every task's progress lines in the
    candidates' order. A task runs without the least-squares ``executor`` of
    ``search.fit_options`` (the task is already one worker's share)."""
    if pool is None or len(candidates) < 2:
        return [function(model, c, current, search) for c in candidates]
    quiet = dataclasses.replace(search, say=None,
                                fit_options={**search.fit_options, "executor": None})
    return map_replayed(pool, functools.partial(_trial, function, model, current, quiet),
                        candidates, search.say)


def map_replayed(pool: Executor, task: Callable[[Any, Callable[[str], None]], Any],
                 items: Sequence[Any], say: Callable[[str], None]) -> list[Any]:
    """``[task(item, say) for item in items]`` on `pool`, one task per item: each task's
    progress lines are recorded in its worker and given to `say` in the items' order (`task`
    must pickle: a module-level function or a ``functools.partial`` of one)."""
    futures = [pool.submit(_recorded, task, item) for item in items]
    results = []
    for future in futures:
        result, lines = future.result()
        for line in lines:
            say(line)
        results.append(result)
    return results


def _trial(function: Callable, model: Any, current: Any, search: Any, candidate: Any,
           say: Callable[[str], None]) -> Any:
    """One candidate's trial with `say` as the search's progress sink."""
    return function(model, candidate, current, dataclasses.replace(search, say=say))


def _recorded(task: Callable, item: Any) -> tuple[Any, list[str]]:
    """One task in a worker: its result and the progress lines it said."""
    lines: list[str] = []
    return task(item, lines.append), lines


__all__ = ["WORKERS_VARIABLE", "available_cpus", "resolve_workers", "limit_threads", "trial_pool",
           "map_trials", "map_replayed", "THREAD_VARIABLES"]
