"""A session with a person's questionnaires, the experimenter's notes and a described participant, end to end.

One experiment session (blocked by mode: an ON block and an OFF block of two trials each; a weighted NASA-TLX
after each block and two Likert items after the session) runs on the simulated rig on the virtual clock, with
the questionnaires answered as a person answers them: the runner shows the prompt and waits; the answers come
two seconds later.  What must hold: no cue while a questionnaire waits, the next one the protocol's pause after
the answers; answers that do not fit are ignored (an event says why) and the prompt still waits; each sheet's
answers and their event are stored together; a note during a trial is stored on the session clock within that
trial; a note added afterwards (``haptic-study note``) appends without altering a row; the covariates given at
registration are stored, a second registration with other values is refused; and a withdrawal leaves none of it
in the file, while ``export participant`` of another participant writes theirs.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import sqlite3
from pathlib import Path

import pytest

from pipeline.force.config import FrameworkConfig
from pipeline.sim.participant import SimulatedParticipant
from protocol.runner.session_driver import SessionDriver
from protocol.runner.session_setup import delivery_limits, finish_session, open_new_session, start_runner
from protocol.storage import StorageError, StudyDatabase, new_owner_token
from protocol.storage.annotations import answers, covariates_by_code, notes
from protocol.study.config import load_protocol
from protocol.study.covariates import CovariateError
from protocol.study.questionnaires import Prompt
from protocol.study.sim_answers import simulated_answers
from study_app.cli.main import main
from study_app.headless import session_run

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "surgeons.toml"
PAUSE_S = 1.0
ANSWER_AFTER_TICKS = 2000  # the person answers 2 s after the prompt


def _protocol():
    p = load_protocol(EXAMPLE)
    return dataclasses.replace(p, targets=p.targets[:1], trials_per_cell=2, ordering="blocked_by_mode",
                               trial=dataclasses.replace(p.trial, max_trial_s=4.0, pause_s=PAUSE_S),
                               training=dataclasses.replace(p.training, enabled=False, required=False))


def _run(db: StudyDatabase, code: str, number: int, covariates: dict[str, str]) -> dict:
    """One experiment session, the questionnaires answered by a 'person' (the first sheet first off its scale)."""
    protocol = _protocol()
    eng = session_run._engine(100 + number, "virtual", ("right",), FrameworkConfig())
    opened = open_new_session(db, code=code, number=number, kind="experiment", protocol=protocol, seed=0, rig="sim",
                              config={}, calibration=None, lease_owner=new_owner_token(), covariates=covariates)
    participant = SimulatedParticipant(seed=opened.participant_seed)
    eng.rig.set_driver(participant)
    recorder, runner = start_runner(db, opened, submit=eng.loop.submit, participant=participant,
                                    participant_time=lambda: eng.rig.sim_time_s, limits=delivery_limits(eng.loop),
                                    auto_reset_faults=True, threaded=False)  # a person answers: not simulated
    driver = SessionDriver(eng.ring, eng.loop.replay_log, ())
    eng.loop.on_event = driver.on_loop_event
    prompts: list[tuple[Prompt, int]] = []
    runner.listeners.append(lambda ev: prompts.append((ev[1], eng.loop.clock.now_ns()))
                            if isinstance(ev, tuple) and ev[0] == "questionnaire" else None)
    waited, noted, bad_sent = 0, None, False
    try:
        while not runner.done:
            eng.loop.run_ticks(session_run.BLOCK_TICKS)
            driver.feed(runner)
            spec = runner.running_trial
            if noted is None and spec is not None and spec.index == 1 and runner.state.phase == "active":
                runner.note(f"{code} looked away from the screen", trial_index=1, deviation=True)
                noted = spec.index
            if runner.questions.asked is not None:
                assert runner.running_trial is None  # no cue while a questionnaire waits
                waited += session_run.BLOCK_TICKS
                if waited >= ANSWER_AFTER_TICKS:
                    prompt = runner.questions.asked
                    sheet = simulated_answers(prompt, 7)
                    if not bad_sent:  # a sheet off its scale first: ignored, the prompt still waits
                        first = next(iter(sheet))
                        runner.answer(*prompt.key, {**sheet, first: 42.5})
                        bad_sent = True
                    else:
                        runner.answer(*prompt.key, sheet)
                        waited = 0
    finally:
        eng.loop.ramp_down()
        eng.rig.close()
        finish_session(db, recorder, opened)
    return {"session_id": opened.session_id, "prompts": prompts, "status": runner.status}


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> dict:
    folder = tmp_path_factory.mktemp("annotations")
    path = folder / "study.db"
    db = StudyDatabase(path)
    try:
        with pytest.raises(CovariateError, match="covariate group = 'expert': must be one of novice, resident"):
            open_new_session(db, code="P01", number=1, kind="experiment", protocol=_protocol(), seed=0, rig="sim",
                             config={}, calibration=None, lease_owner=new_owner_token(), covariates={"group": "expert"})
        assert db.conn.execute("SELECT COUNT(*) FROM participants").fetchone() == (0,)  # nothing stored
        first = _run(db, "P01", 1, {"group": "surgeon", "years_experience": "14", "age_band": "40-49"})
        second = _run(db, "P02", 2, {"group": "novice"})
    finally:
        db.close()
    return {"path": path, "folder": folder, "first": first, "second": second}


def _rows(path: Path, sql: str, *args: object) -> list[tuple]:
    c = sqlite3.connect(path)
    try:
        return c.execute(sql, args).fetchall()
    finally:
        c.close()


def test_each_block_and_the_session_get_their_sheet_and_no_cue_comes_while_one_waits(study) -> None:
    path, sid = study["path"], study["first"]["session_id"]
    assert study["first"]["status"] == "completed"
    keys = [p.key for p, _ in study["first"]["prompts"]]
    assert keys == [("workload", keys[0][1]), ("workload", keys[1][1]), ("experience", "session")]
    assert {keys[0][1], keys[1][1]} == {"on", "off"}
    c = sqlite3.connect(path)
    try:
        got = answers(c, [sid])
        trials = c.execute("SELECT trial_index, haptic_mode, started_at_s, ended_at_s FROM trials WHERE "
                           "session_id = ? ORDER BY trial_index", (sid,)).fetchall()
        events = c.execute("SELECT t_s, detail FROM events WHERE session_id = ? AND kind = 'questionnaire' "
                           "ORDER BY rowid", (sid,)).fetchall()
    finally:
        c.close()
    by_key: dict[tuple[str, str], list] = {}
    for a in got:
        by_key.setdefault((a.questionnaire, a.block), []).append(a)
    assert {k: len(v) for k, v in by_key.items()} == {("workload", "on"): 21, ("workload", "off"): 21,
                                                      ("experience", "session"): 2}
    first_block = by_key[("workload", trials[0][1])]
    answered_s = first_block[0].answered_at_s
    assert all(a.answered_at_s == answered_s for a in first_block)  # one sheet, one moment
    # the block's last trial ended, the prompt waited ~2 s for the person, the next cue came a pause after the answer
    assert answered_s - trials[1][3] >= 2.0 - 0.2  # (the pause before the prompt, then the 2 s wait)
    assert trials[2][2] - answered_s == pytest.approx(PAUSE_S, abs=0.06)  # within one block of 50 ticks
    words = [d for _, d in events]
    assert words[0].endswith(": shown on the participant screen")
    assert "answers ignored: questionnaire workload: mental = 42.5: must be 0 to 100 in steps of 5" in words[1]
    assert words[2].endswith(": answered by the participant")


def test_a_note_during_a_trial_is_on_the_session_clock_within_it_and_one_afterwards_appends(study) -> None:
    path, sid = study["path"], study["first"]["session_id"]
    c = sqlite3.connect(path)
    try:
        (live,) = notes(c, [sid])
        start, end = c.execute("SELECT started_at_s, ended_at_s FROM trials WHERE session_id = ? AND trial_index = 1",
                               (sid,)).fetchone()
        before = c.execute("SELECT * FROM trials ORDER BY trial_id").fetchall()
    finally:
        c.close()
    assert (live.trial_index, live.deviation, live.text) == (1, True, "P01 looked away from the screen")
    assert live.t_s is not None and start <= live.t_s <= end
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["note", "--db", str(path), "--session", str(sid), "--trial", "3", "the tissue pad slipped"]) == 0
    assert "Noted on session" in out.getvalue()
    c = sqlite3.connect(path)
    try:
        later = notes(c, [sid])
        assert c.execute("SELECT * FROM trials ORDER BY trial_id").fetchall() == before  # nothing altered
    finally:
        c.close()
    assert later[0] == live and (later[1].t_s, later[1].trial_index, later[1].deviation) == (None, 2, False)


def test_covariates_are_stored_typed_with_the_participant_and_never_changed(study) -> None:
    c = sqlite3.connect(study["path"])
    try:
        assert covariates_by_code(c) == {"P01": {"group": "surgeon", "years_experience": 14, "age_band": "40-49"},
                                         "P02": {"group": "novice"}}
    finally:
        c.close()
    db = StudyDatabase(study["path"])
    try:
        with pytest.raises(StorageError, match="covariate group = 'novice': participant P01's group was recorded as "
                                               "'surgeon' when they were registered"):
            open_new_session(db, code="P01", number=1, kind="training", protocol=_protocol(), seed=0, rig="sim",
                             config={}, calibration=None, lease_owner=new_owner_token(), covariates={"group": "novice"})
    finally:
        db.close()
    assert _rows(study["path"], "SELECT COUNT(*) FROM sessions") == [(2,)]


def test_export_writes_them_and_a_withdrawal_leaves_none_of_them_in_the_file(study) -> None:
    path, folder = study["path"], study["folder"]
    out = folder / "export"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["export", "participant", "--db", str(path), "--participant", "P01", "--out", str(out)]) == 0
    assert "surgeon" in (out / "covariates.csv").read_text(encoding="utf-8")
    assert "P01 looked away" in (out / "notes.csv").read_text(encoding="utf-8")
    assert (out / "answers.csv").read_text(encoding="utf-8").count("\n") == 1 + 21 * 2 + 2
    codebook = (out / "codebook.csv").read_text(encoding="utf-8")
    assert all(f"answers.csv,{col}," in codebook for col in ("questionnaire", "block", "item", "rating", "choice"))
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["withdraw", "--db", str(path), "--participant", "P01", "--reason", "withdrew consent",
                     "--yes", "P01"]) == 0
    sid = study["first"]["session_id"]
    for table, where in (("notes", "session_id"), ("questionnaire_answers", "session_id")):
        assert _rows(path, f"SELECT COUNT(*) FROM {table} WHERE {where} = ?", sid) == [(0,)]
    assert _rows(path, "SELECT COUNT(*) FROM covariates") == [(1,)]  # P02's only
    data = path.read_bytes() + (Path(f"{path}-wal").read_bytes() if Path(f"{path}-wal").exists() else b"")
    # a covariate row's text values lie side by side in its record (the protocol's levels are in every stored
    # protocol: the row, not the word, is what must go)
    for gone in (b"groupcategorysurgeon", b"age_bandcategory40-49", b"years_experienceinteger14",
                 b"P01 looked away", b"the tissue pad slipped"):
        assert gone not in data
    assert b"groupcategorynovice" in data  # the search finds what is still there
