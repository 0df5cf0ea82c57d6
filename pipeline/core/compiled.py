"""The compiler of the per-tick code that would otherwise run as Python bytecode: numba's ``njit``.

A simulated study is a million ticks a participant, and a tick of the simulated rig is a few dozen float operations
spread over a handful of objects: as Python, each operation costs tens of nanoseconds of interpreter, compiled it costs
one. :func:`kernel` compiles a function written in the plain Python that numba reads (floats, ints and NumPy arrays;
the models keep their state in a float64 array) and is the only way the code base compiles anything, so the rules
below hold for every compiled function:

* **The interpreted function's bits.** No fast-math: LLVM neither reassociates nor contracts ``a * b + c`` into a
  fused multiply-add, so every operation rounds as Python's does, in the order written; ``math.exp``, ``math.sqrt``
  and ``**`` call the same C library as CPython's.  Each kernel's ``py_func`` (the function as written, run by the
  interpreter) is held to the compiled one bit for bit on any CPU (``tests/pipeline/test_compiled.py``).
  (NaN inputs give NaN as in Python; which of two NaN operands' sign and payload comes out is the machine's.)
* **Python's errors, mostly.** A division by zero raises ``ZeroDivisionError`` as in Python (numba's
  ``error_model="python"``); an overflow of ``math.exp`` or ``**`` gives ``inf`` where Python raises
  ``OverflowError`` (as NumPy's scalars do): the models' inputs are bounded long before (the rig clamps a tick's
  ``dt`` to 10 ms, a depth is millimetres).
* **Arguments of fixed types.** A kernel is compiled for the argument types of its first call; the models pass
  ``float`` and ``int`` only (they convert what callers hand them), so no tick compiles a second version.
* **Integer times stay exact.** A float64 holds integers exactly below 2⁵³ (104 days in nanoseconds): the models
  keep times in their states relative to their first tick (a monotonic clock's nanoseconds since boot may pass
  2⁵³).
* **Compiled once a machine.** Once :func:`cache_kernels` has run (a simulated rig's construction runs it), the
  machine code is cached beside the source (``__pycache__``; numba's own per-user cache where that folder is
  read-only; a Dask worker's own scratch folder on a cluster) and loaded in milliseconds by the next process; a user
  who can write to neither (an unprivileged account without a home) gets it compiled in each process, a few
  seconds.  A rig compiles (or loads) its kernels when it is built (:meth:`pipeline.sim.rig.SimRig.warm_up`), never
  in its first tick.
  numba keys its cache on the kernel's own file and closure only, not on kernels it calls in other modules nor on
  the options below: a kernel that calls other modules' kernels closes over their :func:`fingerprint`
  (``pipeline/sim/rig.py``) and reaches those kernels as globals, never through its closure (a kernel pickles
  differently in every process: a closure holding one would miss the cache every time), and a change of the options
  must come with the caches deleted
  (``find . -name '*.nb[ci]' -delete``; an installed version's files are new, and so are its caches).
"""

from __future__ import annotations

import hashlib
import threading
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any, TypeVar, cast

import numba
import numpy as np
import numpy.typing as npt

__all__ = ["KernelState", "State", "cache_kernels", "fingerprint", "is_warm", "kernel", "kernels", "warm_once"]

F = TypeVar("F", bound=Callable[..., Any])
#: A kernel's state: a float64 array (integers kept in it are below 2⁵³, so exact).
State = npt.NDArray[np.float64]


#: The kernels' dispatchers whose machine code :func:`cache_kernels` has not yet placed on disk.
_UNCACHED: list[Any] = []
#: Every kernel's dispatcher, in the order defined.
_ALL: list[Any] = []


def kernel(fn: F) -> F:
    """Compile ``fn`` (lazily, at its first call; from the on-disk cache once :func:`cache_kernels` has run); typed
    as ``fn``."""
    dispatcher = numba.njit(cache=False, fastmath=False, error_model="python")(fn)
    _UNCACHED.append(dispatcher)
    _ALL.append(dispatcher)
    return cast(F, dispatcher)


def kernels() -> tuple[Any, ...]:
    """Every kernel defined so far in this process (its modules imported), as numba's dispatchers."""
    return tuple(_ALL)


def cache_kernels(folder: str | None = None) -> None:
    """Keep every kernel's machine code on disk from now on: beside its source (numba's own per-user cache where that
    is read-only), or in ``folder`` (a Dask worker's own scratch folder: nothing is written in its installation).

    The place is chosen once a kernel a process, at its first call here (a kernel defined later is taken at the
    next call); where there is none (the source read-only to this user, and no home for numba's own), the kernel is
    compiled in each process instead, a few seconds at the first rig's construction.
    """
    with _LOCK:  # (studies may run in threads of one process, a Dask worker's: one list, popped by one at a time)
        if folder is not None:
            numba.config.CACHE_DIR = folder  # type: ignore[attr-defined]  # numba makes its settings at run time
        while _UNCACHED:
            try:
                _UNCACHED.pop().enable_caching()
            except RuntimeError:
                pass  # no folder to cache in (numba: "no locator available"): compiled in memory


def warm_once(owner: str, compile_them: Callable[[], object]) -> None:
    """Compile ``owner``'s kernels (or load them from the cache) once a process: ``compile_them`` calls each on scratch
    copies of a state, as its owner's methods will.  An owner's construction calls it, so that no tick waits for a
    compiler; a process forked after it inherits the machine code and this record of it."""
    if owner in _WARMED:
        return
    with _LOCK:  # (an owner's warm-up may warm others: re-entrant)
        if owner in _WARMED:
            return
        cache_kernels()
        compile_them()
        _WARMED.add(owner)


def is_warm(owner: str) -> bool:
    """Whether :func:`warm_once` has run for ``owner`` in this process."""
    return owner in _WARMED


#: One warm-up, and one switch of kernels to the cache, at a time in a process.
_LOCK = threading.RLock()
#: The owners (module names) whose kernels :func:`warm_once` has compiled or loaded in this process.
_WARMED: set[str] = set()


def fingerprint(*modules: ModuleType) -> int:
    """The modules' sources, and this one's, as one number below 2⁵⁶: a kernel that calls kernels of ``modules``
    closes over it, so numba's cache of it (keyed on its own file and its closure's values) is rebuilt when one of
    them changes."""
    h = hashlib.sha256(Path(__file__).read_bytes())
    for m in modules:
        h.update(Path(str(m.__file__)).read_bytes())
    return int.from_bytes(h.digest()[:7], "little")


class KernelState:
    """An object whose per-tick arithmetic is a kernel over its :attr:`array` (a float64 state), which a composite (the
    simulated rig, Algorithm 1's framework) may move into a slice of its own array so that one compiled call steps
    them all."""

    __slots__ = ("array",)
    array: State

    def adopt(self, view: State) -> None:
        """Keep the state in ``view`` (a slice of the composite's array) from now on, as it is now."""
        view[:] = self.array
        self.array = view
