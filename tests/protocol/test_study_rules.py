"""The study's rules across sessions (protocol.runner.study_rules): one seed per study, training before the
experiment -- one definition, applied where sessions are stored (the GUI's engine and ``run`` alike) and by
``run``'s plan."""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path

import pytest

from protocol.runner.session_setup import open_new_session
from protocol.runner.study_rules import (
    DEVIATION_EVENT,
    TRAINING_SKIPPED,
    StoredSession,
    StudyRuleError,
    check_new_session,
    next_kind,
    requires_training,
    seed_refusal,
    stored_sessions,
    training_refusal,
)
from protocol.storage import StudyDatabase, new_owner_token, session_scope
from protocol.study.config import ProtocolError, default_protocol, protocol_from_dict
from study_app.cli.main import main

PAPER = default_protocol()
NO_TRAINING = dataclasses.replace(PAPER, training=dataclasses.replace(PAPER.training, enabled=False))


def s(sid: int, code: str, kind: str, status: str = "completed", seed: int = 0) -> StoredSession:
    return StoredSession(sid, code, kind, status, seed)


def test_the_protocol_field_defaults_to_training_enabled_and_cannot_require_what_is_not_there():
    assert PAPER.training.required and requires_training(PAPER)
    d = PAPER.to_dict()
    assert d["training"]["required"] is True  # stored with every session: the report says which was used
    del d["training"]["required"]  # a protocol stored before the field existed
    assert protocol_from_dict(d).training.required
    d["training"]["enabled"] = False
    assert not protocol_from_dict(d).training.required  # no training block: nothing to require
    assert not NO_TRAINING.training.required and not requires_training(NO_TRAINING)
    d["training"].update(enabled=True, required=False)
    assert not requires_training(protocol_from_dict(d))  # training offered, not required
    d["training"].update(enabled=False, required=True)
    with pytest.raises(ProtocolError, match=r"^protocol: training.required = true: must be false when "
                                            r"training.enabled = false"):
        protocol_from_dict(d)


def test_seed_training_and_next_step_rules():
    study = [s(1, "P01", "training", seed=3), s(2, "P01", "experiment", seed=3), s(3, "P02", "training", "running", 3),
             s(4, "P03", "training", "aborted", 3)]
    assert seed_refusal([], 9) == "" and seed_refusal(study, 3) == ""
    assert seed_refusal(study, 9) == (
        "seed = 9: this study's seed is 3, fixed by its first session (session 1, P01); every session of a study uses "
        "it, so its schedules can be reproduced: use seed 3, or a new database for a new study")
    assert training_refusal(study, "P01", PAPER) == ""
    assert training_refusal(study, "P02", PAPER).startswith("P02's training (session 3) was interrupted")
    assert training_refusal(study, "P03", PAPER).startswith("P03's training (session 4) ended aborted, not completed")
    assert training_refusal(study, "P04", PAPER) == (
        "P04 has no training session; the protocol requires a completed one before the experiment (training.required)")
    assert training_refusal(study, "P04", NO_TRAINING) == ""
    assert [next_kind(study, c, PAPER) for c in ("P01", "P02", "P03", "P04")] == [
        "experiment", "training", "experiment", "training"]
    assert next_kind(study, "P04", NO_TRAINING) == "experiment"
    # the seed is never overridable; a missing training only with a reason (whitespace is no reason)
    with pytest.raises(StudyRuleError, match="this study's seed is 3"):
        check_new_session(study, code="P04", kind="training", seed=4, protocol=PAPER, training_override="because")
    with pytest.raises(StudyRuleError, match=r"^P04 has no training session"):
        check_new_session(study, code="P04", kind="experiment", seed=3, protocol=PAPER, training_override="  \n ")
    detail = check_new_session(study, code="P04", kind="experiment", seed=3, protocol=PAPER,
                               training_override="  trained\nin the pilot ")
    assert detail.startswith(f"{TRAINING_SKIPPED}: P04's experiment started without a completed training session")
    assert detail.endswith("Reason given: trained in the pilot")
    assert check_new_session(study, code="P01", kind="experiment", seed=3, protocol=PAPER) == ""


def _open(db: StudyDatabase, code: str, kind: str, seed: int, override: str = "") -> int:
    owner = new_owner_token()
    number = int(code[1:]) if code[1:].isdigit() else 99
    opened = open_new_session(db, code=code, number=number, kind=kind, protocol=PAPER, seed=seed, rig="sim",
                              config={}, calibration=None, lease_owner=owner, training_override=override)
    db.release_lease(session_scope(opened.session_id), owner)
    return opened.session_id


def test_where_sessions_are_stored_the_rules_refuse_or_store_the_deviation(tmp_path: Path):
    db = StudyDatabase(tmp_path / "study.db")
    try:
        with pytest.raises(StudyRuleError, match=r"^P01 has no training session"):
            _open(db, "P01", "experiment", 2)
        assert stored_sessions(db) == []  # refused before anything was stored
        sid = _open(db, "P01", "experiment", 2, override="trained on the rig in the pilot")
        (_, detail), = db.conn.execute("SELECT kind, detail FROM events WHERE session_id = ? AND kind = ?",
                                          (sid, DEVIATION_EVENT)).fetchall()
        assert detail.startswith("training skipped: P01's experiment started without") and "pilot" in detail
        with pytest.raises(StudyRuleError, match="this study's seed is 2"):
            _open(db, "P02", "training", 7)
        t = _open(db, "P02", "training", 2)
        db.end_session(t, "completed")
        e = _open(db, "P02", "experiment", 2)  # trained: no deviation stored
        assert db.conn.execute("SELECT COUNT(*) FROM events WHERE session_id = ? AND kind = ?",
                               (e, DEVIATION_EVENT)).fetchone() == (0,)
    finally:
        db.close()


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_run_refuses_another_seed_and_an_untrained_experiment_in_one_line_touching_nothing(tmp_path: Path, capsys):
    db_path = tmp_path / "study.db"
    db = StudyDatabase(db_path)
    try:
        _open(db, "ALICE", "training", 4)  # a session the GUI stored, seed 4
    finally:
        db.close()
    before = _digest(db_path)
    assert main(["run", "--participants", "2", "--seed", "5", "--db", str(db_path)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "seed = 5: this study's seed is 4, fixed by its first session (session 1, ALICE)" in err[0]
    assert _digest(db_path) == before
    db = StudyDatabase(db_path)
    try:
        t = _open(db, "P01", "training", 4)
        db.end_session(t, "aborted", "the participant felt unwell")
    finally:
        db.close()
    before = _digest(db_path)
    # --continue would start P01's experiment after a training that did not complete: refused before writing
    assert main(["run", "--participants", "1", "--seed", "4", "--db", str(db_path), "--continue"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "cannot continue: P01's training (session 2) ended aborted, not completed" in err[0]
    assert _digest(db_path) == before
