"""Spreading independent analysis work over the machine's cores.

Reading samples (SQLite row decoding) and drawing figures (matplotlib) are
CPU-bound Python; threads would share one core through the GIL, so the work
goes to worker processes.  Forking is cheap (the workers inherit the imported
modules) but unsafe once other threads exist, so a process that has threads
spawns its workers instead.

``HAPTIC_STUDY_WORKERS`` sets how many worker processes the analysis may use
(a shared lab machine; the test suite, which already runs a test per core).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Any, TypeVar

from foundation.platform_support.processes import die_with, worker_context
from foundation.platform_support.threads import usable_cpu_count

__all__ = ["WORKERS_ENV", "default_workers", "run_tasks", "workers_env_problem"]

T = TypeVar("T")


#: The environment variable that sets the analysis's worker processes (unset: the usable cores, at most 4).
WORKERS_ENV = "HAPTIC_STUDY_WORKERS"


def workers_env_problem() -> str | None:
    """What is wrong with :data:`WORKERS_ENV` in one line, or None when it is unset or a whole number >= 1."""
    raw = os.environ.get(WORKERS_ENV)
    if raw is None or raw.strip() == "":
        return None
    try:
        n = int(raw)
    except ValueError:
        n = 0
    return None if n >= 1 else f"{WORKERS_ENV} = {raw!r}: must be a whole number of worker processes, at least 1"


def default_workers() -> int:
    """Worker processes to use: :data:`WORKERS_ENV` when set, else the usable cores, at most 4.

    Raises
    ------
    ValueError
        :data:`WORKERS_ENV` is set to something else than a whole number >= 1
        (the command line checks it first and says so in one line).
    """
    problem = workers_env_problem()
    if problem is not None:
        raise ValueError(problem)
    raw = os.environ.get(WORKERS_ENV, "").strip()
    if raw:
        return int(raw)
    cores = usable_cpu_count()  # the affinity mask (every CPU where the OS has none; platform_support)
    return max(1, min(4, cores))


def run_tasks(
    fn: Callable[..., T],
    tasks: Sequence[tuple[Any, ...]],
    *,
    workers: int,
    on_done: Callable[[int, T], None] | None = None,
) -> list[T]:
    """``[fn(*t) for t in tasks]``, over ``workers`` processes when more than one.

    Parameters
    ----------
    fn
        A module-level function (it is pickled by name).
    tasks
        Argument tuples.
    workers
        Processes; 1 runs everything in this process, in order.
    on_done
        Called in this process as ``on_done(task index, result)`` when each task finishes.

    Returns
    -------
    list
        Results in task order.  The first exception raised by a task is re-raised.
    """
    if workers <= 1 or len(tasks) <= 1:
        out = []
        for i, t in enumerate(tasks):
            r = fn(*t)
            if on_done is not None:
                on_done(i, r)
            out.append(r)
        return out
    ctx = worker_context()  # fork while single-threaded on Linux, else spawn (platform_support)
    results: list[Any] = [None] * len(tasks)
    # the workers die with this process (PR_SET_PDEATHSIG): a killed command leaves no orphan computing on
    with ProcessPoolExecutor(max_workers=min(workers, len(tasks)), mp_context=ctx, initializer=die_with,
                             initargs=(os.getpid(),)) as pool:
        pending: dict[Future[T], int] = {pool.submit(fn, *t): i for i, t in enumerate(tasks)}
        try:
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for f in done:
                    i = pending.pop(f)
                    results[i] = f.result()
                    if on_done is not None:
                        on_done(i, results[i])
        except BaseException:
            for f in pending:
                f.cancel()
            raise
    return results
