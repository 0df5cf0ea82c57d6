"""Fault rehearsal does what it says: a planned kill loses what a live crash loses and leaves the cut trial stored
as interrupted; a fault planned for trial k lands in trial k, or is said to have been moved or withdrawn; and a
refused database path leaves nothing behind.

Headless on the virtual clock, one participant of a tiny protocol at a time.
"""

from __future__ import annotations

import os
import re
import sqlite3
import tomllib
from pathlib import Path

import pytest
from cli_subprocess import cli, tiny_protocol

from pipeline.sim.faults import FaultInjector, SimFault, latch_delay_s
from protocol.runner.rehearsal import FaultPlan, RehearsalTrigger
from protocol.study.clock import SessionClock
from protocol.study.config import ProtocolConfig, protocol_from_dict
from protocol.study.records import TrialRecord
from protocol.study.trial import PhaseChanged, TrialPhase
from study_app.headless import run_study

ROOT = Path(__file__).resolve().parents[2]


def protocol_text(max_trial_s: float = 2.0, pause_s: float = 0.5) -> str:
    return tiny_protocol("rehearsal", max_trial_s, 0.5, pause_s)


def protocol(max_trial_s: float = 2.0, pause_s: float = 0.5) -> ProtocolConfig:
    return protocol_from_dict(tomllib.loads(protocol_text(max_trial_s, pause_s)), "rehearsal protocol")


def rows(db: Path, sql: str, *args: object) -> list[tuple]:
    c = sqlite3.connect(db)
    try:
        return c.execute(sql, args).fetchall()
    finally:
        c.close()



@pytest.mark.parametrize("seconds", [0.5, 2.0])
def test_a_planned_kill_loses_at_most_100_ms_and_its_trial_is_stored_as_interrupted(tmp_path: Path,
                                                                                     seconds: float) -> None:
    """2.0: planned at the cap itself, the kill is moved to the trial's last millisecond, so it still cuts the trial."""
    (tmp_path / "p.toml").write_text(protocol_text(), encoding="utf-8")
    db = tmp_path / "study.db"
    killed = cli(["run", "--participants", "1", "--seed", "2", "--db", str(db), "--protocol", "p.toml",
                  "--inject-fault", f"kill@P01:2+{seconds:g}"], tmp_path)
    assert killed.returncode == -9, killed.stderr
    # the record says the interruption was a rehearsal (stored before it, whenever the kill falls)
    assert rows(db, "SELECT detail FROM events WHERE kind = 'fault_rehearsal'")[0] == (
        f"kill@P01:2+{seconds:g}: planned, to be rehearsed on the simulated rig (not a device failure)",)
    (cue_s,) = rows(db,
                    "SELECT t_s FROM events WHERE kind = 'phase' AND detail = 'trial 2 (index 1): cued -> active'")[0]
    kill_s = cue_s + min(seconds, 2.0 - 0.001)
    # the last record of the killed run: in its open block's chunks, appended at each commit
    (last_s,) = rows(db, "SELECT MAX(t_last_s) FROM session_chunks WHERE segment = 0")[0]
    assert kill_s - 0.100 - 1e-9 <= last_s <= kill_s + 1e-9  # at most one commit interval of records lost
    assert rows(db, "SELECT trial_index FROM trials") == [(0,)]
    run_study(str(db), participants=1, seed=2, protocol=protocol(), continue_study=True)
    ((outcome, cause, started, ended, n),) = rows(
        db, "SELECT outcome, abort_cause, started_at_s, ended_at_s, n_samples FROM trials WHERE trial_index = 1")
    assert (outcome, cause, started) == ("aborted", "interrupted", cue_s)
    assert ended == pytest.approx(last_s, abs=1e-9) and n == round((last_s - cue_s) * 1000) + 1
    assert rows(db, "SELECT COUNT(*) FROM trials WHERE outcome != 'aborted'") == [(4,)]  # every cell full


def test_a_planned_kill_in_a_parallel_study_stores_nothing_past_its_moment(tmp_path: Path) -> None:
    """Issue 42, class 8: the worker that planned the kill killed the study's main process and was left to die by
    PR_SET_PDEATHSIG; it ran on and committed up to 0.35 s of records past the kill's moment."""
    (tmp_path / "p.toml").write_text(protocol_text(), encoding="utf-8")
    db = tmp_path / "study.db"
    killed = cli(["run", "--participants", "2", "--jobs", "2", "--seed", "2", "--db", str(db), "--protocol", "p.toml",
                  "--inject-fault", "kill@P02:2+0.5"], tmp_path)
    assert killed.returncode == -9, killed.stderr
    ((sid,),) = rows(db, "SELECT s.session_id FROM sessions s JOIN participants p USING (participant_id) "
                         "WHERE p.code = 'P02'")
    ((cue_s,),) = rows(db, "SELECT t_s FROM events WHERE session_id = ? AND kind = 'phase' "
                           "AND detail = 'trial 2 (index 1): cued -> active'", sid)
    ((last_s,),) = rows(db, "SELECT MAX(t_last_s) FROM (SELECT t_last_s FROM session_chunks WHERE session_id = ? "
                            "UNION ALL SELECT t_last_s FROM session_blocks WHERE session_id = ?)", sid, sid)
    kill_s = cue_s + 0.5
    assert kill_s - 0.100 - 1e-9 <= last_s <= kill_s + 1e-9  # nothing past the kill, one commit interval lost at most


# 0.04 s: the shortest pause the protocol allows with haptics ON (the feedback's ramp-out), shorter than a stale
# pose's latch: a fault latched after its trial would hit the next one
@pytest.mark.parametrize("kind,pause_s", [("sensor-stall", 0.5), ("sensor-stall", 0.04), ("stale-pose", 0.04)])
def test_a_fault_planned_at_the_cap_is_moved_into_its_trial_and_said_so(tmp_path: Path, kind: str,
                                                                         pause_s: float) -> None:
    """Planned at the trial's cap, the watchdog would latch it after the trial: it is moved so that it latches
    inside, aborts that trial (not the next) and the report says where it went."""
    db = tmp_path / "study.db"
    progress = run_study(str(db), participants=1, seed=1, protocol=protocol(3.0, pause_s), jobs=1,
                         faults=[FaultPlan(kind, "P01", 1, 3.0)])
    outcomes = rows(db, "SELECT trial_index, outcome, abort_cause FROM trials ORDER BY trial_index")
    assert outcomes[0][1:] == ("aborted", "fault")
    assert all(o[1] != "aborted" for o in outcomes[1:]), outcomes  # the next trial is not hit
    delay = latch_delay_s(kind, 0.005, 0.050)
    (note,) = progress.rehearsals
    assert note == (f"{kind}@P01:1+3: injected during trial 1, moved to +{3.0 - delay - 0.001:.3f} s: a {kind} is "
                    f"latched up to {delay * 1e3:g} ms after it begins and trial 1 ends 3 s after its cue at the "
                    "latest")


class _Rig:
    """What the fault switches touch, for the injector alone."""

    class _Sensor:
        stalled = False

    def __init__(self) -> None:
        self.sensor = self._Sensor()


def test_a_fault_whose_trial_ends_before_the_watchdog_latches_it_is_ended_at_once() -> None:
    injector, rig = FaultInjector(), _Rig()
    calls: list[tuple[str, int]] = []

    def cancel(kind: str, at_ns: int) -> bool:
        calls.append((kind, at_ns))
        return injector.cancel(kind, at_ns, rig)

    trig = RehearsalTrigger.for_session([FaultPlan("sensor-stall", "P01", 1, 1.0)], "P01", "experiment", 0,
                                        lambda kind, at: injector.schedule(SimFault(kind, at, 0.02)),
                                        lambda: pytest.fail("no kill planned"), cancel, max_trial_s=2.0,
                                        latch_s=lambda kind: 0.007)
    trig.on_runner_event(PhaseChanged(5_000_000, 0, TrialPhase.CUED, TrialPhase.ACTIVE))
    injector.apply(rig, 1_006_000_000)  # the stall has begun ...
    assert rig.sensor.stalled
    # ... and the trial succeeds 2 ms later, before the watchdog can see it
    rec = TrialRecord(session_id=1, trial_index=0, target_label="GENTLE", target_force_n=0.6, haptic_mode="on",
                      outcome="success", clock=SessionClock(0.0, 0), cue_ns=5_000_000, end_ns=1_007_000_000)
    trig.on_runner_event(rec)
    assert calls == [("sensor-stall", 1_005_000_000)] and not rig.sensor.stalled and not injector.busy
    assert trig.report == [("sensor-stall@P01:1+1: begun 1 s into trial 1, which ended (success) 2 ms later, before "
                            "the watchdog latched it: ended at once, the trial was not aborted")]


def test_a_fault_whose_trial_the_experimenter_aborted_first_is_not_taken_for_its_abort() -> None:
    """Review: any aborted trial was stored as the fault's doing ("injected during trial 1"), an Esc inside the
    latch window too, and the fault was left to run on into the pause."""
    calls: list[tuple[str, int]] = []
    notes: list[str] = []
    trig = RehearsalTrigger.for_session([FaultPlan("sensor-stall", "P01", 1, 1.0)], "P01", "experiment", 0,
                                        lambda kind, at: None, lambda: pytest.fail("no kill planned"),
                                        lambda kind, at: calls.append((kind, at)), max_trial_s=2.0,
                                        latch_s=lambda kind: 0.007, note=lambda t, text: notes.append(text))
    trig.on_runner_event(PhaseChanged(5_000_000, 0, TrialPhase.CUED, TrialPhase.ACTIVE))
    rec = TrialRecord(session_id=1, trial_index=0, target_label="GENTLE", target_force_n=0.6, haptic_mode="on",
                      outcome="aborted", clock=SessionClock(0.0, 0), cue_ns=5_000_000, end_ns=1_007_000_000,
                      abort_reason="operator", abort_cause="experimenter")
    trig.on_runner_event(rec)
    assert calls == [("sensor-stall", 1_005_000_000)]  # ended at once, not left to run into the pause
    assert trig.report == ["sensor-stall@P01:1+1: begun 1 s into trial 1, which was aborted (experimenter) before "
                           "the watchdog latched it: ended at once, not the trial's abort"]
    assert notes[-1] == trig.report[-1] and "injected" not in notes[-1]


#: How the refusal of a path that is no regular file reads (the CLI names what it is, the storage layer says so)
_NOT_A_FILE = re.compile(r"is not a regular file|not a database file; give the path of a regular file")


def test_a_device_path_is_refused_and_nothing_is_left_beside_it(tmp_path: Path) -> None:
    fifo = tmp_path / "pipe.db"
    os.mkfifo(fifo)
    for args in (["run", "--participants", "1", "--db", str(fifo)], ["check", "--db", str(fifo)]):
        r = cli(args, tmp_path, timeout=60)  # (before: SQLite opened the pipe and waited for a writer)
        assert r.returncode == 2 and r.stderr.count("\n") == 1 and _NOT_A_FILE.search(r.stderr), r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pipe.db"]
    if os.access("/dev", os.W_OK):  # root: SQLite could create /dev/null-journal
        journal = Path("/dev/null-journal")
        before = journal.stat().st_mtime_ns if journal.exists() else None  # (another program's leftover, if any)
        r = cli(["run", "--participants", "1", "--db", "/dev/null"], tmp_path)
        assert r.returncode == 2 and _NOT_A_FILE.search(r.stderr), r.stderr
        assert (journal.stat().st_mtime_ns if journal.exists() else None) == before  # not made, not touched
