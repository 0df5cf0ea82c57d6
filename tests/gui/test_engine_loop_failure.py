"""The study engine when its haptic loop dies: the fault is latched, reported, stored; the session is left resumable.

On the virtual clock the loop runs inside the engine's ``step``; on the real
clock in its own thread, watched by :class:`pipeline.runtime.supervisor.LoopSupervisor`
from the driver thread.  Either way a dead loop cannot emit its own event, so
the engine pushes one into the runner's event path, interrupts the session
(resumable) and refuses what needs a loop.
"""

from __future__ import annotations

import sqlite3
import time

from pipeline.devices.interfaces import Fault
from protocol.study.trial import TrialPhase
from study_app.engine import messages as m
from study_app.engine.host import StudyEngine
from study_app.engine.sessions import list_resumable
from study_app.engine.setup import HostConfig


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
        e.eng.rig.sensor.read_wrench = _fail
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
        assert len(refused) == 2
        assert all("the haptic loop died (OSError('Net F/T socket closed'))" in r for r in refused)
    finally:
        e.close("test over")
        e.release_ring()
    kinds = stored_events(db)
    died = [d for k, d in kinds if k == "fault" and d.startswith("LOOP_STALLED")]
    assert died == ["LOOP_STALLED: the haptic loop died (OSError('Net F/T socket closed')); the haptic device's "
                    "command watchdog dropped the force to zero"]
    assert [k for k, _ in kinds][-1] == "session_interrupted"
    assert [s["code"] for s in list_resumable(db)] == ["P01"]  # interrupted, resumable


def test_a_dead_loop_thread_on_the_real_clock_is_found_by_the_supervisor() -> None:
    events: list[object] = []
    e = StudyEngine(HostConfig(clock="real"), events.append, shared_ring=False)
    e.start()
    try:
        thread = e.loop._thread
        assert thread is not None
        e.eng.rig.sensor.read_wrench = _fail
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


def test_a_frozen_loop_in_a_session_on_the_real_clock_is_latched_and_stored(tmp_path, short_protocol) -> None:
    """The loop thread hangs in a sensor read mid-session: the supervisor (on a clock the test moves) reports it
    after 50 ms without a tick, the runner stores it, and the loop latches it when it runs again."""
    import threading

    from pipeline.core.clock import VirtualClock

    events: list[object] = []
    e = StudyEngine(HostConfig(clock="real"), events.append, shared_ring=False)
    hang, hanging, thaw = threading.Event(), threading.Event(), threading.Event()
    read = e.eng.rig.sensor.read_wrench

    def read_or_hang():
        if hang.is_set():
            hang.clear()
            hanging.set()
            thaw.wait(10.0)
        return read()

    e.eng.rig.sensor.read_wrench = read_or_hang
    e.start()
    db = str(tmp_path / "s.db")
    try:
        e.handle(m.StartSession(db, "P01", "experiment", short_protocol, 3, 1))
        assert e.runner is not None
        clock = VirtualClock()
        e.supervisor.clock = clock  # the supervisor's wall clock, moved by the test
        ticks = e.loop.tick_count
        end = time.monotonic() + 5.0
        while e.loop.tick_count < ticks + 50 and time.monotonic() < end:  # the session runs (bounded wait)
            e.step(throttle=False)
            time.sleep(0.002)
        hang.set()
        assert hanging.wait(5.0)  # the loop thread is inside the read that hangs
        e.step(throttle=False)  # the supervisor sees the last tick count
        frozen_at = e.loop.tick_count
        clock.advance(50_000_000)
        e.step(throttle=False)
        assert not [ev for ev in events if isinstance(ev, m.EngineFault) and "LOOP_STALLED" in ev.detail]
        clock.advance(1_000_000)
        e.step(throttle=False)
        assert e.loop.tick_count == frozen_at  # still hanging
        (fault,) = [ev for ev in events if isinstance(ev, m.EngineFault) and "LOOP_STALLED" in ev.detail]
        assert fault.detail.startswith("LOOP_STALLED: no loop tick for 51 ms (limit 50 ms): the haptic loop is frozen")
        # stored while the loop still hangs (it may never come back): the recorder commits on its own thread
        end = time.monotonic() + 5.0
        while not any(d.startswith("LOOP_STALLED") for _, d in stored_events(db)) and time.monotonic() < end:
            e.step(throttle=False)
            time.sleep(0.01)
        assert e.loop.tick_count == frozen_at
        assert any(k == "fault" and d.startswith("LOOP_STALLED: no loop tick for 51 ms") for k, d in stored_events(db))
        thaw.set()
        end = time.monotonic() + 5.0
        while not e.loop.faults & Fault.LOOP_STALLED and time.monotonic() < end:
            e.step(throttle=False)
            time.sleep(0.002)
        assert e.loop.faults & Fault.LOOP_STALLED  # latched by the loop itself once it ran again
        assert not e.loop_dead  # frozen, not dead: the session goes on, waiting for a reset
    finally:
        thaw.set()
        e.close("test over")
        e.release_ring()
    stored = [d for k, d in stored_events(db) if k == "fault" and d.startswith("LOOP_STALLED")]
    assert stored[0].startswith("LOOP_STALLED: no loop tick for 51 ms (limit 50 ms): the haptic loop is frozen; the "
                                "haptic device's command watchdog dropped the force to zero")
