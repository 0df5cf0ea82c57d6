"""The study engine (the GUI's) on the Lab Streaming Layer: ``gui --lsl`` publishes every session's markers, and a
virtual-clock engine refuses it in one line, storing nothing.

The real-clock session is cut short by the experimenter's abort after its first cue (~1 s): the markers an inlet
receives are the session's start, the cue, the abort and the end, at the times the database stores.
"""

from __future__ import annotations

import json
import sqlite3
import threading

import pylsl

from study_app.engine import messages as m
from study_app.engine.host import StudyEngine
from study_app.engine.setup import HostConfig

#: Bounded waits for the network, s.
RESOLVE_S = 10.0


def _engine(clock: str, events: list) -> StudyEngine:
    e = StudyEngine(HostConfig(clock=clock, speed=0, lsl=True, loop_process=False), events.append,
                    shared_ring=False)
    e.start()
    return e


def test_a_virtual_clock_engine_refuses_lsl_and_stores_nothing(tmp_path, short_protocol):
    events: list = []
    e = _engine("virtual", events)
    try:
        e.handle(m.StartSession(str(tmp_path / "s.db"), "P01", "training", short_protocol, 0, 1))
    finally:
        e.close("test over")
        e.release_ring()
    refused = [ev for ev in events if isinstance(ev, m.CommandRefused)]
    assert len(refused) == 1 and "needs the real clock" in refused[0].message
    assert not (tmp_path / "s.db").exists()


def test_the_engine_publishes_a_sessions_markers(tmp_path, short_protocol):
    events: list = []
    e = _engine("real", events)
    db = str(tmp_path / "s.db")
    try:
        e.handle(m.StartSession(db, "P01", "training", short_protocol, 0, 1))
        started = [ev for ev in events if isinstance(ev, m.SessionStarted)]
        assert started, [ev for ev in events if isinstance(ev, m.CommandRefused)]
        # the outlets exist once the session started; the inlet listens before the engine reads the first record
        found = pylsl.resolve_byprop("source_id", f"haptic-study/short GUI test protocol (seed 0)/P01/"
                                                  f"session-{started[0].session_id}/markers", 1, RESOLVE_S)
        assert found, "the engine's markers outlet was not found on this machine"
        inlet = pylsl.StreamInlet(found[0], recover=False)
        inlet.open_stream(timeout=RESOLVE_S)
        markers: list[dict] = []
        stamps: list[float] = []
        lost = threading.Event()

        def listen() -> None:  # (a closed outlet's inlet answers no more: what it sent is taken as it comes)
            while pylsl.local_clock() < deadline:
                try:
                    chunk, ts = inlet.pull_chunk(timeout=0.05)
                except pylsl.util.LostError:  # the outlet closed after the session's end
                    break
                markers.extend(json.loads(s[0]) for s in chunk)
                stamps.extend(ts)
            lost.set()

        deadline = pylsl.local_clock() + 60.0
        listener = threading.Thread(target=listen, daemon=True)
        listener.start()
        for _ in range(200_000):  # (steps of the driver; each waits for the next tick on the real clock)
            e.step()
            if any(mk["event"] == "cue" for mk in list(markers)):
                break
        e.handle(m.AbortSession("test over"))
        for _ in range(200_000):
            e.step()
            if any(isinstance(ev, m.SessionEnded) for ev in events):
                break
        lost.wait(RESOLVE_S)
    finally:
        if not e.closed:
            e.close("test over")
        e.release_ring()
    assert [mk["event"] for mk in markers][:2] == ["session_start", "cue"]
    assert markers[1]["trial"] == 1 and "haptics" in markers[1]
    assert "session_end" in [mk["event"] for mk in markers]
    conn = sqlite3.connect(db)
    started_s, t0_ns = conn.execute("SELECT started_at_s, t0_ns FROM recordings").fetchone()
    link, outlets = conn.execute("SELECT records_to_lsl_s, outlets FROM lsl_runs").fetchone()
    cue_s, = conn.execute("SELECT t_s FROM events WHERE kind = 'cue'").fetchone()
    assert abs(stamps[1] - ((cue_s - started_s) + t0_ns * 1e-9 + link)) < 1e-3  # (one machine: one clock)
    assert [o["name"] for o in json.loads(outlets)] == ["haptic-study force", "haptic-study markers"]
