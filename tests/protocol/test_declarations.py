"""What a protocol declares about its participants and asks them: covariates and questionnaires, each checked.

A bad declaration is refused when the file is loaded, in one line naming the file, the field, the value and what
is allowed; a bad value (a covariate outside its range, a questionnaire's answer off its scale) in one line
naming the covariate or item, the value and what is allowed.  The paper's protocol declares neither, and stores
exactly the JSON it stored before they existed.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from protocol.study.config import ProtocolError, default_protocol, load_protocol, protocol_from_dict
from protocol.study.covariates import CovariateError, checked_values, parse_assignment, simulated_values
from protocol.study.questionnaires import SESSION, checked_answers, due
from protocol.study.sim_answers import simulated_answers

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "surgeons.toml"
BASE = """
name = "t"
[[targets]]
label = "GENTLE"
force_n = 0.6
[design]
ordering = "blocked_by_mode"
"""


def _load(tmp_path: Path, extra: str, base: str = BASE) -> object:
    p = tmp_path / "p.toml"
    p.write_text(base + extra, encoding="utf-8")
    return load_protocol(p)


def _refusal(tmp_path: Path, extra: str, base: str = BASE) -> str:
    with pytest.raises(ProtocolError) as info:
        _load(tmp_path, extra, base)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(str(tmp_path / "p.toml") + ": "), msg
    return msg.split(": ", 1)[1]


def test_the_papers_protocol_declares_nothing_and_stores_the_json_it_always_stored() -> None:
    p = default_protocol()
    assert p.covariates == () and p.questionnaires == ()
    assert "covariates" not in p.to_json() and "questionnaires" not in p.to_json()


def test_the_example_protocol_declares_five_covariates_and_two_questionnaires_and_round_trips() -> None:
    p = load_protocol(EXAMPLE)
    assert [c.name for c in p.covariates] == ["group", "years_experience", "robotic_hours", "handedness", "age_band"]
    assert [c.required for c in p.covariates] == [True, False, False, False, False]
    assert [(q.name, q.kind, q.after) for q in p.questionnaires] == [("workload", "nasa_tlx", "block"),
                                                                     ("experience", "likert", "session")]
    assert len(p.questionnaires[0].questions()) == 6 + 15
    assert protocol_from_dict(json.loads(p.to_json())) == p


COVARIATE_REFUSALS = [
    ('[[covariates]]\nkind = "category"\nlevels = ["a", "b"]\n',
     "covariates[0].name = None: every covariate needs a name"),
    ('[[covariates]]\nname = "Group"\nkind = "category"\nlevels = ["a", "b"]\n',
     "covariates[0].name = 'Group': must be a lower-case name"),
    ('[[covariates]]\nname = "haptic_mode"\nkind = "category"\nlevels = ["a", "b"]\n',
     "covariates[0].name = 'haptic_mode': is a column the report already has"),
    ('[[covariates]]\nname = "g"\nkind = "colour"\n', "covariates[0].kind = 'colour': allowed values: category"),
    ('[[covariates]]\nname = "g"\nkind = "category"\n', "covariates[0].levels = None: a category needs its levels"),
    ('[[covariates]]\nname = "g"\nkind = "category"\nlevels = ["a", "a"]\n', "levels must be distinct"),
    ('[[covariates]]\nname = "g"\nkind = "category"\nlevels = ["a"]\n', "must be a list of 2 to 32 level names"),
    ('[[covariates]]\nname = "y"\nkind = "integer"\nmin = 0\n', "covariates[0].max = None: an integer covariate "
     "needs its range"),
    ('[[covariates]]\nname = "y"\nkind = "integer"\nmin = 5\nmax = 5\n', "covariates[0].max = 5: must be greater "
     "than covariates[0].min = 5"),
    ('[[covariates]]\nname = "y"\nkind = "integer"\nmin = 0.5\nmax = 5\n', "covariates[0].min = 0.5: must be a "
     "whole number"),
    ('[[covariates]]\nname = "y"\nkind = "float"\nmin = 0\nmax = 5\nlevels = ["a", "b"]\n',
     "covariates[0].levels = ['a', 'b']: an float has a range"),
    ('[[covariates]]\nname = "y"\nkind = "float"\nmin = 0\nmax = 5\n[[covariates]]\nname = "y"\nkind = "float"\n'
     'min = 0\nmax = 5\n', "covariates[1].name = 'y': is declared twice"),
    ('[[covariates]]\nname = "y"\nkind = "float"\nmin = 0\nmax = 5\nrequired = "yes"\n',
     "covariates[0].required = 'yes': must be true or false"),
]


@pytest.mark.parametrize(("extra", "expect"), COVARIATE_REFUSALS, ids=[e for _, e in COVARIATE_REFUSALS])
def test_a_bad_covariate_declaration_is_one_line_naming_the_field(tmp_path, extra, expect) -> None:
    assert expect in _refusal(tmp_path, extra)


def test_values_are_typed_and_a_bad_one_is_one_line_naming_covariate_value_and_what_is_allowed() -> None:
    declared = load_protocol(EXAMPLE).covariates
    got = checked_values(declared, {"group": "surgeon", "years_experience": "12", "robotic_hours": "150.5",
                                    "handedness": ""})
    assert got == {"group": "surgeon", "years_experience": 12, "robotic_hours": 150.5}
    assert type(got["years_experience"]) is int and type(got["robotic_hours"]) is float
    for given, expect in [
        ({"group": "surgeon", "years_experience": "-3"}, "covariate years_experience = '-3': must be a whole number "
                                                         "from 0 to 50 years"),
        ({"group": "surgeon", "years_experience": "2.5"}, "covariate years_experience = '2.5': must be a whole"),
        ({"group": "surgeon", "robotic_hours": "nan"}, "covariate robotic_hours = 'nan': must be a number from 0 to "
                                                       "10000 h"),
        ({"group": "expert"}, "covariate group = 'expert': must be one of novice, resident, surgeon"),
        ({"years_experience": "3"}, "covariate group = (none): required by the protocol; must be one of novice"),
        ({"group": "novice", "name": "Jane"}, "covariate name = 'Jane': the protocol declares no such covariate "
                                              "(it declares group, years_experience"),
    ]:
        with pytest.raises(CovariateError) as info:
            checked_values(declared, given)
        assert expect in str(info.value) and "\n" not in str(info.value), str(info.value)
    with pytest.raises(CovariateError, match="covariate group = 'x': the protocol declares no such covariate "
                                             r"\(it declares none\)"):
        checked_values((), {"group": "x"})
    assert parse_assignment(" group = novice ") == ("group", "novice")
    with pytest.raises(CovariateError, match="--covariate = 'group': must be NAME=VALUE"):
        parse_assignment("group")


def test_simulated_participants_get_values_within_the_declarations_from_the_seed_alone() -> None:
    declared = load_protocol(EXAMPLE).covariates
    a = [simulated_values(declared, 0, n) for n in range(1, 41)]
    assert a == [simulated_values(declared, 0, n) for n in range(1, 41)]  # the same seed: the same values
    assert a != [simulated_values(declared, 1, n) for n in range(1, 41)]
    for v in a:
        assert checked_values(declared, v) == v  # every one within its declaration
    assert {v["group"] for v in a} == {"novice", "resident", "surgeon"}


QUESTIONNAIRE_REFUSALS = [
    ('[[questionnaires]]\nname = "w"\nkind = "likert"\n[[questionnaires.items]]\nid = "a"\ntext = "A?"\n',
     "questionnaires[0].items[0].scale = None: every Likert item needs its scale (or its questionnaire's)"),
    ('[[questionnaires]]\nname = "w"\nkind = "likert"\n[[questionnaires.items]]\nid = "a"\ntext = "A?"\n'
     'scale = {min = 1, max = 7, low = "no"}\n', "questionnaires[0].items[0].scale.high = None: a scale needs"),
    ('[[questionnaires]]\nname = "w"\nkind = "likert"\nscale = {min = 3, max = 3, low = "a", high = "b"}\n'
     '[[questionnaires.items]]\nid = "a"\ntext = "A?"\n', "questionnaires[0].scale.max = 3: must be 1 to 20 more"),
    ('[[questionnaires]]\nname = "w"\nkind = "likert"\n', "questionnaires[0].items = None: a Likert questionnaire "
     "needs its [[questionnaires.items]]"),
    ('[[questionnaires]]\nname = "w"\nkind = "nasa_tlx"\nafter = "trial"\n', "questionnaires[0].after = 'trial': "
     "allowed values: block, session"),
    ('[[questionnaires]]\nname = "w"\nkind = "nasa_tlx"\nscale = {min = 1, max = 7, low = "a", high = "b"}\n',
     "questionnaires[0].scale = "),
    ('[[questionnaires]]\nname = "w"\nkind = "sus"\n', "questionnaires[0].kind = 'sus': allowed values: nasa_tlx"),
    ('[[questionnaires]]\nname = "w"\nkind = "nasa_tlx"\n[[questionnaires]]\nname = "w"\nkind = "nasa_tlx"\n',
     "questionnaires[1].name = 'w': is declared twice"),
]


@pytest.mark.parametrize(("extra", "expect"), QUESTIONNAIRE_REFUSALS, ids=[e[:40] for _, e in QUESTIONNAIRE_REFUSALS])
def test_a_bad_questionnaire_declaration_is_one_line_naming_the_field(tmp_path, extra, expect) -> None:
    assert expect in _refusal(tmp_path, extra)


def test_a_block_questionnaire_needs_an_order_by_mode(tmp_path) -> None:
    msg = _refusal(tmp_path, '[[questionnaires]]\nname = "w"\nkind = "nasa_tlx"\n', BASE.replace("blocked_by_mode",
                                                                                                 "random"))
    assert msg.startswith("questionnaires[0].after = 'block': needs design.ordering 'blocked_by_mode' or "
                          "'counterbalanced'")
    p = _load(tmp_path, '[[questionnaires]]\nname = "w"\nkind = "nasa_tlx"\nafter = "session"\n',
              BASE.replace("blocked_by_mode", "random"))
    assert p.questionnaires[0].after == "session"  # type: ignore[attr-defined]


def test_a_questionnaire_is_due_after_each_mode_block_once_and_the_session_after_the_last_trial() -> None:
    qs = load_protocol(EXAMPLE).questionnaires
    modes = ["on"] * 3 + ["off"] * 3 + ["on"]  # the re-run of an aborted ON trial appended
    assert [due(qs, modes, p, []) for p in (0, 1, 2)] == [None, None, None]
    p3 = due(qs, modes, 3, [])
    assert p3 is not None and p3.key == ("workload", "on")
    assert due(qs, modes, 6, [("workload", "on")]).key == ("workload", "off")  # type: ignore[union-attr]
    done = [("workload", "on"), ("workload", "off")]
    assert due(qs, modes, 6, done) is None  # the ON block after it has been asked about
    assert due(qs, modes, 7, done).key == ("experience", SESSION)  # type: ignore[union-attr]
    assert due(qs, modes, 7, [*done, ("experience", SESSION)]) is None


def test_answers_are_checked_against_their_questions_in_one_line() -> None:
    tlx_q, likert = load_protocol(EXAMPLE).questionnaires
    good = simulated_answers(due([tlx_q], ["on", "off"], 1, []), 5)  # type: ignore[arg-type]
    assert checked_answers(tlx_q, good) == good
    for change, expect in [
        ({"mental": 42.0}, "questionnaire workload: mental = 42.0: must be 0 to 100 in steps of 5"),
        ({"mental|physical": "effort"}, "mental|physical = 'effort': must be 'mental' or 'physical'"),
        ({"colour": 3}, "questionnaire workload: answer 'colour' = 3: no such question"),
    ]:
        with pytest.raises(ValueError, match=expect.replace("|", r"\|")):
            checked_answers(tlx_q, {**good, **change})
    with pytest.raises(ValueError, match=r"confident = 8\.0: must be a whole number from 1 to 7"):
        checked_answers(likert, {"felt_force": 4, "confident": 8.0})
    with pytest.raises(ValueError, match="felt_force = None"):
        checked_answers(likert, {"confident": 4})


def test_the_simulated_participant_answers_by_its_rule_lower_workload_with_haptics_on() -> None:
    from protocol.study import tlx
    from protocol.study.questionnaires import Prompt

    tlx_q = load_protocol(EXAMPLE).questionnaires[0]
    def raw(block: str, seed: int) -> float:
        sheet = simulated_answers(Prompt(tlx_q, block), seed)
        return tlx.score({k: float(v) for k, v in sheet.items() if "|" not in k}).raw

    diff = [raw("off", s) - raw("on", s) for s in range(200)]
    # the rule's relief is 12 rating points; its noise (s.d. 7.5 per rating, mean of six) leaves the mean of 200
    # differences within ±2 of it
    assert sum(diff) / len(diff) == pytest.approx(12.0, abs=2.0)
    sheet = simulated_answers(Prompt(tlx_q, "on"), 3)
    assert sheet == simulated_answers(Prompt(tlx_q, "on"), 3)  # deterministic
    assert sorted(tlx.weights({k: str(v) for k, v in sheet.items() if "|" in k}).values()) == [0, 1, 2, 3, 4, 5]
