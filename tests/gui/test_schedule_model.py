"""The schedule of visits as the setup form holds it (no window): a returning participant's visits, their states and
dates from a first visit days ago, the next (visit, part) proposed, the rule ``run --visit`` applies (a visit outside
its window needs a reason, stored as its deviation), and the engine's own check of it on the database."""

from __future__ import annotations

import datetime as _dt

import pytest
from schedule_study import VISITS, first_visit_days_ago

from protocol.runner.study_rules import StoredSession, StudyRuleError, stored_sessions
from protocol.runner.visit_schedule import VisitState
from protocol.storage import StudyDatabase, StudyReader
from protocol.study.config import load_protocol
from study_app.engine import messages as m
from study_app.engine.session_list import list_sessions
from study_app.engine.sessions import part_to_run
from study_app.engine.visit_start import check_visit_start
from study_app.models.schedule import VisitRow
from study_app.models.setup import SetupModel


@pytest.fixture
def proto(tmp_path):
    p = tmp_path / "visits.toml"
    p.write_text(VISITS, encoding="utf-8")
    return p


def _form(tmp_path, proto, code: str = "P01") -> SetupModel:
    setup = SetupModel()
    db = tmp_path / "study.db"
    setup.update(db_path=str(db), protocol_path=str(proto))
    setup.set_known(list_sessions(db))
    setup.update(code=code)
    return setup


def day(days_ago: int) -> _dt.date:
    return _dt.date.today() - _dt.timedelta(days=days_ago)



def test_a_new_participant_starts_with_the_first_visit(tmp_path, proto) -> None:
    setup = _form(tmp_path, proto)
    v = setup.values
    assert (v.visit, v.part, v.kind) == ("baseline", "practice", "training")
    assert setup.next_step() == "P01: no visit yet: the first is due today; 0 of 3 visits done; next: baseline — " \
                                "practice (due today)"
    assert [r.text() for r in setup.schedule.rows()][1] == "• 2. post, day 7 ± 1: not yet — test to do"
    assert not setup.errors and not setup.schedule.refusal
    # the first visit, held today: its day stored with it, no deviation
    assert setup.start_command().events == (("visit", "baseline (visit 1): held on study day 0, planned day 0 ± 0 "
                                                      "(started in the GUI)"),)


def test_a_returning_participant_is_due_for_the_post_test(tmp_path, proto, monkeypatch) -> None:
    first_visit_days_ago(monkeypatch, tmp_path / "study.db", proto, days=8)
    setup = _form(tmp_path, proto)
    assert (setup.values.visit, setup.values.part, setup.values.kind) == ("post", "test", "experiment")
    sched = setup.schedule.schedule
    assert sched is not None and sched.first == day(8)  # the local date of the first stored session
    assert [(v.name, v.state, v.earliest, v.latest) for v in sched.visits] == [
        ("baseline", "done", day(8), day(8)), ("post", "due", day(2), day(0)), ("retention", "not yet", day(-19),
                                                                                 day(-25))]
    rows = [r.text() for r in setup.schedule.rows()]
    assert rows[0].startswith("✓ 1. baseline, day 0 (") and rows[0].endswith("): done — practice done, test done")
    assert rows[1].startswith("▶ 2. post, day 7 ± 1 (") and rows[1].endswith("): due today — test to do")
    assert rows[2].startswith("• 3. retention, day 30 ± 3 (") and rows[2].endswith("): not yet — test to do")
    assert setup.next_step().endswith(", today study day 8; 1 of 3 visits done; next: post — test (due today)")
    assert not setup.errors and not setup.schedule.refusal
    # the retention visit chosen now: too early, and the form says why before Start
    setup.update(visit="retention")
    assert setup.values.part == "test"
    assert setup.schedule.refusal == "visit 'retention' is out of order: the earlier visit 'post' is not done"
    # a baseline part again: the database keeps one session per visit and part
    setup.update(visit="baseline", part="test")
    assert "already has a completed experiment session" in setup.errors["code"]


def test_an_overdue_visit_needs_the_reason_stored_as_its_deviation(tmp_path, proto, monkeypatch) -> None:
    db = tmp_path / "study.db"
    first_visit_days_ago(monkeypatch, db, proto, days=12)
    setup = _form(tmp_path, proto)
    assert setup.values.visit == "post"
    post = setup.schedule.rows()[1].text()
    assert post.startswith("▶ 2. post, day 7 ± 1 (") and post.endswith("): overdue — test to do")
    why = "visit 'post' is outside its window: held on study day 12, planned for day 7 ± 1"
    assert setup.schedule.refusal == why
    with pytest.raises(StudyRuleError, match="outside its window"):
        setup.start_command()
    cmd = setup.start_command(visit_reason="  participant was ill last week ")
    assert cmd.events[1] == ("deviation", f"{why}: participant was ill last week")
    # the engine checks the same rule on the database: without the deviation it refuses, nothing stored
    study = load_protocol(proto)
    store = StudyDatabase(db, readonly=True)
    try:
        sessions, infos = stored_sessions(store), StudyReader.over(store).sessions()
    finally:
        store.close()
    check_visit_start(cmd, study, sessions, infos)
    bare = m.StartSession(cmd.db_path, "P01", "experiment", cmd.protocol_path, 0, 1, part="test", visit="post",
                          events=cmd.events[:1])
    with pytest.raises(StudyRuleError, match="cannot run P01's visit 'post' is outside its window"):
        check_visit_start(bare, study, sessions, infos)
    with pytest.raises(ValueError, match="stores the study day it is held on"):
        check_visit_start(m.StartSession(cmd.db_path, "P01", "experiment", None, 0, 1, part="test", visit="post"),
                          study, sessions, infos)
    part = part_to_run(cmd, study)
    assert part.part is not None and part.part.visit is not None and part.part.visit.name == "post"


def test_an_interrupted_part_of_a_visit_is_resumed_not_run_again(tmp_path, proto) -> None:
    today = _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")
    known = [{"session_id": 1, "code": "P01", "participant_number": 1, "kind": "training", "status": "running",
              "seed": 0, "started_at": today, "part": "practice", "visit": "baseline", "writer": ""}]
    setup = _form(tmp_path, proto)
    setup.set_known(known)
    assert setup.schedule.rows()[0].text().endswith("due today — practice interrupted (resume it), test to do")
    assert "interrupted training session (session 1" in setup.errors["code"]
    assert StoredSession.of(known[0]).visit == "baseline"
    assert setup.describe_resumable({**known[0], "trials_planned": 2}).startswith(
        "session 1: P01 training (visit baseline, part practice)")


def test_a_study_without_visits_has_no_schedule(tmp_path) -> None:
    from conftest import SHORT_PROTOCOL

    p = tmp_path / "p.toml"
    p.write_text(SHORT_PROTOCOL, encoding="utf-8")
    setup = _form(tmp_path, p)
    assert setup.schedule.schedule is None and setup.values.visit == ""
    assert setup.start_command().events == ()
    with pytest.raises(ValueError, match="the protocol has no \\[\\[visits\\]\\]"):
        check_visit_start(m.StartSession("x.db", "P01", "experiment", None, 0, 1, visit="post"),
                          load_protocol(p), [], [])


def test_a_visit_reads_short_in_the_forms_column() -> None:
    def row(lo, hi, state="due", proposed="test") -> str:
        v = VisitState("post", 2, 7, 1, "post", state, lo, hi, (("test", "to do"), ("extra", "interrupted")))
        return VisitRow(v, proposed).text(_dt.date(2026, 12, 6))

    d = _dt.date
    tail = "due today — test to do, extra interrupted (resume it)"
    assert row(d(2026, 12, 4), d(2026, 12, 6)) == f"▶ 2. post, day 7 ± 1 (4–6 Dec): {tail}"
    assert row(d(2026, 11, 30), d(2026, 12, 2)) == f"▶ 2. post, day 7 ± 1 (30 Nov–2 Dec): {tail}"
    assert row(d(2026, 12, 30), d(2027, 1, 2)) == f"▶ 2. post, day 7 ± 1 (30 Dec–2 Jan 2027): {tail}"
    assert row(d(2027, 1, 3), d(2027, 1, 5)) == f"▶ 2. post, day 7 ± 1 (3–5 Jan 2027): {tail}"
    assert row(None, None, "not yet", "") == "• 2. post, day 7 ± 1: not yet — test to do, extra interrupted (resume it)"
