"""Headless studies end to end: a short study on the virtual clock, crash (SIGKILL) and resume, bad input."""

from __future__ import annotations

import dataclasses
import json
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from records import all_records, trial_samples

from protocol.storage import StorageError, StudyDatabase
from protocol.study.config import default_protocol
from protocol.study.design import build_schedule, schedule_from_json
from study_app.headless import resume_session, run_study

ROOT = Path(__file__).resolve().parents[2]


def short_protocol(trials_per_cell: int = 1, training: bool = False):
    """The paper's protocol with fewer trials (4 per participant), short pauses (the 2 s pause between trials
    only adds ticks to simulate; 0.1 s is above the feedback's ramp-out) and an optional short training block."""
    p = default_protocol()
    return dataclasses.replace(
        p,
        trials_per_cell=trials_per_cell,
        trial=dataclasses.replace(p.trial, pause_s=0.1),
        training=dataclasses.replace(p.training, enabled=training, seconds_per_target_per_mode=3.0),
    )


def rows(db: Path, sql: str, *args: object) -> list[tuple]:
    c = sqlite3.connect(db)
    try:
        return c.execute(sql, args).fetchall()
    finally:
        c.close()


def test_short_study_end_to_end(tmp_path: Path) -> None:
    db = tmp_path / "study.db"
    proto = short_protocol(training=True)
    progress = run_study(str(db), participants=2, seed=11, protocol=proto)
    # participants run in parallel worker processes (the default jobs): session ids are allocated in any order
    sessions = rows(db, "SELECT session_id, kind, status, schedule_json, participant_number FROM sessions "
                        "ORDER BY participant_number, session_id")
    assert [(s[1], s[2]) for s in sessions] == [("training", "completed"), ("experiment", "completed")] * 2
    assert progress.sessions == [s[0] for s in sessions]
    for sid, kind, _, sched_json, number in sessions:
        schedule = schedule_from_json(sched_json)
        if kind == "experiment":
            assert schedule == build_schedule(proto, 11, number)  # the stored schedule is the one run
        trials = rows(db, "SELECT trial_index, target_label, haptic_mode, outcome, tct_s, n_samples, trial_id "
                          "FROM trials WHERE session_id = ? ORDER BY trial_index", sid)
        assert [(t[0], t[1], t[2]) for t in trials] == [(s.index, s.target_label, s.haptic_mode) for s in schedule]
        for t in trials:
            assert t[3] in ("success", "timeout")
            assert (t[4] is not None) == (t[3] == "success")
            smp = trial_samples(db, t[6])
            assert len(smp) == t[5]  # every sample of the trial window is stored, once
            assert smp["t_s"].iloc[0] == 0.0
            if t[3] == "success":
                assert smp["t_s"].iloc[-1] == pytest.approx(t[4], abs=1e-9)  # TCT = the last sample of the window
            else:
                assert smp["t_s"].iloc[-1] == pytest.approx(12.0 if kind == "experiment" else 3.0, abs=1e-9)
    # provenance stored before trial 1
    cfg = json.loads(rows(db, "SELECT config_json FROM sessions LIMIT 1")[0][0])
    assert cfg["rig"] == "sim" and cfg["framework"]["f_max_n"] == 3.0
    assert rows(db, "SELECT COUNT(*) FROM events WHERE kind = 'cue'")[0][0] == 2 * (4 + 4)
    # nothing is overwritten: running the same codes again is refused, the data untouched
    before = rows(db, "SELECT SUM(n_records) FROM session_blocks")[0][0]
    with pytest.raises(StorageError, match="already holds sessions for participant P01"):
        run_study(str(db), participants=1, seed=11, protocol=proto)
    assert rows(db, "SELECT SUM(n_records) FROM session_blocks")[0][0] == before


def test_same_seed_same_study(tmp_path: Path) -> None:
    proto = short_protocol()
    a, b = tmp_path / "a.db", tmp_path / "b.db"
    run_study(str(a), participants=1, seed=5, protocol=proto)
    run_study(str(b), participants=1, seed=5, protocol=proto)
    q = "SELECT trial_index, outcome, tct_s, rmse_n, max_ae_n FROM trials ORDER BY trial_id"
    assert rows(a, q) == rows(b, q)
    assert rows(a, "SELECT data FROM session_blocks ORDER BY session_id, segment, block") == rows(
        b, "SELECT data FROM session_blocks ORDER BY session_id, segment, block")  # the recordings, byte for byte


def _run_cli(args: list[str], env: dict[str, str] | None = None,
             timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "study_app.cli", *args], capture_output=True, text=True, timeout=timeout,
        env={**os.environ, **(env or {})}, cwd=ROOT,
    )


def _run_killed_in_training(db: Path, proto: Path, participants: int, seed: int, trial: int, seconds: float) -> int:
    """A study killed (SIGKILL) ``seconds`` into P01's ``trial``-th practice trial; the command line plans only
    experiment trials, so this runs the library in a subprocess of its own.  Returns the exit status."""
    code = (
        "from protocol.study.config import load_protocol\n"
        "from protocol.runner.rehearsal import FaultPlan\n"
        "from study_app.headless import run_study\n"
        f"run_study({str(db)!r}, participants={participants}, seed={seed}, protocol=load_protocol({str(proto)!r}), "
        f"jobs=1, faults=[FaultPlan('kill', 'P01', {trial}, {seconds}, 'training')])\n"
    )
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                          cwd=ROOT).returncode


@pytest.mark.parametrize("kill_at", ["kill@P01:1+9", "kill@P01:3+4"])
def test_sigkill_then_resume_loses_and_duplicates_nothing(tmp_path: Path, kill_at: str) -> None:
    """SIGKILL mid-study (a real kill -9 of the process), then --resume: every finished trial intact, none twice."""
    db = tmp_path / "crash.db"
    proto = tmp_path / "short.toml"
    proto.write_text(
        (ROOT / "protocol" / "study" / "default.toml").read_text().replace("trials_per_cell = 5", "trials_per_cell = 2")
        .replace("enabled = true", "enabled = false")
    )
    killed = _run_cli(["run", "--participants", "1", "--seed", "3", "--db", str(db), "--protocol", str(proto),
                       "--inject-fault", kill_at])
    assert killed.returncode == -9  # SIGKILL
    before = rows(db, "SELECT trial_index, outcome, tct_s, rmse_n, n_samples FROM trials ORDER BY trial_index")
    sid = rows(db, "SELECT session_id FROM sessions WHERE kind = 'experiment'")[0][0]
    assert rows(db, "SELECT status FROM sessions WHERE session_id = ?", sid)[0][0] == "running"
    # every finished trial has all its samples committed (the trial row commits them)
    for idx, _, _, _, n in before:
        assert len(trial_samples(db, sid * 1_000_000 + idx)) == n
    schedule = schedule_from_json(rows(db, "SELECT schedule_json FROM sessions WHERE session_id = ?", sid)[0][0])
    interrupted = schedule[len(before)]
    marked = [cols for (s, _), cols in all_records(db).items() if s == sid]
    in_trial = np.concatenate([c["trial_index"] == interrupted.index for c in marked]) if marked else np.empty(0, bool)
    t_ns = np.concatenate([c["t_ns"] for c in marked])[in_trial] if marked else np.empty(0)
    partial = (int(in_trial.sum()), (t_ns[-1] - t_ns[0]) / 1e9 if len(t_ns) else None)

    resumed = _run_cli(["run", "--db", str(db), "--resume", "P01"])
    assert resumed.returncode == 0, resumed.stderr
    after = rows(db, "SELECT trial_index, outcome, tct_s, rmse_n, n_samples, abort_reason, repeat_of, target_label, "
                     "haptic_mode FROM trials WHERE session_id = ? ORDER BY trial_index", sid)
    assert [a[:5] for a in after[: len(before)]] == before  # finished trials untouched
    final_schedule = schedule_from_json(rows(db, "SELECT schedule_json FROM sessions WHERE session_id = ?", sid)[0][0])
    assert [a[0] for a in after] == [s.index for s in final_schedule]  # nothing skipped or duplicated
    if partial[0]:
        # killed mid-trial: that trial is stored as aborted with the reason, its real cue and its samples,
        # and re-run at the end
        ab = after[len(before)]
        assert ab[1] == "aborted" and "interrupted" in ab[5] and ab[4] == partial[0]
        (cue,) = rows(db, "SELECT t_s FROM events WHERE session_id = ? AND kind = 'phase' AND detail = ?",
                      sid, f"trial {interrupted.index + 1} (index {interrupted.index}): cued -> active")
        started, ended, cause = rows(db, "SELECT started_at_s, ended_at_s, abort_cause FROM trials WHERE trial_id = ?",
                                     sid * 1_000_000 + interrupted.index)[0]
        assert started == cue[0] and ended == pytest.approx(cue[0] + partial[1], abs=1e-9) and cause == "interrupted"
        assert after[-1][6] == interrupted.index
        assert (after[-1][7], after[-1][8]) == (interrupted.target_label, interrupted.haptic_mode)
    completed = [a for a in after if a[1] != "aborted"]
    cells = sorted((a[7], a[8]) for a in completed)
    assert cells == sorted((s.target_label, s.haptic_mode) for s in build_schedule(
        dataclasses.replace(short_protocol(2)), 3, 1))  # balanced: every cell its full count
    assert rows(db, "SELECT status FROM sessions WHERE session_id = ?", sid)[0][0] == "completed"
    # a second resume has nothing to continue
    again = _run_cli(["run", "--db", str(db), "--resume", "P01"])
    assert again.returncode == 2 and "no interrupted session" in again.stderr


def test_bad_input_is_refused_before_anything_is_stored(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text((ROOT / "protocol" / "study" / "default.toml").read_text().replace("hold_s = 1.0", "hold_s = -1.0"))
    db = tmp_path / "x.db"
    r = _run_cli(["run", "--participants", "1", "--db", str(db), "--protocol", str(bad)], timeout=60)
    assert r.returncode == 2 and "trial.hold_s = -1.0" in r.stderr and "Traceback" not in r.stderr
    assert not db.exists()
    r = _run_cli(["run", "--participants", "1", "--db", str(tmp_path / "nowhere" / "x.db")], timeout=60)
    assert r.returncode == 2 and "does not exist" in r.stderr
    r = _run_cli(["run", "--db", str(db), "--resume", "bad code!"], timeout=60)
    assert r.returncode == 2 and "--resume: 'bad code!': must be 1–32 characters" in r.stderr  # parsed as a code
    newer = tmp_path / "newer.db"
    StudyDatabase(newer).close()
    c = sqlite3.connect(newer)
    c.execute("PRAGMA user_version = 9")
    c.close()
    r = _run_cli(["run", "--participants", "1", "--db", str(newer)], timeout=60)
    assert r.returncode == 2 and "newer than this software supports" in r.stderr
    r = _run_cli(["run", "--db", str(newer.with_name("missing.db")), "--resume", "P01"], timeout=60)
    assert r.returncode == 2


def test_resume_for_unknown_code(tmp_path: Path) -> None:
    db = tmp_path / "s.db"
    StudyDatabase(db).close()
    with pytest.raises(StorageError, match="no such participant"):
        resume_session(str(db), "P07")


def test_parallel_study_matches_sequential(tmp_path: Path) -> None:
    """jobs=2 (one worker process per participant, one shared database) stores exactly what jobs=1 stores."""
    proto = short_protocol(training=True)
    proto = dataclasses.replace(proto, trial=dataclasses.replace(proto.trial, max_trial_s=4.0))  # keep it fast
    seq, par = tmp_path / "seq.db", tmp_path / "par.db"
    seen: list[tuple[int, int, int]] = []
    p1 = run_study(str(seq), participants=2, seed=21, protocol=proto, jobs=1)
    p2 = run_study(str(par), participants=2, seed=21, protocol=proto, jobs=2,
                   on_progress=lambda p: seen.append((p.participant, p.study_trials_done, p.study_trials_total)))
    trials = ("SELECT p.code, s.kind, t.trial_index, t.outcome, t.tct_s, t.rmse_n, t.max_ae_n, t.n_samples, "
              "t.last_tick - t.first_tick "
              "FROM trials t JOIN sessions s USING (session_id) JOIN participants p USING (participant_id) "
              "ORDER BY p.code, s.kind, t.trial_index")
    a, b = rows(seq, trials), rows(par, trials)
    assert len(a) == 2 * (4 + 4)
    assert a == b
    sched = ("SELECT p.code, s.kind, s.schedule_json, s.status FROM sessions s JOIN participants p "
             "USING (participant_id) ORDER BY p.code, s.kind")
    assert rows(seq, sched) == rows(par, sched)
    blocks = ("SELECT p.code, s.kind, b.segment, b.block, b.data FROM session_blocks b JOIN sessions s "
              "USING (session_id) JOIN participants p USING (participant_id) "
              "ORDER BY p.code, s.kind, b.segment, b.block")
    assert rows(seq, blocks) == rows(par, blocks)  # the whole recordings, byte for byte
    # the summary: the same sessions, in participant order (training before experiment), whatever their ids
    def described(db: Path, sessions: list[int]) -> list[tuple]:
        return [rows(db, "SELECT p.code, s.kind FROM sessions s JOIN participants p USING (participant_id) "
                         "WHERE s.session_id = ?", sid)[0] for sid in sessions]
    assert described(seq, p1.sessions) == described(par, p2.sessions) == [
        ("P01", "training"), ("P01", "experiment"), ("P02", "training"), ("P02", "experiment")]
    assert p2.study_trials_done == p1.study_trials_done == p2.study_trials_total == 16
    assert p2.study_time_s == pytest.approx(p1.study_time_s, abs=1e-6)
    # progress came from the workers, summed over them, and never went backwards
    assert seen and seen[-1][1:] == (16, 16) and {s[0] for s in seen} == {1, 2}
    assert [s[1] for s in seen] == sorted(s[1] for s in seen)


def _processes_mentioning(text: str) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if text.encode() in (d / "cmdline").read_bytes():
                    out.append(int(d.name))
            except OSError:
                pass
    return out


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_sigkill_of_a_parallel_study_leaves_no_orphan_and_resumes(tmp_path: Path) -> None:
    """kill -9 of a parallel `run`: the workers die with it, finished trials are intact, each participant resumes."""
    db = tmp_path / "crash-par.db"
    proto = tmp_path / "short.toml"
    proto.write_text(
        (ROOT / "protocol" / "study" / "default.toml").read_text().replace("trials_per_cell = 5", "trials_per_cell = 1")
        .replace("enabled = true", "enabled = false")
    )
    killed = _run_cli(["run", "--participants", "2", "--jobs", "2", "--seed", "3", "--db", str(db),
                       "--protocol", str(proto), "--inject-fault", "kill@P02:3+9"])
    assert killed.returncode == -9
    # the workers got SIGKILL from the kernel when the main process died (reaped by init: poll, don't sleep blindly)
    import time

    deadline = time.monotonic() + 10.0
    while _processes_mentioning(str(db)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert _processes_mentioning(str(db)) == []
    sessions = rows(db, "SELECT p.code, s.session_id, s.status FROM sessions s JOIN participants p "
                        "USING (participant_id) WHERE s.kind = 'experiment' ORDER BY s.session_id")
    status = {code: st for code, _, st in sessions}
    # P02's was cut by the kill; P01's ran beside it and may have ended first (the two workers start and run at the
    # speed the machine gives each: CI on a clean clone once saw P01 done before P02's kill)
    assert len(sessions) == 2 and status["P02"] == "running" and status["P01"] in ("running", "completed"), status
    for _, sid, _ in sessions:
        for idx, n in rows(db, "SELECT trial_index, n_samples FROM trials WHERE session_id = ?", sid):
            assert len(trial_samples(db, sid * 1_000_000 + idx)) == n
    for code in (c for c, st in status.items() if st == "running"):
        r = _run_cli(["run", "--db", str(db), "--resume", code])
        assert r.returncode == 0, r.stderr
    assert rows(db, "SELECT status FROM sessions ORDER BY session_id") == [("completed",), ("completed",)]
    for _, sid, _ in sessions:
        done = rows(db, "SELECT target_label, haptic_mode FROM trials WHERE session_id = ? "
                        "AND outcome != 'aborted'", sid)
        assert len(done) == 4 and len(set(done)) == 4  # every cell once: nothing skipped or duplicated


def test_a_crashed_worker_stops_the_study_with_one_clear_error(tmp_path: Path) -> None:
    """A worker that dies without a word (here SIGKILLed) is named; the others are stopped; data stays resumable."""
    import multiprocessing
    import signal

    from study_app.headless import StudyWorkerError

    db = tmp_path / "crash.db"

    def kill_p02_once_started(p) -> None:
        if p.study_trials_done >= 1:
            for child in multiprocessing.active_children():
                if child.name == "study-P02" and child.is_alive():
                    os.kill(child.pid, signal.SIGKILL)

    with pytest.raises(StudyWorkerError) as err:
        run_study(str(db), participants=2, seed=4, protocol=short_protocol(), jobs=2,
                  on_progress=kill_p02_once_started)
    msg = str(err.value)
    assert msg.startswith("participant P02 failed (its worker process ended with exit code -9); "
                          "the other participants were stopped, their committed data is kept")
    assert multiprocessing.active_children() == []
    for t_id, n in rows(db, "SELECT trial_id, n_samples FROM trials"):
        assert len(trial_samples(db, t_id)) == n
    assert msg.endswith("complete the study with the same command and --continue")
    before = rows(db, "SELECT trial_id, outcome, tct_s, n_samples FROM trials ORDER BY trial_id")
    progress = run_study(str(db), participants=2, seed=4, protocol=short_protocol(), jobs=2, continue_study=True)
    assert rows(db, "SELECT p.code, s.kind, s.status FROM sessions s JOIN participants p USING (participant_id) "
                    "ORDER BY p.code") == [("P01", "experiment", "completed"), ("P02", "experiment", "completed")]
    after = rows(db, "SELECT trial_id, outcome, tct_s, n_samples FROM trials ORDER BY trial_id")
    assert set(before) <= set(after)  # what was stored stays as it was
    assert sorted(progress.sessions) == [s[0] for s in rows(db, "SELECT session_id FROM sessions ORDER BY session_id")]


def test_parallel_study_stops_its_workers_when_the_parent_fails(tmp_path: Path) -> None:
    """An exception in the parent (here from the progress display) kills the workers; their sessions stay resumable."""
    import multiprocessing

    db = tmp_path / "stop.db"

    class Stop(Exception):
        pass

    def fail_once_both_started(p) -> None:
        # both sessions open and a trial stored: on a busy machine the second worker may start well after the first
        if p.study_trials_done >= 1 and rows(db, "SELECT status FROM sessions") == [("running",), ("running",)]:
            raise Stop

    with pytest.raises(Stop):
        run_study(str(db), participants=2, seed=4, protocol=short_protocol(), jobs=2,
                  on_progress=fail_once_both_started)
    assert multiprocessing.active_children() == []  # killed and reaped, none left writing
    before = rows(db, "SELECT trial_id, outcome, n_samples FROM trials ORDER BY trial_id")
    assert rows(db, "SELECT status FROM sessions") == [("running",), ("running",)]
    for t_id, _, n in before:
        assert len(trial_samples(db, t_id)) == n
    resume_session(str(db), "P02")
    assert sorted(rows(db, "SELECT p.code, s.status FROM sessions s JOIN participants p USING (participant_id)")) == [
        ("P01", "running"), ("P02", "completed")]


def _short_training_toml(tmp_path: Path) -> Path:
    proto = tmp_path / "short-training.toml"
    proto.write_text(
        (ROOT / "protocol" / "study" / "default.toml").read_text().replace("trials_per_cell = 5", "trials_per_cell = 1")
        .replace("seconds_per_target_per_mode = 20.0", "seconds_per_target_per_mode = 4.0")
    )
    return proto


def _participant_sessions(db: Path) -> list[tuple]:
    return rows(db, "SELECT p.code, s.kind, s.status FROM sessions s JOIN participants p USING (participant_id) "
                    "ORDER BY p.code, s.kind DESC")


def test_continue_completes_a_study_killed_during_training(tmp_path: Path) -> None:
    """kill -9 during P01's training: `--continue` resumes that training, then runs everything not started."""
    db = tmp_path / "crash-training.db"
    proto = _short_training_toml(tmp_path)
    args = ["run", "--participants", "2", "--jobs", "1", "--seed", "8", "--db", str(db), "--protocol", str(proto)]
    assert _run_killed_in_training(db, proto, 2, 8, 2, 1.0) == -9  # 1 s into P01's 2nd practice trial
    assert _participant_sessions(db) == [("P01", "training", "running")]
    training_sid = rows(db, "SELECT session_id FROM sessions")[0][0]
    before = rows(db, "SELECT trial_index, outcome, tct_s, n_samples FROM trials ORDER BY trial_index")

    # the same command again is refused, naming the way out, and changes nothing
    again = _run_cli(args)
    assert again.returncode == 2 and "--continue" in again.stderr and "Traceback" not in again.stderr
    assert rows(db, "SELECT trial_index, outcome, tct_s, n_samples FROM trials ORDER BY trial_index") == before

    done = _run_cli([*args, "--continue"])
    assert done.returncode == 0, done.stderr
    assert _participant_sessions(db) == [
        ("P01", "training", "completed"), ("P01", "experiment", "completed"),
        ("P02", "training", "completed"), ("P02", "experiment", "completed"),
    ]
    training = rows(db, "SELECT trial_index, outcome, tct_s, n_samples, target_label, haptic_mode FROM trials "
                        "WHERE session_id = ? ORDER BY trial_index", training_sid)
    assert [t[:4] for t in training[: len(before)]] == before  # the practice already done is kept as it was
    practised = sorted((t[4], t[5]) for t in training if t[1] != "aborted")
    assert practised == sorted((t, m) for m in ("on", "off") for t in ("GENTLE", "FIRM"))  # each once, none lost
    assert rows(db, "SELECT COUNT(*) FROM events WHERE session_id = ? AND kind = 'resume'", training_sid) == [(1,)]
    assert "participants" in done.stdout  # the study summary

    # nothing is left: continuing again runs nothing and says so
    idle = _run_cli([*args, "--continue"])
    assert idle.returncode == 0, idle.stderr
    assert "nothing to continue" in idle.stderr
    assert rows(db, "SELECT COUNT(*) FROM sessions") == [(4,)]


def test_continue_refuses_another_seed_or_protocol_and_changes_nothing(tmp_path: Path) -> None:
    db = tmp_path / "s.db"
    proto = short_protocol()
    run_study(str(db), participants=1, seed=2, protocol=proto, jobs=1)
    before = rows(db, "SELECT COUNT(*), SUM(n_samples) FROM trials")
    with pytest.raises(StorageError, match=r"P01's experiment session \d+ in .* was run with --seed 2, not 3"):
        run_study(str(db), participants=2, seed=3, protocol=proto, continue_study=True)
    other = dataclasses.replace(proto, trials_per_cell=2)
    with pytest.raises(StorageError, match="was run with another protocol"):
        run_study(str(db), participants=2, seed=2, protocol=other, continue_study=True)
    assert rows(db, "SELECT COUNT(*), SUM(n_samples) FROM trials") == before
    assert rows(db, "SELECT COUNT(*) FROM sessions") == [(1,)]
    with pytest.raises(StorageError, match="no database at"):
        run_study(str(tmp_path / "missing.db"), participants=1, seed=2, protocol=proto, continue_study=True)
    assert not (tmp_path / "missing.db").exists()


def test_continue_adds_participants_and_keeps_finished_and_aborted_sessions(tmp_path: Path) -> None:
    """A finished study continued with more participants runs only the new ones; an ended session is not re-run."""
    db = tmp_path / "grow.db"
    proto = short_protocol()
    run_study(str(db), participants=1, seed=6, protocol=proto, jobs=1)
    c = sqlite3.connect(db)
    c.execute("UPDATE sessions SET status = 'aborted'")  # as if the experimenter had ended it
    c.commit()
    c.close()
    first = rows(db, "SELECT trial_id, outcome, tct_s FROM trials ORDER BY trial_id")
    progress = run_study(str(db), participants=3, seed=6, protocol=proto, jobs=2, continue_study=True)
    assert _participant_sessions(db) == [
        ("P01", "experiment", "aborted"), ("P02", "experiment", "completed"), ("P03", "experiment", "completed")]
    assert rows(db, "SELECT trial_id, outcome, tct_s FROM trials WHERE session_id = 1 ORDER BY trial_id") == first
    assert progress.study_trials_total == progress.study_trials_done == 2 * proto.trials_per_participant
    # the new participants are exactly who they would have been in one uninterrupted study
    fresh = tmp_path / "fresh.db"
    run_study(str(fresh), participants=3, seed=6, protocol=proto, jobs=1)
    q = ("SELECT p.code, t.trial_index, t.outcome, t.tct_s, t.rmse_n FROM trials t JOIN sessions s USING (session_id) "
         "JOIN participants p USING (participant_id) WHERE p.code != 'P01' ORDER BY p.code, t.trial_index")
    assert rows(db, q) == rows(fresh, q)


def test_resume_continues_an_interrupted_training_session(tmp_path: Path) -> None:
    """resume_session takes the participant's open session whatever its kind: here, practice."""
    db = tmp_path / "t.db"
    proto = _short_training_toml(tmp_path)
    assert _run_killed_in_training(db, proto, 1, 1, 1, 3.0) == -9
    progress = resume_session(str(db), "P01")
    assert progress.kind == "training" and progress.study_trials_done == progress.study_trials_total > 0
    assert _participant_sessions(db) == [("P01", "training", "completed")]
    with pytest.raises(StorageError, match="no interrupted session"):
        resume_session(str(db), "P01")


def test_an_exception_in_a_worker_stops_the_study_with_its_message_and_continue_completes_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A Python exception inside a participant's worker (injected) is reported by name; the study then completes."""
    import multiprocessing

    import protocol.runner.session
    import study_app.headless.pool as pool
    from study_app.headless import StudyWorkerError

    db = tmp_path / "raise.db"
    real_process = protocol.runner.session.SessionRunner.process

    def process_then_fail(self, rows, *args):
        real_process(self, rows, *args)
        if len(rows) and int(rows["t_ns"][-1]) > 3_000_000_000:  # the loop's clock, 3 s in
            raise RuntimeError("injected by the test 3 s into the participant")

    # the workers are forked, so they run the patched runner (spawned ones would import it afresh)
    fork = multiprocessing.get_context("fork")
    monkeypatch.setattr(pool, "worker_context", lambda: fork)
    monkeypatch.setattr(protocol.runner.session.SessionRunner, "process", process_then_fail)
    with pytest.raises(StudyWorkerError) as err:
        run_study(str(db), participants=2, seed=9, protocol=short_protocol(), jobs=2)
    msg = str(err.value)
    assert msg.startswith(("participant P01 failed (RuntimeError: injected by the test 3 s into the participant)",
                           "participant P02 failed (RuntimeError: injected by the test 3 s into the participant)")), msg
    assert msg.endswith("complete the study with the same command and --continue")
    assert multiprocessing.active_children() == []
    # every session stored stays resumable (the other worker may not have opened its own yet on a loaded machine)
    statuses = rows(db, "SELECT status FROM sessions")
    assert statuses and set(statuses) == {("running",)}
    monkeypatch.setattr(protocol.runner.session.SessionRunner, "process", real_process)
    run_study(str(db), participants=2, seed=9, protocol=short_protocol(), jobs=2, continue_study=True)
    assert rows(db, "SELECT status FROM sessions") == [("completed",), ("completed",)]
    for sid in (1, 2):
        done = rows(db, "SELECT target_label, haptic_mode FROM trials WHERE session_id = ? "
                        "AND outcome != 'aborted'", sid)
        assert len(done) == 4 and len(set(done)) == 4  # every cell once
