"""The study engine: in-process on the virtual clock, and as a process whose controller goes away."""

from __future__ import annotations

import json
import os
import sqlite3
import time

import pytest

from pipeline.devices.interfaces import Fault
from study_app.engine import messages as m
from study_app.engine.client import EngineClient
from study_app.engine.host import StudyEngine
from study_app.engine.setup import HostConfig


@pytest.fixture
def engine():
    events: list[object] = []
    e = StudyEngine(HostConfig(clock="virtual", speed=0), events.append, shared_ring=False)
    e.start()
    yield e, events
    if not e.closed:
        e.close("test over")
    e.release_ring()


def run_until(e: StudyEngine, pred, max_steps: int = 20_000) -> None:
    for _ in range(max_steps):
        if pred():
            return
        e.step()
    raise AssertionError("condition not reached")


def of(events, kind):
    return [ev for ev in events if isinstance(ev, kind)]


def db_rows(path, sql, *args):
    c = sqlite3.connect(path)
    try:
        return c.execute(sql, args).fetchall()
    finally:
        c.close()


def test_a_whole_session_is_stored_with_its_calibration(engine, tmp_path, short_protocol):
    e, events = engine
    db = str(tmp_path / "s.db")
    e.handle(m.StartSession(db, "P01", "experiment", short_protocol, 3, 1))
    assert of(events, m.CommandRefused) == []
    run_until(e, lambda: e.runner is None)
    started = of(events, m.TrialStarted)
    ended = of(events, m.TrialEnded)
    assert [t.position for t in started] == [1, 2]
    assert sorted(t.haptic_mode for t in started) == ["off", "on"]
    assert [t.record.trial_index for t in ended] == [0, 1]
    fin = of(events, m.SessionEnded)
    assert len(fin) == 1 and fin[0].status == "completed" and fin[0].completed == 2 and fin[0].aborted == 0
    stored = db_rows(db, "SELECT trial_index, outcome, rmse_n FROM trials ORDER BY trial_index")
    assert [(r[0], r[1]) for r in stored] == [(0, ended[0].record.outcome), (1, ended[1].record.outcome)]
    assert [r[2] for r in stored] == pytest.approx([t.record.metric("rmse_n") for t in ended])
    (status, cal_json, cfg_json), = db_rows(db, "SELECT status, calibration_json, config_json FROM sessions")
    assert status == "completed"
    assert json.loads(cal_json) == e.calibration.to_dict()
    assert json.loads(cfg_json)["app"] == "gui"
    assert db_rows(db, "SELECT SUM(n_records) FROM session_blocks")[0][0] > 2000  # the whole session, recorded


def test_calibration_refuses_a_degenerate_set_and_keeps_the_previous(engine):
    e, events = engine
    before = e.calibration
    e.handle(m.Calibrate("tool-down only"))
    done = of(events, m.CalibrationDone)[-1]
    assert not done.accepted and done.calibration is None
    assert "rank 6 of 10" in done.reason and done.condition_number > 1e12
    assert e.calibration is before
    assert [p.done for p in of(events, m.CalibrationProgress)] == [1, 2, 3, 4, 5, 6]


def test_calibration_accepts_a_good_set_and_installs_it(engine, tmp_path, short_protocol):
    e, events = engine
    e.handle(m.Calibrate("quick"))
    done = of(events, m.CalibrationDone)[-1]
    assert done.accepted and done.reason == "" and done.n_poses == 6
    assert done.condition_number < 100 and done.rms_force_residual_n < 0.01
    assert e.calibration.to_dict() == done.calibration
    for _ in range(4):
        e.step()
    h = e.health()
    # the loop paused for the calibration: that gap is not reported as an overrun
    assert h.ticks == 199 and h.periods_over_2ms == 0 and h.period_max_us == 1000.0
    db = str(tmp_path / "s.db")
    e.handle(m.StartSession(db, "P02", "training", short_protocol, 0, 2))
    (cal_json,), = db_rows(db, "SELECT calibration_json FROM sessions")
    assert json.loads(cal_json) == done.calibration


def test_commands_without_a_session_are_refused_with_a_reason(engine, tmp_path):
    e, events = engine
    e.handle(m.Pause())
    e.handle(m.StartSession(str(tmp_path / "s.db"), "bad code", "experiment", None, 0, 1))
    e.handle(m.StartSession(str(tmp_path / "nowhere" / "s.db"), "P01", "experiment", None, 0, 1))
    refused = of(events, m.CommandRefused)
    assert [r.command for r in refused] == ["Pause", "StartSession", "StartSession"]
    assert refused[0].message == "no session is running"
    assert refused[1].message.startswith("participant code = 'bad code'")
    assert "does not exist" in refused[2].message
    assert not (tmp_path / "s.db").exists()


def test_abort_trial_requeues_and_close_leaves_the_session_resumable(engine, tmp_path, short_protocol):
    e, events = engine
    db = str(tmp_path / "s.db")
    e.handle(m.StartSession(db, "P01", "experiment", short_protocol, 0, 1))
    run_until(e, lambda: len(of(events, m.TrialStarted)) == 1)
    e.handle(m.AbortTrial("participant sneezed"))
    run_until(e, lambda: len(of(events, m.TrialStarted)) == 2)
    assert of(events, m.TrialEnded)[0].record.outcome == "aborted"
    assert of(events, m.TrialStarted)[1].trials_total == 3  # re-queued at the end
    # a confirmation for the trial that ended is refused by the engine, and ignored by the runner had it been
    # queued before the trial ended (one test of a late abort: SessionRunner.trial_ended)
    e.handle(m.AbortTrial("too late", trial_index=0))
    assert of(events, m.CommandRefused)[-1].message == "trial 1 had already ended: nothing was aborted"
    e.runner.abort_trial("too late", trial_index=0)
    run_until(e, lambda: e.runner.machine.elapsed_ns > 200_000_000)
    assert e.runner.state.aborted == 1
    e.close("the experimenter GUI went away", detached=True)
    assert e.loop.faults & Fault.ENGINE_DETACHED
    assert e.loop.framework.safety.gain == 0.0
    assert of(events, m.SessionEnded)[-1].status == "interrupted"
    assert isinstance(events[-1], m.EngineStopped)
    rows = db_rows(db, "SELECT trial_index, outcome, abort_reason FROM trials ORDER BY trial_index")
    assert rows == [(0, "aborted", "participant sneezed"), (1, "aborted", "the experimenter GUI went away")]
    assert db_rows(db, "SELECT status FROM sessions") == [("running",)]
    assert db_rows(db, "SELECT kind, detail FROM events WHERE kind = 'detached'") == [
        ("detached", "the experimenter GUI went away")]
    assert db_rows(db, "SELECT detail FROM events WHERE detail LIKE '%ignored%'") == [
        ("abort_trial for trial 1 (index 0) ignored: it had ended",)]


def test_resume_continues_an_interrupted_session(tmp_path, short_protocol):
    db = str(tmp_path / "s.db")
    events: list[object] = []
    e = StudyEngine(HostConfig(clock="virtual", speed=0), events.append, shared_ring=False)
    e.start()
    e.handle(m.StartSession(db, "P01", "experiment", short_protocol, 0, 1))
    run_until(e, lambda: len(of(events, m.TrialStarted)) == 1 and e.runner.machine.elapsed_ns > 100_000_000)
    e.close("closed")
    e.release_ring()
    events.clear()
    e2 = StudyEngine(HostConfig(clock="virtual", speed=0), events.append, shared_ring=False)
    e2.start()
    try:
        e2.handle(m.ListSessions(db))
        (listed,) = of(events, m.SessionsListed)
        # counted as the GUI counts: designed trials done, aborted attempts (each queues a re-run), the schedule
        assert [(s["session_id"], s["trials_done"], s["trials_aborted"], s["trials_planned"], s["trials_total"])
                for s in listed.sessions] == [(1, 0, 1, 2, 3)]
        e2.handle(m.ResumeSession(db, 1))
        assert of(events, m.SessionStarted)[0].start_position == 1
        run_until(e2, lambda: e2.runner is None)
    finally:
        e2.close("test over")
        e2.release_ring()
    assert of(events, m.SessionEnded)[0].status == "completed"
    rows = db_rows(db, "SELECT trial_index, outcome FROM trials ORDER BY trial_index")
    assert [r[0] for r in rows] == [0, 1, 2] and rows[0][1] == "aborted" and rows[2][1] != "aborted"
    assert db_rows(db, "SELECT COUNT(*) FROM events WHERE kind = 'calibration'") == [(1,)]
    _assert_replays_bit_for_bit(db, 1, runs=2)


def _assert_replays_bit_for_bit(db: str, session_id: int, runs: int) -> None:
    """Each recorded run of the session, through the pipeline again, renders exactly what the GUI's engine did."""
    import numpy as np

    from pipeline.force.replay import replay
    from protocol.storage import connect_readonly
    from protocol.storage.recordings import read_segment, segments_of

    c = connect_readonly(db)
    try:
        segments = [read_segment(c, session_id, seg) for seg, _, _ in segments_of(c, session_id)]
    finally:
        c.close()
    assert len(segments) == runs
    peak_n = 0.0
    for s in segments:
        out = replay(s.replay_inputs())
        for axis in ("fx", "fy", "fz"):
            assert np.array_equal(out.column(f"render_{axis}"), s.columns[f"render_{axis}"])
        assert np.array_equal(out.force_n, s.columns["force_n"])
        peak_n = max(peak_n, float(np.hypot(np.hypot(s.columns["render_fx"], s.columns["render_fy"]),
                                            s.columns["render_fz"]).max()))
    assert peak_n > 0.05  # feedback was rendered: the comparison means something


def test_engine_process_exits_cleanly_when_the_gui_goes_away(tmp_path, short_protocol):
    """Close the command pipe mid-trial, as a crashed GUI would: force to zero, trial stored, exit."""
    db = str(tmp_path / "s.db")
    client = EngineClient(HostConfig(clock="virtual", speed=2.0))
    client.start()
    try:
        seen: list[object] = []

        def wait(pred, timeout_s: float = 30.0):
            end = time.monotonic() + timeout_s
            while not pred():
                ev = client.get(0.05)
                if ev is not None:
                    seen.append(ev)
                assert time.monotonic() < end, f"timed out; events: {[type(x).__name__ for x in seen]}"

        wait(lambda: any(isinstance(x, m.EngineReady) for x in seen))
        client.send(m.StartSession(db, "P01", "experiment", short_protocol, 0, 1))
        wait(lambda: any(isinstance(x, m.TrialStarted) for x in seen))
        ring = client.ring
        t_start = next(x for x in seen if isinstance(x, m.TrialStarted)).t_s
        wait(lambda: ring.latest(1)["t_s"][0] > t_start + 0.3)
        client.detach()
        wait(lambda: any(isinstance(x, m.EngineStopped) for x in seen))
        assert client.join(15.0)
        last = ring.latest(1)[0]
        assert last["faults"] == float(Fault.ENGINE_DETACHED) and last["gain"] == 0.0
        assert last["render_fx"] == last["render_fy"] == last["render_fz"] == 0.0
    finally:
        client.kill()
    assert db_rows(db, "SELECT trial_index, outcome, abort_reason FROM trials") == [
        (0, "aborted", "the experimenter GUI went away (closed or crashed)")]
    assert db_rows(db, "SELECT status FROM sessions") == [("running",)]
    assert db_rows(db, "SELECT SUM(n_records) FROM session_blocks")[0][0] > 250


def test_a_rehearsed_fault_is_stored_aborts_the_trial_and_waits_for_the_experimenters_reset(engine, tmp_path,
                                                                                            short_protocol):
    e, events = engine
    db = str(tmp_path / "f.db")
    e.handle(m.StartSession(db, "P01", "experiment", short_protocol, 3, 1))
    e.handle(m.InjectFault("sensor-stall", trial=1, seconds=0.2))
    assert of(events, m.CommandRefused) == [] and of(events, m.FaultInjected)[-1].when == "trial 1 + 0.2 s"
    run_until(e, lambda: of(events, m.TrialEnded))
    ended = of(events, m.TrialEnded)[0].record
    assert ended.outcome == "aborted" and ended.abort_reason.startswith("fault: SENSOR_STALE")
    # the GUI saw the fault; no cue follows until the experimenter resets
    assert any(f.kind == "fault" and f.detail.startswith("SENSOR_STALE") for f in of(events, m.EngineFault))
    run_until(e, lambda: e.health().waiting.startswith("fault latched (SENSOR_STALE)"))
    for _ in range(100):
        e.step()
    assert len(of(events, m.TrialStarted)) == 1
    e.handle(m.ResetFaults())
    run_until(e, lambda: e.runner is None)
    fin = of(events, m.SessionEnded)[-1]
    assert fin.status == "completed" and fin.aborted == 1 and fin.completed == 2
    stored = db_rows(db, "SELECT kind, detail FROM events WHERE kind IN ('fault', 'fault_cleared', 'faults_reset')")
    assert [k for k, _ in stored] == ["fault", "fault_cleared", "faults_reset"]
    rehearsal = db_rows(db, "SELECT detail FROM events WHERE kind = 'fault_rehearsal' ORDER BY t_s")
    assert rehearsal == [
        ("sensor-stall@P01:1+0.2: planned, to be rehearsed on the simulated rig (not a device failure)",),
        ("sensor-stall@P01:1+0.2: rehearsed on the simulated rig (not a device failure), due +0.2 s into trial 1",),
        ("sensor-stall@P01:1+0.2: injected during trial 1",)]
    assert db_rows(db, "SELECT abort_cause FROM trials WHERE outcome = 'aborted'") == [("fault",)]
    assert db_rows(db, "SELECT repeat_of FROM trials ORDER BY trial_index DESC LIMIT 1") == [(0,)]
    assert db_rows(db, "SELECT COUNT(*) FROM leases") == [(0,)]


def test_fault_rehearsal_now_and_its_refusals(engine, tmp_path, short_protocol):
    e, events = engine
    e.handle(m.InjectFault("nan-burst"))
    run_until(e, lambda: e.loop.faults & Fault.NON_FINITE)
    e.handle(m.InjectFault("melt-down"))
    e.handle(m.InjectFault("sensor-stall", trial=2, seconds=1.0))  # no session
    refused = [r.message for r in of(events, m.CommandRefused)]
    assert refused[0].startswith("fault kind = 'melt-down': allowed values are sensor-stall, nan-burst")
    assert refused[1].startswith("fault rehearsal at a trial: start or resume a session first")
    # a trial that has begun: the refusal says so and names the trials still to come
    e.handle(m.ResetFaults())  # the NaN burst's fault
    e.handle(m.StartSession(str(tmp_path / "r.db"), "P01", "experiment", short_protocol, 3, 1))
    run_until(e, lambda: of(events, m.TrialStarted))
    e.handle(m.InjectFault("sensor-stall", trial=1, seconds=1.0))
    e.handle(m.InjectFault("sensor-stall", trial=3, seconds=1.0))
    refused = [r.message for r in of(events, m.CommandRefused)]
    assert refused[-2:] == ["fault trial = 1: trial 1 has already begun; the one still to come is trial 2",
                            "fault trial = 3: the session has trials 1 to 2; the one still to come is trial 2"]
    # one rehearsed "now" during the session: its trial aborts, and the record says it was rehearsed
    e.handle(m.InjectFault("nan-burst"))
    run_until(e, lambda: of(events, m.TrialEnded))
    assert of(events, m.TrialEnded)[0].record.outcome == "aborted"
    e.handle(m.AbortSession("test over"))
    run_until(e, lambda: e.runner is None)
    assert db_rows(str(tmp_path / "r.db"), "SELECT detail FROM events WHERE kind = 'fault_rehearsal'") == [
        ("nan-burst: rehearsed on the simulated rig (not a device failure), now",)]


def test_no_trial_is_cued_to_a_participant_screen_that_is_closed(engine, tmp_path, short_protocol):
    """Issue 40, item 1: Start and Resume are refused while the GUI says the participant screen is closed; one that
    closes mid-trial aborts that trial (cause participant_screen, stored, run again later, as a trial a closed GUI
    cut is stored) and pauses the session, so no cue comes until it is open and the experimenter resumes."""
    from protocol.study.records import AbortCause, Outcome

    e, events = engine
    db = str(tmp_path / "s.db")
    e.handle(m.ParticipantScreenState(False, "closed"))
    e.handle(m.StartSession(db, "P01", "experiment", short_protocol, 3, 1))
    refused = of(events, m.CommandRefused)
    assert len(refused) == 1 and "the participant screen is closed" in refused[0].message
    assert e.runner is None and (not os.path.exists(db) or not db_rows(db, "SELECT * FROM sessions"))
    e.handle(m.ParticipantScreenState(True))
    e.handle(m.StartSession(db, "P01", "experiment", short_protocol, 3, 1))
    run_until(e, lambda: any(p.phase == "active" for p in of(events, m.PhaseEntered)))
    e.handle(m.ParticipantScreenState(False, "minimised"))  # mid-trial
    run_until(e, lambda: of(events, m.TrialEnded))
    rec = of(events, m.TrialEnded)[0].record
    assert rec.outcome is Outcome.ABORTED and rec.abort_cause is AbortCause.PARTICIPANT_SCREEN
    assert "participant screen was minimised" in (rec.abort_reason or "")
    cued = len(of(events, m.TrialStarted))
    for _ in range(200):  # 10 s of loop time, far past the protocol's 0.3 s pause: no cue while it is closed
        e.step()
    assert len(of(events, m.TrialStarted)) == cued and e.health().paused
    e.handle(m.Resume())
    assert "participant screen is minimised" in of(events, m.CommandRefused)[-1].message
    e.handle(m.ParticipantScreenState(True))
    e.handle(m.Resume())
    run_until(e, lambda: e.runner is None)
    assert of(events, m.SessionEnded)[-1].status == "completed"
    stored = db_rows(db, "SELECT trial_index, outcome, abort_cause, repeat_of FROM trials ORDER BY trial_index")
    assert stored == [(0, "aborted", "participant_screen", None), (1, stored[1][1], None, None),
                      (2, stored[2][1], None, 0)]  # the aborted trial run again at the end
    (detail,), = db_rows(db, "SELECT detail FROM events WHERE kind = 'participant_screen'")
    assert "minimised: trial 1 is stored as aborted and run again later" in detail
