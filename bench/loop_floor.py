"""The machine's floor beside ``bench loop``'s measurement: a process that does nothing but wake every 1 ms.

Why: a period over 5 ms aborts the trial it falls in, and a loop that does its work in microseconds can still wake
late -- when the kernel or, in a virtual machine, the hypervisor takes its CPU away (the guest's steal counter
sees little of it).  Then no design of the loop's process helps, and the bench must say so rather than blame (or
credit) the code.  So beside each measurement a bare timer runs on the loop's CPU, in the same load, at the same
time: ``SCHED_FIFO`` just below the loop (it never delays the loop, which preempts it), the collector off, nothing
allocated per wake-up but a float.  Its periods over 2 ms and over 5 ms are the machine's; the loop's beyond them
are the code's.

Run as ``python bench/loop_floor.py CPU PRIORITY OUT`` by :class:`Floor` only: when ``OUT.stop`` appears (it looks
every 100 wake-ups: a signal handler would be an OS-specific call) it writes its figures to ``OUT`` (JSON) and
ends.
"""

from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
import time
from typing import Any

__all__ = ["FLOOR_PRIORITY", "Floor"]

_HERE = os.path.abspath(__file__)
#: SCHED_FIFO priority of the bare timer: just below the loop's (pipeline.core.clock.REALTIME_PRIORITY, 20) so that
#: it never delays the loop, above every normal process and the loop process's helpers (10) -- and another engine's
#: on a shared machine -- so that only the kernel, the hypervisor or a loop delays it.
FLOOR_PRIORITY = 19
_PERIOD_NS = 1_000_000


class Floor:
    """The bare timer's process on ``cpu`` (start at construction, :meth:`stop` for its figures)."""

    def __init__(self, cpu: int, out: str) -> None:
        self.cpu = cpu
        self.out = out
        self.proc = subprocess.Popen([sys.executable, _HERE, str(cpu), str(FLOOR_PRIORITY), out],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def stop(self) -> dict[str, Any] | None:
        """End it; its figures (None if it died without them)."""
        with open(self.out + ".stop", "w", encoding="utf-8"):
            pass
        try:
            self.proc.wait(10.0)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(5.0)
        if not os.path.exists(self.out):
            return None
        with open(self.out, encoding="utf-8") as fh:
            figures: dict[str, Any] = json.load(fh)
        return figures


def _run(cpu: int, priority: int, out: str) -> None:
    from foundation.platform_support.threads import pin_to_cpu, set_fifo_priority

    placed = pin_to_cpu(cpu)
    scheduling = f"{set_fifo_priority(priority)} on {placed}"
    stop_file = out + ".stop"
    gc.disable()
    counts = {"periods": 0, "over_2ms": 0, "over_5ms": 0}
    worst_ns = 0
    now = last = time.monotonic_ns()
    deadline = now + _PERIOD_NS
    while counts["periods"] % 100 or not os.path.exists(stop_file):
        wait_ns = deadline - time.monotonic_ns()
        if wait_ns > 0:
            time.sleep(wait_ns * 1e-9)
        now = time.monotonic_ns()
        period = now - last
        last = now
        counts["periods"] += 1
        counts["over_2ms"] += period > 2 * _PERIOD_NS
        counts["over_5ms"] += period > 5 * _PERIOD_NS
        worst_ns = max(worst_ns, period)
        deadline += _PERIOD_NS
        if deadline < now:  # slots missed: the next one from now, as the loop does
            deadline = now + _PERIOD_NS
    with open(out, "w", encoding="utf-8") as fh:
        json.dump({**counts, "max_ms": worst_ns * 1e-6, "scheduling": scheduling}, fh)


if __name__ == "__main__":
    from foundation.platform_support.processes import die_with

    die_with(os.getppid())  # a bench that is killed leaves no timer behind
    _run(int(sys.argv[1]), int(sys.argv[2]), sys.argv[3])
