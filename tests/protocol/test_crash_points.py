"""A crash at every storage call of a session, then ``--continue``: every designed trial once, nothing completed early.

The session (a tiny protocol: two trials, one aborted by a sensor fault and
re-run) is killed with SIGKILL just before each of its commits in turn
(``HAPTIC_STUDY_CRASH_AT=commit:N``, :mod:`protocol.storage.crashpoint`): those
are all the states a crash can leave the file in.  A few kills fall between the
statements of the aborted trial's transaction as well.  At each kill the file
must be consistent as a reader sees it (an aborted trial always has its re-run in
the stored schedule; a session marked completed has every cell full), and after
``run --continue`` the study must be complete with every designed trial present
exactly once and everything the reader saw at the kill unchanged.

The runs are children of a fork server that has imported the product once, two
at a time; the commit count is deterministic because a run on the virtual clock
commits on its records' own time.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import sqlite3
import tomllib
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest
from test_storage import FakeClock, _session_args

from protocol.runner.rehearsal import parse_fault_plan
from protocol.storage import crashpoint
from protocol.storage.crashpoint import CRASH_ENV
from protocol.storage.database import StudyDatabase
from protocol.study.config import ProtocolConfig, protocol_from_dict
from protocol.study.design import build_schedule, schedule_from_json
from study_app.headless import run_study

#: Two designed trials (one per mode), no training; short trials and pauses keep the commits few.
PROTOCOL = """name = "crash points"
[[targets]]
label = "GENTLE"
force_n = 0.6
[design]
modes = ["on", "off"]
trials_per_cell = 1
[trial]
max_trial_s = 0.9
hold_s = 0.3
pause_s = 0.2
[training]
enabled = false
"""
SEED = 1
#: Trial 1 is aborted by a sensor stall and re-run at the end: the state change under test.
FAULT = "sensor-stall@P01:1+0.5"


def _protocol() -> ProtocolConfig:
    return protocol_from_dict(tomllib.loads(PROTOCOL), "crash-points protocol")


def _run(db: str, crash_at: str, cont: bool) -> None:
    """A child process: the study (with its fault) or its --continue, crashing where planned."""
    if crash_at:
        os.environ[CRASH_ENV] = crash_at
    else:
        os.environ.pop(CRASH_ENV, None)
    protocol = _protocol()
    faults = [] if cont else [parse_fault_plan(FAULT)]
    run_study(db, participants=1, seed=SEED, protocol=protocol, jobs=1, continue_study=cont, faults=faults)


def _child(ctx: Any, db: Path, crash_at: str, cont: bool) -> int | None:
    p = ctx.Process(target=_run, args=(str(db), crash_at, cont))
    p.start()
    p.join(300)
    return p.exitcode


def _view(db: Path) -> dict[str, list[tuple[Any, ...]]] | None:
    """What a reader of the file sees (None: no study in it yet)."""
    if not db.exists() or db.stat().st_size == 0:
        return None
    c = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        if c.execute("SELECT COUNT(*) FROM sqlite_master WHERE name = 'sessions'").fetchone()[0] == 0:
            return None
        q = {
            "sessions": "SELECT session_id, kind, status, schedule_json FROM sessions ORDER BY session_id",
            "trials": "SELECT * FROM trials ORDER BY trial_id",
            "events": "SELECT rowid, * FROM events ORDER BY rowid",
            "recordings": "SELECT * FROM recordings ORDER BY session_id, segment",
            "blocks": "SELECT session_id, segment, block, n_records, data, crc32 FROM session_blocks "
                      "ORDER BY session_id, segment, block",
        }
        return {k: c.execute(sql).fetchall() for k, sql in q.items()}
    finally:
        c.close()


def _problems(view: dict[str, list[tuple[Any, ...]]], finished: bool) -> list[str]:
    """What is wrong with the study as a reader sees it ([] when consistent)."""
    protocol = _protocol()
    designed = [(s.target_label, s.haptic_mode) for s in build_schedule(protocol, SEED, 1)]
    out: list[str] = []
    sessions = view["sessions"]
    if finished and [(s[1], s[2]) for s in sessions] != [("experiment", "completed")]:
        out.append(f"sessions after --continue: {[(s[1], s[2]) for s in sessions]}")
    for sid, _, status, schedule_json in sessions:
        schedule = schedule_from_json(schedule_json)
        rows = [t for t in view["trials"] if t[1] == sid]
        idx = [t[2] for t in rows]
        outcome = {t[2]: t[6] for t in rows}
        if idx != list(range(len(idx))) or len(idx) > len(schedule):
            out.append(f"session {sid}: trial rows {idx} are not a prefix of its {len(schedule)}-trial schedule")
        if [(s.target_label, s.haptic_mode) for s in schedule if s.repeat_of is None] != designed:
            out.append(f"session {sid}: the schedule's designed trials changed")
        reruns = Counter(s.repeat_of for s in schedule if s.repeat_of is not None)
        for i, o in outcome.items():
            if (o == "aborted") != (reruns[i] == 1) or reruns[i] > 1:
                out.append(f"session {sid}: trial index {i} ({o}) has {reruns[i]} re-runs in the stored schedule")
        done = Counter((schedule[i].target_label, schedule[i].haptic_mode) for i, o in outcome.items()
                       if o != "aborted" and i < len(schedule))
        if any(n > protocol.trials_per_cell for n in done.values()):
            out.append(f"session {sid}: a cell holds more than its trials: {dict(done)}")
        if status == "completed" and (len(idx) != len(schedule) or
                                      any(done[c] != protocol.trials_per_cell for c in set(designed))):
            out.append(f"session {sid} is marked completed with {len(idx)}/{len(schedule)} trials, cells {dict(done)}")
    return out


def _unchanged(before: dict[str, list[tuple[Any, ...]]], after: dict[str, list[tuple[Any, ...]]]) -> list[str]:
    """Rows a reader saw at the crash that the resume changed or dropped (sessions may end and grow a schedule)."""
    out = []
    for table in ("trials", "events", "recordings", "blocks"):
        missing = set(before[table]) - set(after[table])
        if missing:
            out.append(f"{table}: {len(missing)} row(s) seen at the crash changed or gone, e.g. {min(missing)[:4]}")
    for (sid, _, _, sched), (sid2, _, _, sched2) in zip(before["sessions"], after["sessions"], strict=False):
        old, new = schedule_from_json(sched), schedule_from_json(sched2)
        if sid != sid2 or new[: len(old)] != old:
            out.append(f"session {sid}: the stored schedule was rewritten, not extended")
    return out


def _case(ctx: Any, folder: Path, crash_at: str, expect_killed: bool) -> list[str]:
    folder.mkdir()
    db = folder / "study.db"
    code = _child(ctx, db, crash_at, cont=False)
    if code != (-9 if expect_killed else 0):
        return [f"{crash_at}: the crashing run ended with {code}"]
    seen = _view(db)
    problems = [] if seen is None else [f"{crash_at}, at the crash: {p}" for p in _problems(seen, finished=False)]
    code = _child(ctx, db, "", cont=True)
    if code != 0:
        return [*problems, f"{crash_at}: --continue ended with {code}"]
    after = _view(db)
    assert after is not None
    problems += [f"{crash_at}, after --continue: {p}" for p in _problems(after, finished=True)]
    if seen is not None:
        problems += [f"{crash_at}, after --continue: {p}" for p in _unchanged(seen, after)]
    return problems


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> tuple[int, list[int]]:
    """The uncrashed run, counted: its commits, and the statements at which trial rows were inserted."""
    db = tmp_path_factory.mktemp("reference") / "study.db"
    inserts: list[int] = []
    original = StudyDatabase.insert_trial

    def counting(self: StudyDatabase, row: Any) -> None:
        inserts.append(crashpoint.statements_seen() + 1)  # the INSERT is the next statement
        original(self, row)

    mp_env = os.environ.get(CRASH_ENV)
    os.environ[CRASH_ENV] = "commit:0"
    StudyDatabase.insert_trial = counting
    try:
        c0, s0 = crashpoint.commits_seen(), crashpoint.statements_seen()
        _run(str(db), "commit:0", cont=False)
        commits = crashpoint.commits_seen() - c0
        inserts = [i - s0 for i in inserts]
    finally:
        StudyDatabase.insert_trial = original
        if mp_env is None:
            os.environ.pop(CRASH_ENV, None)
        else:
            os.environ[CRASH_ENV] = mp_env
    view = _view(db)
    assert view is not None and _problems(view, finished=True) == []
    outcomes = [t[6] for t in view["trials"]]
    assert outcomes[0] == "aborted" and len(outcomes) == 3  # aborted, then trial 2, then trial 1's re-run
    return commits, inserts


def test_a_crash_at_any_commit_or_inside_the_abort_transaction_loses_and_duplicates_no_trial(
        reference: tuple[int, list[int]], tmp_path: Path) -> None:
    commits, inserts = reference
    assert 8 < commits < 200, commits
    # every commit in turn, and one past the last (the run completes); and inside the aborted trial's transaction:
    # before its row, before the schedule with its re-run, before the open block's write (then its COMMIT)
    cases = [(f"commit:{n}", n <= commits) for n in range(1, commits + 2)]
    cases += [(f"statement:{n}", True) for n in (inserts[0], inserts[0] + 2, inserts[0] + 3)]
    # spawn, not forkserver: a forkserver child's exit status comes back through the server over a pipe, and with two
    # cases starting children at once that report was lost now and then (exit code 255, "not reported"); a spawned
    # child is this process's own, its status read by waitpid
    ctx = mp.get_context("spawn")
    with ThreadPoolExecutor(max_workers=2) as pool:
        found = list(pool.map(lambda c: _case(ctx, tmp_path / c[0].replace(":", "-"), *c), cases))
    problems = [p for f in found for p in f]
    assert problems == [], f"{len(problems)} problem(s) in {len(cases)} crashes:\n" + "\n".join(problems[:20])


def test_the_crash_point_is_refused_when_misspelt(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from protocol.storage import StorageError

    monkeypatch.setenv(CRASH_ENV, "commit=3")
    with pytest.raises(StorageError, match="expected commit:N or statement:N"):
        StudyDatabase(tmp_path / "x.db")
    assert list(tmp_path.iterdir()) == []  # refused before the file was made


def test_what_is_queued_in_one_atomic_block_is_one_commit_whatever_the_deadline(tmp_path: Path) -> None:
    from protocol.storage import Recorder
    from protocol.study.clock import SessionClock
    from protocol.study.records import TrialRecord

    path = tmp_path / "s.db"
    db = StudyDatabase(path)
    sid = db.create_session(**_session_args())
    clock = FakeClock()
    rec = Recorder(db, threaded=False, clock=clock)
    trial = TrialRecord(session_id=sid, trial_index=0, target_label="FIRM", target_force_n=1.2, haptic_mode="off",
                        outcome="aborted", clock=SessionClock(0.0, 0), cue_ns=0, end_ns=5)

    def seen() -> tuple[int, str]:
        c = sqlite3.connect(path)
        try:
            n = c.execute("SELECT COUNT(*) FROM trials").fetchone()[0]
            return n, c.execute("SELECT schedule_json FROM sessions").fetchone()[0]
        finally:
            c.close()

    before = seen()
    with pytest.raises(RuntimeError), rec.atomic():
        rec.trial(trial)
        raise RuntimeError("the runner failed half-way")
    clock.now = 1.0
    rec.event(sid, 0.1, "x")  # past the deadline: commits what is pending
    assert seen() == before  # the half-done state change was not stored
    with rec.atomic():
        rec.trial(trial)
        clock.now = 5.0  # the deadline passes in the middle ...
        rec.event(sid, 0.2, "y")
        assert seen() == before  # ... and nothing is committed before the block ends
        with rec.atomic():  # nested: the outer block commits
            rec.call(lambda d: d.update_schedule(sid, "[]"))
        assert seen() == before
    assert seen() == (1, "[]")
    rec.close()
    db.close()
