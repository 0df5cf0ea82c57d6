"""The 1 kHz loop alone in its own process (real clock): sessions, calibration, and the neighbours that die or freeze.

The study engine runs in this test's process (in-process, as the GUI's engine process runs it); the loop runs in
the process :mod:`study_app.engine.loop_process` starts.  Real processes, real clock: the tests wait only in
bounded polls, and assert nothing about timing (``bench loop`` measures it).
"""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import threading
import time
from collections.abc import Callable

import pytest
from test_engine_loop_failure import stored_events

from analysis.reading.load import load_study
from analysis.report.latency_methods import latency_paragraph
from pipeline.core.clock import VirtualClock
from pipeline.devices.interfaces import Fault
from pipeline.runtime.ring import RingBuffer
from study_app.cli.main import main
from study_app.engine import messages as m
from study_app.engine.client import EngineClient
from study_app.engine.host import StudyEngine
from study_app.engine.sessions import list_resumable
from study_app.engine.setup import HostConfig

WAIT_S = 30.0


def run_until(e: StudyEngine, done: Callable[[], bool], timeout_s: float = WAIT_S) -> None:
    """Step the engine's driver until ``done()`` (bounded)."""
    end = time.monotonic() + timeout_s
    while not done():
        assert time.monotonic() < end, "timed out"
        e.step()
        time.sleep(0.005)


@pytest.fixture
def engine():
    events: list[object] = []
    e = StudyEngine(HostConfig(clock="real", health_period_s=0.1), events.append)
    e.events = events  # type: ignore[attr-defined]
    e.start()
    try:
        yield e
    finally:
        e.close("test over")
        e.release_ring()


def test_the_loop_runs_in_a_process_of_its_own_and_a_session_there_is_stored_and_replays_exactly(
        engine: StudyEngine, tmp_path, short_protocol, capsys) -> None:
    e = engine
    assert e.remote is not None and e.loop.runs_in == "process"
    pid = e.remote.loop.pid
    assert pid != os.getpid() and e.remote.loop.link.alive
    assert "haptic-loop" not in [t.name for t in threading.enumerate()]  # no loop thread here
    run_until(e, lambda: e.loop.tick_count > 100)
    health = e.health()
    assert health.loop_pid == pid
    assert " on CPU " in health.scheduling or " on any CPU " in health.scheduling  # the core it runs on, said
    lat = health.latency  # the end-to-end latency: the loop's own share from its records, the rest measured
    assert lat is not None and [s["name"] for s in lat["stages"]][:2] == [
        "loop: the F/T sample waits for the next tick", "loop: the tick computes the command"]
    assert lat["force_ms"] >= 5.0 and lat["motion_ms"] > 0
    db = str(tmp_path / "s.db")
    e.handle(m.StartSession(db, "P01", "experiment", short_protocol, 3, 1))
    events = e.events  # type: ignore[attr-defined]
    run_until(e, lambda: any(isinstance(ev, m.SessionEnded) for ev in events), 60.0)
    ended = [ev for ev in events if isinstance(ev, m.TrialEnded)]
    assert len(ended) >= 2 and not [ev for ev in events if isinstance(ev, m.CommandRefused)]
    kinds = [k for k, _ in stored_events(db)]
    assert kinds[0] == "session_start" and "cue" in kinds  # the runner's events, stored from this process
    con = sqlite3.connect(db)
    try:
        (config_json,) = con.execute("SELECT config_json FROM sessions").fetchone()
    finally:
        con.close()
    stored = json.loads(config_json)["latency"]  # stored with the session (the real clock's only)
    assert [s["name"] for s in stored["stages"]] == [s["name"] for s in lat["stages"]]
    said = latency_paragraph(load_study([db], include_incomplete=True))
    assert "Measured when each of the 1 session on the real clock started, and stored with it: tip → hand" in said
    # the recording's replay log came over the link beside the records: replay reproduces every rendered force
    assert main(["replay", "--db", db, "--session", "1"]) == 0
    assert "bit-identical to the recording" in capsys.readouterr().out


def test_the_simulated_calibration_steps_run_in_the_loops_process_with_the_loop_paused(engine: StudyEngine) -> None:
    e = engine
    events = e.events  # type: ignore[attr-defined]
    run_until(e, lambda: e.loop.tick_count > 50)
    e.handle(m.Calibrate("quick"))
    (done,) = [ev for ev in events if isinstance(ev, m.CalibrationDone)]
    assert done.accepted and [ev.done for ev in events if isinstance(ev, m.CalibrationProgress)][-1] == done.n_poses
    e.handle(m.CheckFrames())
    (frames,) = [ev for ev in events if isinstance(ev, m.FrameCheckDone)]
    assert frames.passed
    ticks = e.loop.tick_count
    run_until(e, lambda: e.loop.tick_count > ticks + 50)  # the loop ticks again after each step
    assert not [ev for ev in events if isinstance(ev, m.CommandRefused)]


def test_a_loop_process_that_dies_is_reported_stored_and_interrupts_the_session(tmp_path, short_protocol) -> None:
    events: list[object] = []
    e = StudyEngine(HostConfig(clock="real"), events.append)
    e.start()
    db = str(tmp_path / "s.db")
    try:
        e.handle(m.StartSession(db, "P01", "experiment", short_protocol, 3, 1))
        run_until(e, lambda: e.loop.tick_count > 300)
        assert e.remote is not None
        os.kill(e.remote.loop.pid, signal.SIGKILL)  # a crash in a device library, as seen in a real window
        run_until(e, lambda: bool(e.loop_dead))
        assert e.loop_dead == "killed by SIGKILL (signal 9)"
        (fault,) = [ev for ev in events if isinstance(ev, m.EngineFault) and "LOOP_STALLED" in ev.detail]
        assert fault.detail.startswith("LOOP_STALLED: the haptic loop process died (killed by SIGKILL (signal 9))")
        assert e.health().faults & Fault.LOOP_STALLED
        e.handle(m.ResetFaults())
        assert [ev.message for ev in events if isinstance(ev, m.CommandRefused)][-1].startswith(
            "reset faults: the haptic loop died (killed by SIGKILL (signal 9))")
    finally:
        e.close("test over")
        e.release_ring()
    kinds = stored_events(db)
    assert any(k == "fault" and d.startswith("LOOP_STALLED: the haptic loop process died") for k, d in kinds)
    assert kinds[-1][0] == "session_interrupted"
    assert [s["code"] for s in list_resumable(db)] == ["P01"]


def test_a_frozen_loop_process_is_latched_by_the_supervisor_and_by_the_loop_once_it_runs_again(
        tmp_path, short_protocol) -> None:
    events: list[object] = []
    e = StudyEngine(HostConfig(clock="real"), events.append)
    e.start()
    db = str(tmp_path / "s.db")
    assert e.remote is not None
    pid = e.remote.loop.pid
    try:
        e.handle(m.StartSession(db, "P01", "experiment", short_protocol, 3, 1))
        run_until(e, lambda: e.loop.tick_count > 300)
        clock = VirtualClock()
        e.supervisor.clock = clock  # the supervisor's wall clock, moved by the test
        os.kill(pid, signal.SIGSTOP)
        e.step()
        frozen_at = e.loop.tick_count
        clock.advance(50_000_000)
        e.step()
        assert not [ev for ev in events if isinstance(ev, m.EngineFault) and "LOOP_STALLED" in ev.detail]
        clock.advance(1_000_000)
        e.step()
        assert e.loop.tick_count == frozen_at
        (fault,) = [ev for ev in events if isinstance(ev, m.EngineFault) and "LOOP_STALLED" in ev.detail]
        assert fault.detail.startswith("LOOP_STALLED: no loop tick for 51 ms (limit 50 ms): the haptic loop is frozen")
        run_until(e, lambda: any(d.startswith("LOOP_STALLED: no loop tick for 51 ms") for _, d in stored_events(db)))
        os.kill(pid, signal.SIGCONT)
        run_until(e, lambda: bool(e.loop.faults & Fault.LOOP_STALLED))  # latched by the loop itself
        assert not e.loop_dead
    finally:
        os.kill(pid, signal.SIGCONT)
        e.close("test over")
        e.release_ring()


def test_when_the_engine_process_dies_the_loop_ramps_the_force_to_zero_latches_detached_and_ends(
        tmp_path, short_protocol) -> None:
    """The study engine's process is killed mid-trial (a crash): its loop's process, alone, latches ENGINE_DETACHED,
    ramps the rendered force to zero through the safety stage's ramp, closes its devices and ends."""
    client = EngineClient(HostConfig(clock="real", health_period_s=0.1))
    try:
        client.wait_ready(WAIT_S)
        client.send(m.StartSession(str(tmp_path / "s.db"), "P01", "experiment", short_protocol, 3, 1))
        ring = client.ring
        assert ring is not None
        health: m.Health | None = None
        end = time.monotonic() + WAIT_S
        while health is None or not (len(rows := ring.latest(1)) and rows["gain"][0] == 1.0):  # feedback fully on
            assert time.monotonic() < end, "no trial with feedback on came"
            ev = client.get(0.01)
            health = ev if isinstance(ev, m.Health) else health
        assert health.loop_pid and health.loop_pid != client.pid
        os.kill(client.pid, signal.SIGKILL)  # type: ignore[arg-type]
        end = time.monotonic() + WAIT_S
        while _alive(health.loop_pid):
            assert time.monotonic() < end, "the loop's process did not end"
            time.sleep(0.01)
        last = ring.latest(200)
        detached = last[(last["faults"] & Fault.ENGINE_DETACHED) != 0]
        assert len(detached) and detached["gain"][-1] == 0.0  # latched, then ramped to zero within its ticks
        assert last["render_fx"][-1] == last["render_fy"][-1] == last["render_fz"][-1] == 0.0
        # the ramp: from the latch to zero within the safety stage's fault ramp (40 ms, records at 1 kHz)
        assert len(detached) <= 60
    finally:
        client.kill()


def _alive(pid: int) -> bool:
    from foundation.platform_support.processes import process_exists, process_stat_fields

    fields = process_stat_fields(pid)
    return process_exists(pid) and not (fields is not None and fields[0] == "Z")


def test_a_ring_capped_at_what_the_link_delivered_reads_no_further() -> None:
    ring = RingBuffer.create(("a",), 16, shared=False)
    for k in range(10):
        ring.write((float(k),))
    limit = [4]
    ring.cap(lambda: limit[0])
    got = ring.read_since(0)
    assert [r[0] for r in got.rows] == [0.0, 1.0, 2.0, 3.0] and got.cursor == 4 and got.lost == 0
    limit[0] = 10
    got = ring.read_since(got.cursor)
    assert [r[0] for r in got.rows] == [4.0, 5.0, 6.0, 7.0, 8.0, 9.0] and got.cursor == 10
    assert ring.write_count == 10 and len(ring.latest(3)) == 3  # the newest record's state is not capped
    ring.close()


def test_on_the_virtual_clock_the_loop_stays_in_the_engine_and_no_latency_is_stored(tmp_path, short_protocol) -> None:
    """Simulated time: the loop runs in the engine's step, nobody feels a force, and a session stores what it always
    stored (no latency in its config_json: the headless studies' bytes do not change)."""
    events: list[object] = []
    e = StudyEngine(HostConfig(clock="virtual", speed=0), events.append, shared_ring=False)
    e.start()
    db = str(tmp_path / "v.db")
    try:
        assert e.remote is None and e.latency is None and e.health().latency is None
        e.handle(m.StartSession(db, "P01", "experiment", short_protocol, 3, 1))
        run_until(e, lambda: any(isinstance(ev, m.SessionEnded) for ev in events), 120.0)
    finally:
        e.close("test over")
        e.release_ring()
    con = sqlite3.connect(db)
    try:
        (config_json,) = con.execute("SELECT config_json FROM sessions").fetchone()
    finally:
        con.close()
    assert "latency" not in json.loads(config_json)
