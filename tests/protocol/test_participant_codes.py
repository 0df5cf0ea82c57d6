"""Participant codes compared as a person reads them (issue 40, item 2): ``p01`` beside ``P01`` is one participant.

One normalisation (:mod:`protocol.storage.codes`: NFKC, stripped, case-folded) is used by the database's uniqueness
check, the GUI's form and every command that takes a code; a near-duplicate of a code already in a study is refused
in one line naming the code it clashes with, and nothing stored is touched.  Databases that already hold both
spellings keep them, each found by its exact spelling.
"""

from __future__ import annotations

import hashlib
import sqlite3
from pathlib import Path

import pytest

from protocol.storage import StorageError, StudyDatabase, code_key, near_duplicate, normalise_code, validate_code
from protocol.study.config import default_protocol
from protocol.study.design import build_schedule, schedule_to_json
from study_app.cli.main import main
from study_app.models.setup import SetupModel


def _args(code: str, kind: str = "training") -> dict:
    p = default_protocol()
    return dict(code=code, kind=kind, seed=7, participant_number=1, protocol_json=p.to_json(),
                schedule_json=schedule_to_json(build_schedule(p, seed=7, participant_number=1)),
                software_version="0.1.0+test", rig="sim", config={}, calibration=None)


@pytest.fixture
def study(tmp_path) -> Path:
    path = tmp_path / "study.db"
    db = StudyDatabase(path)
    try:
        db.create_session(**_args("P01"))
    finally:
        db.close()
    return path


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_one_normalisation_reads_codes_as_a_person_does():
    assert code_key("p01") == code_key(" P01 ") == code_key("Ｐ０１") == "p01"  # full-width: NFKC
    assert normalise_code(" Ｐ０１\t") == "P01" and validate_code(" Ｐ０１ ") == "P01"  # the case is kept
    assert near_duplicate("p01", ["P01", "P02"]) == "P01"
    assert near_duplicate("P01", ["P01", "p01"]) is None  # stored itself: an existing database keeps both
    assert near_duplicate("P03", ["P01"]) is None
    with pytest.raises(StorageError, match="must be 1–32 characters"):
        validate_code("P 01")


def test_the_database_refuses_a_near_duplicate_naming_the_code_and_changes_nothing(study):
    before = _digest(study)
    db = StudyDatabase(study)
    try:
        for typed in ("p01", "Ｐ０１".lower()):
            with pytest.raises(StorageError, match=r"participant code = 'p01': reads as P01, already in .*study\.db"):
                db.create_session(**_args(normalise_code(typed), "experiment"))
        assert [r[0] for r in db.conn.execute("SELECT code FROM participants")] == ["P01"]
        assert db.conn.execute("SELECT count(*) FROM sessions").fetchone()[0] == 1
        db.create_session(**_args("P01", "experiment"))  # the code as stored is that participant
    finally:
        db.close()
    assert before != _digest(study)


def test_a_database_that_already_holds_both_spellings_keeps_them(tmp_path):
    path = tmp_path / "old.db"
    db = StudyDatabase(path)
    db.create_session(**_args("P01"))
    db.close()
    c = sqlite3.connect(path)  # as an older version stored it, before codes were compared so
    c.execute("INSERT INTO participants (code, created_at) VALUES ('p01', '2024-01-01T00:00:00')")
    c.commit()
    c.close()
    db = StudyDatabase(path)
    try:
        db.create_session(**_args("p01"))  # its own exact spelling: found, not a clash
        assert [s.code for s in db.sessions_of("p01")] == ["p01"] and len(db.sessions_of("P01")) == 1
    finally:
        db.close()


@pytest.mark.parametrize("argv", [
    ["withdraw", "--participant", "p01", "--reason", "asked", "--yes", "p01"],
    ["export", "participant", "--participant", "p01", "--out", "{tmp}/out"],
    ["run", "--resume", "p01"],
])
def test_every_command_that_takes_a_code_refuses_a_near_duplicate_in_one_line(study, tmp_path, capsys, argv):
    before = _digest(study)
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    code = main([*argv, "--db", str(study)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert "'p01': reads as P01" in err and "Traceback" not in err
    assert _digest(study) == before  # nothing stored touched


def test_the_gui_form_refuses_p01_beside_p01_naming_it():
    setup = SetupModel()
    setup.update(db_path="", code="p01", kind="training")
    setup.set_known([{"session_id": 1, "code": "P01", "participant_number": 1, "kind": "training",
                      "status": "completed", "seed": 0}])
    assert not setup.valid
    assert "reads as P01" in setup.errors["code"] and "'p01'" in setup.errors["code"]
    setup.update(code=" Ｐ０１ ", kind="experiment")  # pasted full-width, with spaces: the code as stored
    assert setup.values.code == "P01" and "reads as" not in setup.errors.get("code", "")
