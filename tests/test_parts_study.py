"""A study of several parts run headless (``haptic-study run`` on ``[[parts]]``): each part a session of its own in
the participant's counterbalanced order, resumed in the middle of a plan, withdrawn whole, checked and exported.

One small plan (tests/protocol/test_parts.py's: practice, then three test parts counterbalanced) is run for three
participants once for the module.
"""

from __future__ import annotations

import contextlib
import io
import json
import shutil
import sqlite3
from pathlib import Path

import pandas as pd
import pytest

from protocol.runner.session_setup import open_new_session, participant_code
from protocol.storage import StudyDatabase, new_owner_token, session_scope
from protocol.storage.withdrawal import footprint, withdrawals
from protocol.study.config import ProtocolConfig, load_protocol
from study_app.cli.main import main
from study_app.headless import run_study
from study_app.headless.session_run import StudyProgress, run_steps
from tests.parts_plan import PLAN

pytestmark = pytest.mark.xdist_group("parts_study")  # one worker builds the study once
SEED = 3


def _protocol(folder: Path) -> ProtocolConfig:
    path = folder / "plan.toml"
    path.write_text(PLAN, encoding="utf-8")
    return load_protocol(path)


def _sessions(db: Path) -> list[tuple]:
    c = sqlite3.connect(db)
    try:
        return c.execute("SELECT s.session_id, p.code, s.kind, s.status, s.protocol_json FROM sessions s "
                         "JOIN participants p USING (participant_id) ORDER BY s.session_id").fetchall()
    finally:
        c.close()


def _main(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> dict:
    folder = tmp_path_factory.mktemp("parts")
    protocol = _protocol(folder)
    db = folder / "study.db"
    run_study(str(db), participants=3, seed=SEED, protocol=protocol, jobs=1)
    return {"folder": folder, "db": db, "protocol": protocol}


def test_each_part_is_a_session_in_the_participants_order(study) -> None:
    rows = _sessions(study["db"])
    assert len(rows) == 3 * 4 and all(status == "completed" for _, _, _, status, _ in rows)
    for n in (1, 2, 3):
        code = participant_code(n)
        mine = [(kind, json.loads(pj)["part"]) for _, c, kind, _, pj in rows if c == code]
        want = [p.part.name for p in study["protocol"].plan_for(n, SEED)]
        assert [part["name"] for _, part in mine] == want  # run in the participant's order
        assert [part["position"] for _, part in mine] == [1, 2, 3, 4]
        assert all(part["order"] == want for _, part in mine)
        assert [kind for kind, _ in mine] == ["training", "experiment", "experiment", "experiment"]
    orders = {tuple(json.loads(pj)["part"]["order"]) for *_, pj in rows}
    assert len(orders) == 3  # three participants, three rows of the square


def test_check_passes_on_a_study_of_parts(study) -> None:
    code, out, err = _main("check", "--db", str(study["db"]))
    assert code == 0, out + err
    assert "designed cells: full in 9 of 9 experiment sessions" in out and "No problem found." in out


def test_sessions_lists_each_part(study) -> None:
    code, out, _ = _main("sessions", "--db", str(study["db"]))
    assert code == 0
    head = out.splitlines()[1].split()
    assert head[:5] == ["session", "participant", "number", "kind", "part"]
    assert sum(" practice " in line for line in out.splitlines()) == 3


def test_resume_in_the_middle_of_a_plan(study, tmp_path) -> None:
    """P01 has done two parts and was interrupted at the start of the third: --continue resumes that session
    (not a new one) and runs the fourth; P02 runs whole."""
    protocol: ProtocolConfig = study["protocol"]
    db_path = tmp_path / "mid.db"
    plan = protocol.plan_for(1, SEED)
    names = [p.part.name for p in plan]
    db = StudyDatabase(str(db_path))
    try:
        run_steps(db, 1, [("part", names[0]), ("part", names[1])], protocol=protocol, seed=SEED, clock="virtual",
                  progress=StudyProgress(), on_progress=None, study_owner=new_owner_token())
        owner = new_owner_token()  # the third part stored, then its process gone before its first trial
        opened = open_new_session(db, code="P01", number=1, kind="experiment", protocol=plan[2], seed=SEED,
                                  rig="sim", config={}, calibration=None, lease_owner=owner)
        db.release_lease(session_scope(opened.session_id), owner)
    finally:
        db.close()
    code, _, err = _main("run", "--protocol", str(study["folder"] / "plan.toml"), "--participants", "2",
                           "--seed", str(SEED), "--db", str(db_path), "--continue", "--jobs", "1")
    assert code == 0, err
    rows = _sessions(db_path)
    p01 = [(sid, json.loads(pj)["part"]["name"], status) for sid, c, _, status, pj in rows if c == "P01"]
    assert [name for _, name, _ in p01] == names and all(status == "completed" for *_, status in p01)
    assert p01[2][0] == opened.session_id  # the interrupted part resumed, not stored again
    assert sum(c == "P02" for _, c, *_ in rows) == 4
    # once more: nothing left to run, nothing written
    before = db_path.read_bytes()
    assert _main("run", "--protocol", str(study["folder"] / "plan.toml"), "--participants", "2", "--seed",
                 str(SEED), "--db", str(db_path), "--continue")[0] == 0
    assert db_path.read_bytes() == before


def test_a_new_part_of_a_participant_who_has_it_is_refused(study, tmp_path) -> None:
    copy = tmp_path / "copy.db"
    shutil.copy(study["db"], copy)
    part = study["protocol"].plan_for(2, SEED)[3]
    db = StudyDatabase(str(copy))
    try:
        with pytest.raises(Exception, match=f"already has an experiment session of part {part.part.name!r}"):
            open_new_session(db, code="P02", number=2, kind="experiment", protocol=part, seed=SEED, rig="sim",
                             config={}, calibration=None, lease_owner=new_owner_token())
    finally:
        db.close()


def test_withdrawal_of_a_multi_part_participant_removes_every_row(study, tmp_path) -> None:
    copy = tmp_path / "w.db"
    shutil.copy(study["db"], copy)
    c = sqlite3.connect(copy)
    fp = footprint(c, "P02")
    others = c.execute("SELECT COUNT(*) FROM sessions s JOIN participants p USING (participant_id) "
                       "WHERE p.code != 'P02'").fetchone()[0]
    c.close()
    assert len(fp.sessions) == 4 and fp.trials > 0
    code, _, err = _main("withdraw", "--db", str(copy), "--participant", "P02", "--reason", "asked", "--yes", "P02")
    assert code == 0, err
    c = sqlite3.connect(copy)
    try:
        (w,) = withdrawals(c)
        assert (w.removed_sessions, w.removed_trials, w.removed_events, w.removed_blocks, w.removed_records) == (
            4, fp.trials, fp.events, fp.blocks, fp.records)
        tables = [t for (t,) in c.execute("SELECT name FROM sqlite_master WHERE type = 'table'")
                  if any(col[1] == "session_id" for col in c.execute(f"PRAGMA table_info({t})"))]
        assert {"sessions", "trials", "events", "session_blocks", "recordings"} <= set(tables)
        for table in tables:  # every table of session rows
            sid_rows = c.execute(f"SELECT COUNT(*) FROM {table} WHERE session_id IN ({','.join('?' * 4)})",
                                 [sid for sid, _, _ in fp.sessions]).fetchone()[0]
            assert sid_rows == 0, table
        assert c.execute("SELECT COUNT(*) FROM sessions").fetchone()[0] == others == 8
    finally:
        c.close()
    assert _main("check", "--db", str(copy))[0] == 0


def test_the_report_of_a_study_of_parts_is_a_report_per_part(study, tmp_path) -> None:
    out = tmp_path / "report"
    code, printed, err = _main("report", "--db", str(study["db"]), "--out", str(out))
    assert code == 0, err
    for name in ("regulation", "tracking", "firm"):  # each experiment part from its own sessions only
        trials = pd.read_csv(out / name / "trials.csv")
        assert sorted(trials["participant_code"].unique()) == ["P01", "P02", "P03"]
        part_sessions = {sid for sid, _, kind, _, pj in _sessions(study["db"])
                         if json.loads(pj)["part"]["name"] == name}
        assert set(trials["session_id"]) <= part_sessions
        part_page = (out / name / "report.html").read_text(encoding="utf-8")
        assert f"Part <b>{name}</b>" in part_page and 'href="../report.html"' in part_page  # it says whose it is
    assert not (out / "practice").exists()  # a training part is not analysed
    firm = pd.read_csv(out / "firm" / "trials.csv")
    assert set(firm["target_label"]) == {"FIRM"}  # one task's targets, nothing pooled
    page = (out / "report.html").read_text(encoding="utf-8")
    assert "balanced Latin square (Williams 1949)" in page and "6 rows" in page
    assert "practice kept its place" in page
    parts = pd.read_csv(out / "parts.csv")
    assert len(parts) == 12 and set(parts["part"]) == {"practice", "regulation", "tracking", "firm"}
    assert "regulation: 3 participants" in printed


@pytest.mark.parametrize("argv", [("sweep", "--set", "filter_window=1,10", "--protocol"),
                                  ("power", "--groups", "--simulated", "--protocol")])
def test_commands_of_one_task_refuse_a_study_of_parts(study, tmp_path, argv) -> None:
    code, _, err = _main(*argv, str(study["folder"] / "plan.toml"), "--out", str(tmp_path / "o"))
    assert code == 2 and "a study of several parts (practice, regulation, tracking, firm)" in err
    assert "choose its part with --part NAME" in err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "o").exists()


def test_power_plans_one_part_of_a_pilot(study, tmp_path) -> None:
    """``power --db`` on a pilot of parts: refused without --part (naming them), for a training part and a name it
    does not hold; with --part, the pool is that part's sessions and its task's measures only."""
    from analysis.planning.paired_pool import load_pool

    db = str(study["db"])
    firm, tracking = load_pool([db], part="firm"), load_pool([db], part="tracking")
    assert firm.scopes == ("overall", "FIRM") and "success_rate" in firm.metrics and "lag_s" not in firm.metrics
    assert tracking.scopes == ("overall", "GENTLE") and "lag_s" in tracking.metrics
    assert "success_rate" not in tracking.metrics and "(its part 'tracking')" in tracking.source
    assert firm.participants == tracking.participants == ("P01", "P02", "P03")
    for extra, said in [((), "a study of several parts (practice, "),  # in P01's order
                        (("--part", "practice"), "a training part"),
                        (("--part", "nope"), "holds no session of it; its parts are")]:
        code, _, err = _main("power", "--db", db, "--out", str(tmp_path / "o"), *extra)
        assert code == 2 and said in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()
    code, _, err = _main("power", "--db", db, "--out", str(tmp_path / "o"), "--part", "regulation")
    assert code == 2 and "has 3 participants with both haptic modes" in err  # the part's pool was read


def test_sweep_runs_one_part_of_a_protocol(study, tmp_path) -> None:
    plan = str(study["folder"] / "plan.toml")
    code, out, err = _main("sweep", "--protocol", plan, "--part", "tracking", "--set", "filter_window=10",
                           "--participants", "1", "--studies", "1", "--out", str(tmp_path / "s"))
    assert code == 0, err
    assert "protocol 'tiny plan (part tracking)'" in out
    assert set(pd.read_csv(tmp_path / "s" / "sweep.csv")["metric"]) == {"rmse_N", "max_ae_N", "lag_s", "gain"}
    code, _, err = _main("sweep", "--part", "tracking", "--set", "filter_window=10", "--out", str(tmp_path / "d"))
    assert code == 2 and "the default protocol (the paper's study) is a study of one task" in err
