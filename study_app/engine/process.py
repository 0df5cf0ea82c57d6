"""The study engine's process: its entry point, the command receiver, the driver loop and the way out.

:func:`host_main` is started by :class:`study_app.engine.client.EngineClient` in a process of its own and runs a
:class:`study_app.engine.host.StudyEngine` there: commands arrive over the pipe (a receiver thread queues them),
the driver applies each and does the engine's regular work between them.  If the pipe breaks (the GUI closed or
crashed) the engine latches ``ENGINE_DETACHED`` (the force ramps to zero), aborts the running trial so its row is
stored with the reason (the session stays resumable), commits, and exits.
"""

from __future__ import annotations

import queue
import sys
import threading
import time
from typing import Any

from pipeline.core.clock import collect_garbage, manual_garbage_collection, prepare_helper_thread
from study_app.engine import messages as m
from study_app.engine.host import StudyEngine
from study_app.engine.loop_process import loop_runs_alone
from study_app.engine.setup import HostConfig

__all__ = ["host_main"]


class _Detached:
    """Internal marker: the command pipe broke."""


def host_main(config: HostConfig, conn: Any, events: Any) -> None:
    """Entry point of the study engine process."""
    loop_here = config.clock == "real" and not loop_runs_alone(config)
    if loop_here:
        # The loop is a thread of this process (where it cannot have its own: study_app.engine.loop_process).
        # A pure-Python driver thread must not hold the GIL for the default 5 ms while the loop thread waits for
        # it; and every thread started from here on (device receivers of the real rig, command receiver, recorder,
        # event feeder, loop) inherits FIFO: none can hold the GIL while preempted by another process.
        sys.setswitchinterval(0.0002)
        prepare_helper_thread()
    publish = events.put
    try:
        engine = StudyEngine(config, publish)
    except Exception as exc:  # reported to the GUI as one line
        publish(m.CommandRefused("connect", str(exc)))
        publish(m.EngineStopped(str(exc), {}))
        return
    cmds: queue.SimpleQueue[object] = queue.SimpleQueue()

    def receive() -> None:
        while True:
            try:
                msg = conn.recv()
            except (EOFError, OSError):
                cmds.put(_Detached())
                return
            cmds.put(msg)
            if isinstance(msg, m.Shutdown):
                return

    threading.Thread(target=receive, name="engine-commands", daemon=True).start()
    real = config.clock == "real"
    if loop_here:
        # freeze what exists now and let the collector run only in the driver's quiet window after a tick
        manual_garbage_collection()
    engine.start()
    detached = False
    # real clock: the driver's regular work runs every ~10 ms just after a loop tick (StudyEngine.quiet_wait_s);
    # a command is applied when it arrives, the work it causes waits for the next quiet moment
    step_at_ns = time.perf_counter_ns()
    try:
        while True:
            try:
                if real:
                    cmd = cmds.get(timeout=max(0.0, (step_at_ns - time.perf_counter_ns()) * 1e-9))
                else:
                    cmd = cmds.get_nowait()
            except queue.Empty:
                cmd = None
            if isinstance(cmd, _Detached):
                detached = True
                break
            if isinstance(cmd, m.Shutdown):
                break
            if cmd is not None:
                engine.handle(cmd)
            if not real:
                engine.step()
            elif time.perf_counter_ns() >= step_at_ns:
                engine.step()
                if loop_here:
                    collect_garbage()
                step_at_ns = time.perf_counter_ns() + int(engine.quiet_wait_s(0.01) * 1e9)
    finally:
        reason = "the experimenter GUI went away (closed or crashed)" if detached else "the experimenter GUI closed"
        engine.close(reason, detached=detached)
        if detached:
            events.cancel_join_thread()  # nobody reads the queue any more: do not block the exit on it
        time.sleep(0.2)  # let a reader copy the last records before the segment goes
        engine.release_ring()
