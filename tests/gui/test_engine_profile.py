"""A GUI session on the simulated rig records the simulated participant's profile in its config, as ``run``'s do
(issue 44: ``participant_profile``, from the participant's group under ``[groups]``)."""

from __future__ import annotations

import json
import sqlite3

from study_app.engine import messages as m
from study_app.engine.host import StudyEngine
from tests.cli_subprocess import TWO_GROUPS
from tests.gui.conftest import SHORT_PROTOCOL
from tests.gui.test_engine_host import engine  # noqa: F401  (the fixture: a simulated engine, virtual clock)

GROUPS = SHORT_PROTOCOL + TWO_GROUPS


def _stop(e: StudyEngine) -> None:
    e.handle(m.AbortSession("test: the record is what is looked at"))
    for _ in range(5_000):
        if e.runner is None:
            return
        e.step()
    raise AssertionError("the session did not stop")


def test_a_gui_session_records_its_simulated_participants_profile(engine, tmp_path) -> None:  # noqa: F811
    e, events = engine
    protocol = tmp_path / "groups.toml"
    protocol.write_text(GROUPS, encoding="utf-8")
    db = str(tmp_path / "s.db")
    for code, number, group in (("P01", 1, "surgeon"), ("P02", 2, "novice")):
        e.handle(m.StartSession(db, code, "experiment", str(protocol), 3, number, covariates={"group": group}))
        assert [ev for ev in events if isinstance(ev, m.CommandRefused)] == []
        _stop(e)
    # a returning participant (the form shows its stored covariates and sends them again)
    e.handle(m.StartSession(db, "P01", "training", str(protocol), 3, 1, covariates={"group": "surgeon"}))
    assert [ev for ev in events if isinstance(ev, m.CommandRefused)] == []
    _stop(e)
    c = sqlite3.connect(db)
    try:
        rows = c.execute("SELECT p.code, s.kind, s.config_json FROM sessions s JOIN participants p USING "
                            "(participant_id) ORDER BY s.session_id").fetchall()
    finally:
        c.close()
    profiles = [(code, kind, json.loads(cfg).get("participant_profile")) for code, kind, cfg in rows]
    assert profiles == [("P01", "experiment", "experienced"), ("P02", "experiment", None),
                        ("P01", "training", "experienced")]
    assert all(json.loads(cfg)["app"] == "gui" for _, _, cfg in rows)
