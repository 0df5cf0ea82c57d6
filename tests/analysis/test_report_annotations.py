"""The report of a study that describes its participants, asks NASA-TLX after each block and has notes.

Six simulated participants (counterbalanced blocks, a required group and an integer covariate, a weighted TLX
after each block, two Likert items after the session) are run; one note is added afterwards, marked a deviation.
Recomputed here independently from the database's own rows: each sheet's raw and weighted TLX (the standard's
definition: the mean of the six ratings; Σ weight × rating / 15 with each weight the times its subscale was
chosen in the 15 pairs) and the ON-vs-OFF test of the raw TLX (``scipy.stats.wilcoxon`` on the participants'
values).  The participants' tables carry the covariates, the codebook describes every column, the deviation note
is in deviations.csv and the page has the sections.
"""

from __future__ import annotations

import contextlib
import io
import sqlite3
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats as sps

from analysis.report.report import build_report
from protocol.study.config import load_protocol
from study_app.cli.main import main
from study_app.headless import run_study

PROTOCOL = """
name = "TLX report test"
[[targets]]
label = "GENTLE"
force_n = 0.6
[design]
trials_per_cell = 1
ordering = "counterbalanced"
[trial]
max_trial_s = 4.0
pause_s = 1.0
[training]
enabled = false
[[covariates]]
name = "group"
kind = "category"
levels = ["novice", "surgeon"]
required = true
[[covariates]]
name = "years_experience"
kind = "integer"
min = 0
max = 40
[[questionnaires]]
name = "workload"
kind = "nasa_tlx"
after = "block"
[[questionnaires]]
name = "experience"
kind = "likert"
after = "session"
scale = { min = 1, max = 5, low = "no", high = "yes" }
  [[questionnaires.items]]
  id = "felt_force"
  text = "I could feel the force."
"""
IDS = ["mental", "physical", "temporal", "performance", "effort", "frustration"]


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> dict:
    folder = tmp_path_factory.mktemp("annotated")
    proto = folder / "p.toml"
    proto.write_text(PROTOCOL, encoding="utf-8")
    db = folder / "study.db"
    run_study(str(db), participants=6, seed=3, protocol=load_protocol(proto), jobs=1)
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["note", "--db", str(db), "--session", "2", "--trial", "1", "--deviation",
                     "cue shown late on the participant screen"]) == 0
    out = folder / "report"
    build_report([db], out, workers=1)
    return {"db": db, "out": out}


def _independent_sheets(db: Path) -> pd.DataFrame:
    """Each TLX sheet scored from the stored rows by the standard's definition (a tally of the 15 choices)."""
    c = sqlite3.connect(db)
    try:
        rows = c.execute("SELECT p.code, a.block, a.item, a.rating, a.choice FROM questionnaire_answers a "
                         "JOIN sessions s USING (session_id) JOIN participants p USING (participant_id) "
                         "WHERE a.questionnaire = 'workload'").fetchall()
    finally:
        c.close()
    out = []
    for (code, block), sheet in pd.DataFrame(rows, columns=["code", "block", "item", "rating", "choice"]).groupby(
            ["code", "block"]):
        r = np.array([float(sheet.loc[sheet["item"] == i, "rating"].iloc[0]) for i in IDS])
        pairs = sheet[sheet["choice"].notna()]
        assert len(pairs) == 15
        w = np.array([(pairs["choice"] == i).sum() for i in IDS])
        assert w.sum() == 15
        out.append((code, block, r.mean(), float(w @ r) / 15.0))
    return pd.DataFrame(out, columns=["participant_code", "block", "raw", "weighted"])


def test_the_tlx_scores_equal_the_standards_definition_recomputed_from_the_stored_answers(study) -> None:
    mine = _independent_sheets(study["db"])
    assert len(mine) == 12  # six participants, a sheet after each of two blocks
    q = pd.read_csv(study["out"] / "questionnaires.csv")
    for measure, col in (("tlx_raw", "raw"), ("tlx_weighted", "weighted")):
        got = q[q["measure"] == measure].merge(mine, on=["participant_code", "block"])
        assert len(got) == 12
        # the file rounds to 4 decimals: equal within half a unit of the last
        assert np.allclose(got["value"], got[col], atol=5e-5, rtol=0)


def test_the_modes_test_equals_scipys_wilcoxon_of_the_participants_values_with_its_n(study) -> None:
    mine = _independent_sheets(study["db"]).pivot(index="participant_code", columns="block", values="raw")
    ref = sps.wilcoxon(mine["on"], mine["off"])
    t = pd.read_csv(study["out"] / "questionnaire_tests.csv").set_index("measure")
    assert int(t.loc["tlx_raw", "n_pairs"]) == 6
    assert float(t.loc["tlx_raw", "statistic"]) == pytest.approx(float(ref.statistic), abs=5e-5)
    assert float(t.loc["tlx_raw", "p_value"]) == pytest.approx(float(ref.pvalue), rel=5e-4)  # 4 significant digits
    assert float(t.loc["tlx_raw", "median_on"]) < float(t.loc["tlx_raw", "median_off"])  # the rule's relief


def test_participants_tables_carry_the_covariates_and_the_codebook_describes_every_column(study) -> None:
    out = study["out"]
    per = pd.read_csv(out / "participants.csv")
    assert list(per.columns[:4]) == ["participant_code", "participant_number", "group", "years_experience"]
    c = sqlite3.connect(study["db"])
    try:
        stored = dict(c.execute("SELECT p.code, v.value FROM covariates v JOIN participants p "
                                "USING (participant_id) WHERE v.name = 'group'").fetchall())
    finally:
        c.close()
    assert dict(zip(per["participant_code"], per["group"], strict=True)) == stored
    assert "group" in pd.read_csv(out / "participants_wide.csv").columns
    book = pd.read_csv(out / "codebook.csv")
    assert book["description"].notna().all(), book[book["description"].isna()]
    assert {"questionnaires.csv", "questionnaire_summary.csv", "questionnaire_tests.csv", "notes.csv"} <= set(
        book["file"])


def test_the_deviation_note_is_listed_and_the_page_has_the_sections(study) -> None:
    out = study["out"]
    dev = pd.read_csv(out / "deviations.csv")
    assert (dev["kind"] == "note").sum() == 1
    assert "trial 1: cue shown late on the participant screen (noted after the session)" in set(dev["detail"])
    s = pd.read_csv(out / "questionnaire_summary.csv")
    assert set(s[s["block"] == "session"]["measure"]) == {"felt_force"}
    page = (out / "report.html").read_text(encoding="utf-8")
    for words in ("The participants described", "Questionnaires", "The experimenter's notes",
                  "Hart &amp; Staveland 1988", "n = 6"):
        assert words in page
