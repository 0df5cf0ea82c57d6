"""Where a planning command's independent simulations run: this machine's processes, or a Dask cluster.

``sweep`` and the calibration bench run many simulated participants, each a pure function of its seeds and
settings (:func:`study_app.headless.sim_trials.run_participant`: nothing is stored, nothing is written).  They
hand them to :func:`run_tasks`, which runs them

* one after the other in this process (``jobs`` 1),
* on this machine's cores in a pool of worker processes that die with this one (the default), or
* as Dask tasks on a cluster when a scheduler's address is given (``--scheduler tcp://host:8786`` or the
  :data:`SCHEDULER_ENV` environment variable).  Dask (``distributed``, the well-kept engine for this) places the
  tasks, reschedules the task of a worker that is lost mid-run on another worker (a participant is never dropped:
  the scheduler marks a task failed only after it killed :data:`ALLOWED_FAILURES` workers, and then the command
  stops with that message), and sends each result back here, where the caller stores it.  Ctrl-C cancels the
  tasks still queued or running on the cluster.

A participant is the same computation wherever it runs -- the same code, the same seeds, plain Python floats and
NumPy's seeded generators -- so a sweep's table is identical to the last digit with or without a cluster
(tests/headless/test_fanout.py checks it, a worker killed mid-run included).  To make that a fact rather than a
hope, every worker must run this very software: before any task is sent, each worker's haptic-study version and
simulated participant model are compared with this process's, and a cluster that differs is refused in one line.

Why not Dask for the local case too: a local Dask cluster costs ~2 s to start and a dependency the planning
commands otherwise do not need, for the same fan-out the process pool gives; Dask is an extra
(``pip install 'haptic-study[cluster]'``), imported only when a scheduler is named.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from foundation.errors import InputRefused
from foundation.platform_support.processes import worker_pool

__all__ = ["ALLOWED_FAILURES", "SCHEDULER_ENV", "ClusterError", "connect", "run_tasks", "scheduler_address",
           "software_identity"]

#: The environment variable naming the Dask scheduler when ``--scheduler`` is not given.
SCHEDULER_ENV = "HAPTIC_STUDY_SCHEDULER"
#: Workers a task may lose (killed or crashed under it) before the scheduler gives up on it (Dask's own setting
#: ``distributed.scheduler.allowed-failures``, set here so the behaviour does not depend on the lab's config).
ALLOWED_FAILURES = 3
#: Seconds to reach the scheduler before the command is refused.
CONNECT_TIMEOUT_S = 10.0

_ADDRESS = re.compile(r"^(tcp|tls|inproc|ucx)://[^\s/]+(:\d{1,5})?$")

T = TypeVar("T")
R = TypeVar("R")


class ClusterError(RuntimeError):
    """The cluster failed a task or went away mid-run; the message says what and what is kept."""


def scheduler_address(given: str | None, option: str = "--scheduler") -> str | None:
    """The scheduler's address from ``given`` or :data:`SCHEDULER_ENV`; None: run on this machine.

    Raises :class:`foundation.errors.InputRefused` (one line) for an address that is not ``tcp://host:port``
    (or ``tls://``, ``inproc://``, ``ucx://``).
    """
    source = option
    if given is None:
        given, source = os.environ.get(SCHEDULER_ENV) or None, SCHEDULER_ENV
    if given is None:
        return None
    if not _ADDRESS.match(given):
        raise InputRefused(f"{source}: {given!r} is not a Dask scheduler address; give tcp://HOST:PORT "
                           "(e.g. tcp://10.0.0.5:8786, as `dask scheduler` prints it)")
    return given


def software_identity() -> tuple[str, str]:
    """(haptic-study's version and commit, the simulated participant model's version) of the calling process."""
    from foundation.version import software_provenance
    from pipeline.sim.participant_params import MODEL_VERSION

    p = software_provenance()
    return p.version + (f" at {p.commit[:12]}" if p.commit else ""), MODEL_VERSION


def connect(address: str, option: str = "--scheduler") -> Any:
    """A ``distributed.Client`` on the scheduler at ``address``, its workers checked to run this software.

    Raises :class:`foundation.errors.InputRefused` (one line) when Dask is not installed, the scheduler cannot
    be reached within :data:`CONNECT_TIMEOUT_S`, it has no worker, or a worker runs other software.
    """
    try:
        import dask
        from distributed import Client
    except ImportError:
        raise InputRefused(f"{option}: running on a Dask cluster needs Dask on this machine and the workers: "
                           "pip install 'haptic-study[cluster]'") from None
    dask.config.set({"distributed.scheduler.allowed-failures": ALLOWED_FAILURES})
    try:
        client = Client(address, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise InputRefused(f"{option}: no Dask scheduler answered at {address} within {CONNECT_TIMEOUT_S:g} s "
                           f"({exc}); start one with `dask scheduler` and workers with `dask worker {address}`"
                           ) from None
    try:
        client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
        mine = software_identity()
        theirs = client.run(software_identity)
    except (OSError, TimeoutError) as exc:
        client.close()
        raise InputRefused(f"{option}: the Dask cluster at {address} has no worker that answers ({exc}); "
                           f"start one with `dask worker {address}`") from None
    except ImportError:
        client.close()
        raise InputRefused(f"{option}: a worker of the Dask cluster at {address} cannot import haptic-study; "
                           "install the same version on every worker") from None
    other = {w: tuple(v) for w, v in theirs.items() if tuple(v) != mine}
    if other:
        client.close()
        w, (version, model) = next(iter(other.items()))
        raise InputRefused(f"{option}: worker {w} runs haptic-study {version} (participant model {model}), this "
                           f"machine {mine[0]} ({mine[1]}); every worker must run the same software, or the "
                           "results would depend on where a participant ran")
    return client


def kernels_in_scratch(dask_worker: Any) -> str:
    """On a worker: the simulated rig's compiled code cached in Dask's scratch folder, not in the installation --
    beside the workers' own folders, so the workers of a machine (and one restarted after a crash) compile it once;
    returns the folder."""
    from pipeline.core.compiled import cache_kernels

    folder = os.path.join(os.path.dirname(os.path.abspath(dask_worker.local_directory)), "haptic-study-kernels")
    cache_kernels(folder)
    return folder


def _kernels_in_scratch_plugin() -> Any:
    """A Dask worker plugin running :func:`kernels_in_scratch` on each worker as it starts (Dask imported only here:
    it is an optional extra)."""
    from distributed.diagnostics.plugin import WorkerPlugin

    class KernelsInScratch(WorkerPlugin):
        name = "haptic-study-kernels-in-scratch"

        def setup(self, worker: Any) -> None:
            kernels_in_scratch(worker)

    return KernelsInScratch()


def run_tasks(fn: Callable[[T], R], tasks: Sequence[T], on_result: Callable[[R], None], *, jobs: int = 1,
              client: Any = None, name: str = "haptic-study") -> None:
    """``fn(task)`` for every task; ``on_result`` called here with each result as it comes (in any order).

    ``fn`` and the tasks must be picklable (a module-level function; the workers import it by name).  With
    ``client`` (from :func:`connect`) the tasks run on its cluster; else ``jobs`` > 1 runs them in a pool of that
    many processes, 1 here one after the other.  A task's exception is raised here (after cancelling the rest); a
    task whose workers kept dying raises :class:`ClusterError`.
    """
    if client is not None:
        _run_dask(fn, tasks, on_result, client, name)
    elif jobs > 1 and len(tasks) > 1:
        with worker_pool(min(jobs, len(tasks))) as pool:  # its workers die with this process
            for result in pool.imap_unordered(fn, tasks):
                on_result(result)
    else:
        for task in tasks:
            on_result(fn(task))


def _run_dask(fn: Callable[[T], R], tasks: Sequence[T], on_result: Callable[[R], None], client: Any,
              name: str) -> None:
    from uuid import uuid4

    from distributed import as_completed
    from distributed.scheduler import KilledWorker

    # the rig's compiled code cached in each worker's own folder: on every worker, and on any that joins later (one
    # restarted after a crash), before its first task -- whoever made the client
    client.register_plugin(_kernels_in_scratch_plugin())
    run = uuid4().hex[:12]
    # keys of our own: pure=True would hash each task's arguments (a protocol object per task) for nothing
    futures = client.map(fn, tasks, key=[f"{name}-{run}-{i}" for i in range(len(tasks))], pure=False)
    try:
        for fut in as_completed(futures, loop=client.loop):
            try:
                result = fut.result()
            except KilledWorker as exc:
                raise ClusterError(f"a task was on {ALLOWED_FAILURES} Dask workers that died under it ({exc}); the "
                                   "results so far are kept, run the command again to complete it") from None
            on_result(result)
    finally:  # Ctrl-C or a failure: nothing keeps computing on the cluster for nobody
        client.cancel([f for f in futures if not f.done()])
