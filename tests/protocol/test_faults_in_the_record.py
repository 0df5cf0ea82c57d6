"""Faults in the study record: every fault kind rehearsed on the simulated rig is stored, aborts its trial with the
cause, is reset in the pause and re-run; a fault that does not clear interrupts the session; the true timeline.

Everything runs headless on the virtual clock, one participant of a 4-trial protocol at a time.
"""

from __future__ import annotations

import dataclasses
import itertools
import re
import sqlite3
from pathlib import Path

import pytest

import pipeline.sim.faults
from analysis.reading.load import load_study
from analysis.report.study_record import deviations
from analysis.stats.loop_health import abort_counts, health_table
from protocol.runner.rehearsal import FaultPlan, parse_fault_plan
from protocol.storage import HEALTH_COLUMNS
from protocol.study.config import default_protocol
from protocol.study.design import build_schedule
from study_app.headless import SessionInterrupted, resume_session, run_study

#: What each rehearsed kind latches, as the loop names it.
LATCHES = {"sensor-stall": "SENSOR_STALE", "nan-burst": "NON_FINITE", "bad-status": "SENSOR_STATUS",
           "stale-pose": "POSE_STALE", "device-error": "HAPTIC_DEVICE"}


def short_protocol():
    p = default_protocol()
    return dataclasses.replace(p, trials_per_cell=1, training=dataclasses.replace(p.training, enabled=False))


def rows(db: Path, sql: str, *args: object) -> list[tuple]:
    c = sqlite3.connect(db)
    try:
        return c.execute(sql, args).fetchall()
    finally:
        c.close()


def assert_true_timeline(db: Path, pause_s: float) -> None:
    """Every trial of every session starts at least the protocol's pause after the previous one ended."""
    for (sid,) in rows(db, "SELECT session_id FROM sessions"):
        trials = rows(db, "SELECT trial_index, started_at_s, ended_at_s FROM trials WHERE session_id = ? "
                          "ORDER BY started_at_s", sid)
        for (_, _, end), (idx, start, _) in itertools.pairwise(trials):
            assert start - end >= pause_s - 1e-9, f"session {sid}: trial {idx} cued {start - end:.3f} s after the last"


@pytest.mark.parametrize("kind", sorted(LATCHES))
def test_every_fault_kind_is_stored_aborts_its_trial_and_is_rerun(tmp_path: Path, kind: str) -> None:
    db = tmp_path / "study.db"
    proto = short_protocol()
    # 1 s after the cue of the 2nd trial: no trial can have succeeded yet (the hold alone lasts 1 s)
    progress = run_study(str(db), participants=1, seed=3, protocol=proto, jobs=1,
                         faults=[FaultPlan(kind, "P01", 2, 1.0)])
    assert progress.rehearsals == [f"{kind}@P01:2+1: injected during trial 2"]
    schedule = build_schedule(proto, 3, 1)
    second = schedule[1]
    (start, end, outcome, cause, reason), = rows(
        db, "SELECT started_at_s, ended_at_s, outcome, abort_cause, abort_reason FROM trials WHERE trial_index = 1")
    assert (outcome, cause) == ("aborted", "fault") and reason.startswith(f"fault: {LATCHES[kind]}")
    faults = rows(db, "SELECT t_s, detail FROM events WHERE kind = 'fault'")
    assert len(faults) == 1 and faults[0][1].startswith(LATCHES[kind]) and start < faults[0][0] <= end
    # the record says it was rehearsed, when it was planned and what it did: never taken for a device's failure
    planned, due, did = rows(db, "SELECT t_s, detail FROM events WHERE kind = 'fault_rehearsal' ORDER BY t_s")
    assert planned == (0.0, f"{kind}@P01:2+1: planned, to be rehearsed on the simulated rig (not a device failure)")
    assert due == (pytest.approx(start, abs=1e-9),
                   f"{kind}@P01:2+1: rehearsed on the simulated rig (not a device failure), due +1 s into trial 2")
    assert did == (pytest.approx(end, abs=1e-9), f"{kind}@P01:2+1: injected during trial 2")
    assert faults[0][0] == pytest.approx(end, abs=1e-9)  # the trial ended at the fault
    assert end - start == pytest.approx(1.0, abs=0.06)  # 1 s after the cue, plus the watchdog's own limit
    (reset_t, reset_detail), = rows(db, "SELECT t_s, detail FROM events WHERE kind = 'faults_reset'")
    assert reset_detail == f"cleared {LATCHES[kind]}" and reset_t > end
    # re-run at the end, and every cell complete
    trials = rows(db,
                  "SELECT trial_index, outcome, target_label, haptic_mode, repeat_of FROM trials ORDER BY trial_index")
    assert trials[-1][4] == 1 and trials[-1][2:4] == (second.target_label, second.haptic_mode)
    done = sorted((t[2], t[3]) for t in trials if t[1] != "aborted")
    assert done == sorted((s.target_label, s.haptic_mode) for s in schedule)
    assert rows(db, "SELECT status FROM sessions") == [("completed",)]
    # no cue while the fault was latched, and the protocol's pause after the reset
    (next_cue,) = rows(db, "SELECT MIN(started_at_s) FROM trials WHERE started_at_s > ?", end)[0]
    assert next_cue - max(end, reset_t) >= proto.trial.pause_s - 1e-9
    assert_true_timeline(db, proto.trial.pause_s)
    # the analysis counts it, by cause; and every trial has its loop health
    study = load_study([str(db)])
    counts = dict(zip(*abort_counts(study).to_dict("list").values(), strict=True))
    assert counts["fault"] == 1 and sum(counts.values()) == 1
    listed = deviations(study)  # and the report lists the rehearsal among the deviations from the design
    assert list(listed["kind"]) == ["fault_rehearsal"] * 3
    assert listed["detail"].iloc[2] == f"{kind}@P01:2+1: injected during trial 2"
    health = health_table(study)
    assert health[list(HEALTH_COLUMNS)].notna().all().all()
    if kind == "sensor-stall":  # the record that tripped the abort is the trial's: its health shows the stall
        (age,), = rows(db, "SELECT sensor_age_max_ms FROM trials WHERE trial_index = 1")
        assert age > 5.0


def test_a_run_without_faults_stores_none_and_its_health(tmp_path: Path) -> None:
    db = tmp_path / "study.db"
    run_study(str(db), participants=1, seed=3, protocol=short_protocol(), jobs=1)
    assert rows(db, "SELECT COUNT(*) FROM events WHERE kind IN ('fault', 'faults_reset', 'waiting')") == [(0,)]
    health = rows(db, f"SELECT {', '.join(HEALTH_COLUMNS)} FROM trials")
    assert len(health) == 4
    for p50, p99, pmax, over, sensor, pose, lat50, latmax in health:
        # the virtual clock: exactly 1 ms ticks, fresh samples, poses at the robot's 125 Hz (8 ms)
        assert (p50, p99, pmax, over, sensor) == (1.0, 1.0, 1.0, 0, 0.0)
        assert 0.0 <= pose < 8.0 and lat50 == latmax == 0.0


def test_a_fault_that_does_not_clear_interrupts_the_session_and_it_resumes(tmp_path: Path, monkeypatch) -> None:
    db = tmp_path / "study.db"
    proto = short_protocol()
    # the sensor stays silent for 30 s: it is still stalled 10 s after the runner began waiting
    monkeypatch.setitem(pipeline.sim.faults.DEFAULT_DURATION_S, "sensor-stall", 30.0)
    with pytest.raises(SessionInterrupted) as info:
        run_study(str(db), participants=1, seed=3, protocol=proto, jobs=1,
                  faults=[FaultPlan("sensor-stall", "P01", 2, 1.0)])
    msg = str(info.value)
    assert msg.startswith("P01's experiment session 1: SENSOR_STALE was still latched 10 s after the runner began")
    assert msg.endswith("the session is interrupted and can be resumed") and "\n" not in msg
    assert rows(db, "SELECT status FROM sessions") == [("running",)]
    assert rows(db, "SELECT kind FROM events WHERE kind = 'session_interrupted'") == [("session_interrupted",)]
    assert rows(db, "SELECT COUNT(*) FROM leases") == [(0,)]  # given back
    attempts = rows(db, "SELECT COUNT(*) FROM events WHERE kind = 'faults_reset'")[0][0]
    assert 10 <= attempts <= 25  # tried every 0.5 s while it persisted
    monkeypatch.undo()
    progress = resume_session(str(db), "P01")
    assert progress.study_trials_done == progress.study_trials_total
    assert rows(db, "SELECT status FROM sessions") == [("completed",)]
    done = rows(db, "SELECT COUNT(*) FROM trials WHERE outcome != 'aborted'")[0][0]
    assert done == proto.trials_per_participant
    assert_true_timeline(db, proto.trial.pause_s)


@pytest.mark.parametrize(("text", "message"), [
    ("sensor-stall@P01:4", None),
    ("kill@P02:1+0", None),
    ("stall@P01:4", "kind 'stall' is not one of sensor-stall"),
    ("sensor-stall@P 01:4", "participant code 'P 01' must be"),
    ("sensor-stall@P01:0", "trial '0' must be a whole number ≥ 1"),
    ("sensor-stall@P01:x", "trial 'x' must be a whole number"),
    ("sensor-stall@P01:4+nan", "seconds 'nan' must be a number from 0 to 600"),
    ("sensor-stall@P01:4+-1", "seconds '-1' must be a number from 0 to 600"),
    ("sensor-stall", "expected KIND@CODE:TRIAL[+SECONDS]"),
])
def test_fault_plans_are_read_or_refused_in_one_line(text: str, message: str | None) -> None:
    if message is None:
        plan = parse_fault_plan(text)
        assert str(plan).split("+")[0] == text.split("+")[0]
        return
    with pytest.raises(ValueError) as info:
        parse_fault_plan(text)
    assert message in str(info.value) and str(info.value).startswith(f"--inject-fault = {text!r}: ")


def test_fault_plans_for_participants_or_trials_not_run_are_refused(tmp_path: Path) -> None:
    db = tmp_path / "never.db"
    for plan, says in [(FaultPlan("kill", "P03", 1), "participant P03 is not run by this command"),
                       (FaultPlan("kill", "P01", 5), "trial 5 is beyond the 4 trials of the experiment session"),
                       (FaultPlan("kill", "P01", 1, 13.0), "13 s is after the trial's end at the latest (12 s")]:
        with pytest.raises(ValueError, match=re.escape(says)):
            run_study(str(db), participants=2, seed=3, protocol=short_protocol(), faults=[plan])
    assert not db.exists()


def test_a_fault_planned_after_its_trial_ends_is_withdrawn_and_said_so(tmp_path: Path) -> None:
    db = tmp_path / "study.db"
    proto = short_protocol()
    # 7 s after the cue: this trial succeeded after 5.4 s (participant model v3; 6.5 s with v2); the fault would
    # otherwise land on the pause or the next trial
    progress = run_study(str(db), participants=1, seed=3, protocol=proto, jobs=1,
                         faults=[FaultPlan("sensor-stall", "P01", 4, 7.0)])
    (note,) = progress.rehearsals
    assert note == "sensor-stall@P01:4+7: not injected: trial 4 ended (success) 5.4 s after its cue, before +7 s"
    assert rows(db, "SELECT COUNT(*) FROM events WHERE kind IN ('fault', 'faults_reset')") == [(0,)]
    assert rows(db, "SELECT COUNT(*) FROM trials WHERE outcome = 'aborted'") == [(0,)]


def test_trials_failing_again_and_again_stop_the_session_resumable(tmp_path: Path) -> None:
    db = tmp_path / "study.db"
    proto = short_protocol()
    plans = [FaultPlan("nan-burst", "P01", n, 0.5) for n in (1, 2, 3)]
    with pytest.raises(SessionInterrupted) as info:
        run_study(str(db), participants=1, seed=3, protocol=proto, jobs=1, faults=plans)
    msg = str(info.value)
    assert "3 trials in a row were not delivered as designed" in msg and "\n" not in msg
    assert rows(db, "SELECT abort_cause, COUNT(*) FROM trials GROUP BY abort_cause") == [("fault", 3)]
    assert rows(db, "SELECT status FROM sessions") == [("running",)]
    progress = resume_session(str(db), "P01")
    assert progress.study_trials_done == progress.study_trials_total
    done = rows(db, "SELECT COUNT(*) FROM trials WHERE outcome != 'aborted'")[0][0]
    assert done == proto.trials_per_participant
    assert_true_timeline(db, proto.trial.pause_s)
