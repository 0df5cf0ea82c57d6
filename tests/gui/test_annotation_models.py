"""The GUI's models of issue 44 without Qt: the covariates' form, the questionnaire's pages, the note's subjects."""

from __future__ import annotations

from pathlib import Path

from protocol.study.config import load_protocol
from protocol.study.design import HapticMode
from protocol.study.questionnaires import checked_answers
from study_app.engine import messages as m
from study_app.models.covariate_form import CovariateForm
from study_app.models.notes import note_subjects
from study_app.models.questionnaire import QuestionnaireModel
from study_app.models.session import SessionModel

EXAMPLE = load_protocol(Path(__file__).resolve().parents[2] / "docs" / "examples" / "surgeons.toml")


def test_the_form_asks_a_new_participant_says_every_wrong_answer_and_shows_a_registered_ones_values() -> None:
    form = CovariateForm()
    form.set_questions(EXAMPLE.covariates, None)
    assert form.asking
    form.set_text("years_experience", "sixty")
    form.set_text("robotic_hours", "-1")
    lines = form.error().splitlines()
    assert lines == ["covariate group = (none): required by the protocol; must be one of novice, resident, surgeon",
                     "covariate years_experience = 'sixty': must be a whole number from 0 to 50 years",
                     "covariate robotic_hours = '-1': must be a number from 0 to 10000 h"]
    form.set_text("group", "novice")
    form.set_text("years_experience", " 2 ")
    form.set_text("robotic_hours", "")
    assert form.error() == ""
    assert form.values() == {"group": "novice", "years_experience": "2"}
    assert form.typed() == {"group": "novice", "years_experience": 2}
    form.set_questions(EXAMPLE.covariates, {"group": "surgeon", "years_experience": 14})
    assert not form.asking and form.values() == {} and form.error() == ""
    assert form.registered_text() == "group = surgeon · years_experience = 14 years"
    form.set_questions((), None)  # the paper's protocol: nothing asked
    assert not form.asking and form.error() == ""


def test_the_questionnaire_pages_by_keyboard_send_a_sheet_the_engine_accepts() -> None:
    sent: list[object] = []
    md = QuestionnaireModel(send=lambda cmd: sent.append(cmd) or True)
    tlx_q = EXAMPLE.questionnaires[0]
    md.apply(m.QuestionnaireShown(7, tlx_q, "on"))
    assert md.active and md.position() == "Question 1 of 21" and md.title() == "Mental demand"
    md.next()
    assert md.page == 0  # not answered: Enter does not go on
    md.step(+1)
    assert md.value() == 50.0  # → first: the middle mark
    md.step(+1)
    md.step(+1)
    assert md.value() == 60.0
    for _ in range(25):
        md.step(-1)
    assert md.value() == 0.0  # kept on the scale
    md.next()
    for _ in range(5):
        md.step(+1)
        md.next()
    assert md.item is not None and md.item.pair == ("mental", "physical")
    assert md.pair_names() == ("Mental demand", "Physical demand")
    md.step(+1)  # → chooses the right one and goes on
    assert md.answers["mental|physical"] == "physical" and md.page == 7
    md.back()
    assert md.page == 6
    for _ in range(15):
        md.step(-1)
    assert md.item is None and md.position() == "All 21 questions answered"
    assert md.submit() and md.sent and not md.submit()  # once
    (cmd,) = sent
    assert isinstance(cmd, m.AnswerQuestionnaire) and (cmd.session_id, cmd.questionnaire, cmd.block) == (7, "workload",
                                                                                                       "on")
    assert checked_answers(tlx_q, cmd.answers) == cmd.answers
    md.apply(m.CommandRefused("AnswerQuestionnaire", "not the one waiting"))
    assert not md.sent and md.refused == "not the one waiting"
    md.apply(m.QuestionnaireAnswered(7, "workload", "on"))
    assert not md.active


def test_a_likert_page_takes_a_digit_on_its_scale_and_the_note_proposes_the_running_trial() -> None:
    md = QuestionnaireModel()
    md.apply(m.QuestionnaireShown(1, EXAMPLE.questionnaires[1], "session"))
    assert md.scale()[:3] == (1, 7, 1) and "whole session" in md.heading()
    md.step(+1)
    assert md.value() == 4.0  # the middle of 1–7
    s = SessionModel()
    assert note_subjects(s) == ([("the session", None)], 0)
    s.apply(m.TrialStarted(1.0, 3, 4, 20, "FIRM", 1.2, HapticMode.ON))
    choices, proposed = note_subjects(s)
    assert choices[proposed] == ("trial 4 (running: FIRM, haptics ON)", 3)
