"""The study engine when its haptic loop dies: the fault is latched, reported, stored; the session is left resumable.

On the virtual clock the loop runs inside the engine's ``step``; on the real
clock in its own thread, watched by :class:`pipeline.supervisor.LoopSupervisor`
from the driver thread.  Either way a dead loop cannot emit its own event, so
the engine pushes one into the runner's event path, interrupts the session
(resumable) and refuses what needs a loop.
"""

from __future__ import annotations

import sqlite3
import time

from pipeline.devices import Fault
from protocol.trial import TrialPhase
from study_app import messages as m
from study_app.engine_host import HostConfig, StudyEngine, list_resumable


def _fail() -> None:
    raise OSError("Net F/T socket closed")


def stored_events(db: str) -> list[tuple[str, str]]:
    c = sqlite3.connect(db)
    try:
        return c.execute("SELECT kind, detail FROM events ORDER BY rowid").fetchall()
    finally:
        c.close()


def test_a_loop_that_dies_mid_trial_is_stored_and_interrupts_the_session(tmp_path, short_protocol) -> None:
    events: list[object] = []
    e = StudyEngine(HostConfig(clock="virtual", speed=0), events.append, shared_ring=False)
    e.start()
    try:
        db = str(tmp_path / "s.db")
        e.handle(m.StartSession(db, "P01", "experiment", short_protocol, 3, 1))
        for _ in range(20_000):
            if e.runner is not None and e.runner.machine.phase is TrialPhase.ACTIVE:
                break
            e.step()
        e.step()
        e.eng.rig.sensor.read_wrench = _fail  # type: ignore[method-assign]
        e.step()  # a tick raises inside the loop
        assert e.loop_dead == "OSError('Net F/T socket closed')"
        assert e.loop.faults & Fault.LOOP_STALLED and e.eng.rig.haptic.output.commanded == (0.0, 0.0, 0.0)
        (ended,) = [ev for ev in events if isinstance(ev, m.SessionEnded)]
        assert ended.status == "interrupted" and "the haptic loop died" in ended.reason
        faults = [ev for ev in events if isinstance(ev, m.EngineFault) and "LOOP_STALLED" in ev.detail]
        assert len(faults) == 1
        e.handle(m.StartSession(db, "P02", "experiment", short_protocol, 3, 2))
        e.handle(m.ResetFaults())
        refused = [ev.message for ev in events if isinstance(ev, m.CommandRefused)]
        assert len(refused) == 2 and all("the haptic loop died (OSError('Net F/T socket closed'))" in r for r in refused)
    finally:
        e.close("test over")
        e.release_ring()
    kinds = stored_events(db)
    died = [d for k, d in kinds if k == "fault" and d.startswith("LOOP_STALLED")]
    assert died == ["LOOP_STALLED: the haptic loop died (OSError('Net F/T socket closed')); the haptic device's command "
                    "watchdog dropped the force to zero"]
    assert [k for k, _ in kinds][-1] == "session_interrupted"
    assert [s["code"] for s in list_resumable(db)] == ["P01"]  # interrupted, resumable


def test_a_dead_loop_thread_on_the_real_clock_is_found_by_the_supervisor() -> None:
    events: list[object] = []
    e = StudyEngine(HostConfig(clock="real"), events.append, shared_ring=False)
    e.start()
    try:
        thread = e.loop._thread
        assert thread is not None
        e.eng.rig.sensor.read_wrench = _fail  # type: ignore[method-assign]
        thread.join(5.0)  # the loop thread dies on its next tick (its ramp-down fails the same way)
        assert not thread.is_alive()
        e.step()  # the driver's regular work: the supervisor looks
        assert e.loop_dead.startswith("OSError('Net F/T socket closed')")
        (fault,) = [ev for ev in events if isinstance(ev, m.EngineFault) and "LOOP_STALLED" in ev.detail]
        assert fault.detail.startswith("LOOP_STALLED: the haptic loop thread died (OSError('Net F/T socket closed')")
        assert e.health().faults & Fault.LOOP_STALLED
        e.step()
        assert len([ev for ev in events if isinstance(ev, m.EngineFault)]) == 1  # reported once
    finally:
        t0 = time.monotonic()
        e.close("test over")
        e.release_ring()
        assert time.monotonic() - t0 < 5.0
