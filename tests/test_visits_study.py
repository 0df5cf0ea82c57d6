"""A study with a schedule of visits run headless: the whole schedule on the virtual clock (each visit on its planned
day, the participant learning from the second visit on), one visit at a time (``run --visit``: out of order or
outside its window refused in one line, nothing stored, unless a deviation's reason is given), continued, checked
and reported (the learning page)."""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import sqlite3
from pathlib import Path

import pandas as pd
import pytest

from analysis.reading.load import load_study
from analysis.report.study_record import deviations
from protocol.runner.session_setup import open_new_session
from protocol.storage import StorageError, StudyDatabase, new_owner_token, session_scope
from protocol.study.config import load_protocol
from study_app.cli.main import main
from study_app.headless import run_study
from study_app.headless.plan_visits import visit_step
from study_app.headless.session_run import StudyProgress, practice_of, run_steps
from tests.parts_plan import STUDY

pytestmark = pytest.mark.xdist_group("visits_study")  # one worker builds the study once

TINY = STUDY.replace("tiny plan", "tiny schedule") + """[[parts]]
name = "test"
[[visits]]
name = "baseline"
day = 0
parts = ["practice", "test"]
role = "baseline"
[[visits]]
name = "post"
day = 2
parts = ["test"]
role = "post"
[[visits]]
name = "keep"
day = 9
window_days = 1
parts = ["test"]
role = "retention"
"""


def _main(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


def _rows(db: Path, sql: str) -> list[tuple]:
    c = sqlite3.connect(db)
    try:
        return c.execute(sql).fetchall()
    finally:
        c.close()


def _visits(db: Path) -> list[tuple[str, str, str]]:
    """(code, visit, part) of every session, in order."""
    rows = _rows(db, "SELECT p.code, s.protocol_json FROM sessions s JOIN participants p USING (participant_id) "
                     "ORDER BY s.session_id")
    return [(code, json.loads(pj)["part"]["visit"]["name"], json.loads(pj)["part"]["name"]) for code, pj in rows]


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> dict:
    folder = tmp_path_factory.mktemp("visits")
    (folder / "p.toml").write_text(TINY, encoding="utf-8")
    protocol = load_protocol(folder / "p.toml")
    db = folder / "study.db"
    run_study(str(db), participants=2, seed=4, protocol=protocol, jobs=1)
    return {"folder": folder, "db": db, "protocol": protocol}


def test_the_whole_schedule_runs_each_visit_on_its_day(study) -> None:
    want = [("baseline", "practice"), ("baseline", "test"), ("post", "test"), ("keep", "test")]
    assert _visits(study["db"]) == [(c, v, p) for c in ("P01", "P02") for v, p in want]
    assert {s for (s,) in _rows(study["db"], "SELECT status FROM sessions")} == {"completed"}
    held = _rows(study["db"], "SELECT detail FROM events WHERE kind = 'visit' ORDER BY session_id")
    assert len(held) == 8 and held[3][0].startswith("keep (visit 3): held on study day 9, planned day 9 ± 1")
    # the simulated participant of a later visit has learned; the first visit's is the calibrated one
    plan = study["protocol"].plan_for(1, 4)
    assert practice_of(plan[1]).learned() == 0.0 < practice_of(plan[2]).learned()  # type: ignore[union-attr]


def test_check_passes_and_continue_has_nothing_left(study) -> None:
    code, out, err = _main("check", "--db", str(study["db"]))
    assert code == 0, out + err
    code, out, err = _main("run", "--protocol", str(study["folder"] / "p.toml"), "--participants", "2", "--seed", "4",
                           "--db", str(study["db"]), "--continue")
    assert code == 0 and "nothing to continue" in err


def test_one_visit_at_a_time_refuses_a_visit_out_of_order_or_window(tmp_path, study) -> None:
    db = tmp_path / "lab.db"
    args = ("run", "--protocol", str(study["folder"] / "p.toml"), "--participants", "1", "--seed", "4", "--db",
            str(db), "--jobs", "1")
    assert _main(*args, "--visit", "baseline")[0] == 0
    assert [v for _, v, _ in _visits(db)] == ["baseline", "baseline"]
    before = hashlib.sha256(db.read_bytes()).hexdigest()
    code, _, err = _main(*args, "--visit", "keep", "--day", "9")
    assert code == 2 and "visit 'keep' is out of order: the earlier visit 'post' is not done" in err
    code, _, err = _main(*args, "--visit", "post", "--day", "5")
    assert code == 2 and "outside its window: held on study day 5, planned for day 2 ± 0" in err
    assert "--deviation" in err and len(err.strip().splitlines()) == 1
    assert hashlib.sha256(db.read_bytes()).hexdigest() == before  # refused: nothing stored, not even opened to write
    assert _main(*args, "--visit", "post", "--day", "5", "--deviation", "the participant was ill")[0] == 0
    dev = _rows(db, "SELECT detail FROM events WHERE kind = 'deviation'")
    assert dev == [("visit 'post' is outside its window: held on study day 5, planned for day 2 ± 0: the participant "
                    "was ill",)]
    assert _rows(db, "SELECT detail FROM events WHERE kind = 'visit' ORDER BY rowid DESC LIMIT 1")[0][0] \
        .startswith("post (visit 2): held on study day 5, planned day 2 ± 0 (run --visit)")
    code, _, err = _main(*args, "--continue")  # the rest of the schedule, each visit left on its planned day
    assert code == 0, err
    assert [v for _, v, _ in _visits(db)] == ["baseline", "baseline", "post", "keep"]
    listed = deviations(load_study([db], part="post-test"))  # the report's deviations list it
    assert listed["detail"].tolist() == [dev[0][0]] and listed["participant_code"].tolist() == ["P01"]


def test_an_interrupted_visit_is_resumed_where_it_stopped(tmp_path, study) -> None:
    """P01 did the baseline and was interrupted in the post-test: --visit post resumes that session (not a new
    one); a second session of the same visit and part is refused naming both."""
    protocol = study["protocol"]
    db_path = tmp_path / "mid.db"
    plan = protocol.plan_for(1, 4)
    db = StudyDatabase(str(db_path))
    try:
        run_steps(db, 1, [("visit", visit_step(p, None, 0)) for p in plan[:2]], protocol=protocol, seed=4,
                  clock="virtual", progress=StudyProgress(), on_progress=None, study_owner=new_owner_token())
        owner = new_owner_token()  # the post-test stored, then its process gone before its first trial
        opened = open_new_session(db, code="P01", number=1, kind="experiment", protocol=plan[2], seed=4, rig="sim",
                                  config={}, calibration=None, lease_owner=owner)
        db.release_lease(session_scope(opened.session_id), owner)
        with pytest.raises(StorageError, match="already has an experiment session of part 'test' in visit 'post'"):
            open_new_session(db, code="P01", number=1, kind="experiment", protocol=plan[2], seed=4, rig="sim",
                             config={}, calibration=None, lease_owner=new_owner_token())
    finally:
        db.close()
    code, _, err = _main("run", "--protocol", str(study["folder"] / "p.toml"), "--participants", "1", "--seed", "4",
                         "--db", str(db_path), "--visit", "post", "--day", "2", "--jobs", "1")
    assert code == 0, err
    rows = _rows(db_path, "SELECT session_id, status FROM sessions ORDER BY session_id")
    assert rows[-1] == (opened.session_id, "completed") and len(rows) == 3  # resumed, not stored again


def test_bad_visit_requests_are_refused_in_one_line(tmp_path, study) -> None:
    args = ("run", "--protocol", str(study["folder"] / "p.toml"), "--participants", "1", "--db",
            str(tmp_path / "x.db"))
    for extra, said in ((("--visit", "later"), "--visit = 'later': no such visit; the visits are baseline, post"),
                        (("--day", "3"), "--day is given without --visit"),
                        (("--visit", "post", "--continue"), "--visit post with --continue")):
        code, _, err = _main(*args, *extra)
        assert code == 2 and said in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.db").exists()


def test_the_report_has_learning_curves_and_retention(study) -> None:
    out = study["folder"] / "report"
    code, printed, err = _main("report", "--db", str(study["db"]), "--out", str(out))
    assert code == 0, err
    assert "learning.html" in printed
    for name in ("baseline-test", "post-test", "keep-test"):
        assert (out / name / "report.html").is_file()  # a report per visit and part: one session per participant
    learning = pd.read_csv(out / "learning.csv")
    assert len(learning) == 2 * 3 * 2 and list(learning["day"].unique()) == [0, 2, 9]
    # each value is that visit's own report's (its participants.csv, rounded there to 4 decimals)
    part = pd.read_csv(out / "post-test" / "participants.csv")
    mine = learning[learning["visit"] == "post"].sort_values(["participant_code", "haptic_mode"])
    assert mine["success_rate"].tolist() == part.sort_values(["participant_code", "haptic_mode"])["success_rate"] \
        .tolist()
    kept = pd.read_csv(out / "retention.csv")
    assert set(kept["retention_visit"]) == {"keep"} and len(kept) == 2 * 2 * 4
    page = (out / "learning.html").read_text(encoding="utf-8")
    assert "MixedLM" in page or "not fitted: 2 participants" in page
    assert (out / "learning_curve.png").stat().st_size > 10_000
    assert 'href="learning.html"' in (out / "report.html").read_text(encoding="utf-8")


def test_power_names_a_visits_part_as_the_report_does(study, tmp_path) -> None:
    """A pilot with visits: a part recurs across visits, so power takes VISIT-PART (the report's name); the bare
    part name is refused naming the keys, and the chosen key's sessions are the ones read."""
    from analysis.planning.paired_pool import load_pool

    db = str(study["db"])
    code, _, err = _main("power", "--db", db, "--out", str(tmp_path / "o"), "--part", "test")
    assert code == 2 and "holds no session of it; its parts are baseline-practice, baseline-test, post-test" in err
    pool = load_pool([db], part="post-test")
    assert pool.participants == ("P01", "P02") and "(its part 'post-test')" in pool.source
    code, _, err = _main("power", "--db", db, "--out", str(tmp_path / "o"), "--part", "post-test")
    assert code == 2 and "has 2 participants with both haptic modes" in err and not (tmp_path / "o").exists()
