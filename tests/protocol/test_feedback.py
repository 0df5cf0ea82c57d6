"""Feedback to the trainee (issue 44): a score card after each block where the protocol allows it, off by default.

Its parameters checked in one line; the card's numbers against a hand count (a rate from the outcomes, TCT over
successes only, each measure's own direction of better); a simulated study through ``run``: a card after each
block of each session, stored as a ``feedback`` event whose numbers are recomputed here from the stored trials,
the experiment's compared with the training session before it, and the report's methods saying it was given.
"""

from __future__ import annotations

import math
import sqlite3
from pathlib import Path

import pytest

from protocol.metrics import select
from protocol.study.config import ProtocolError, default_protocol, protocol_from_dict
from protocol.study.feedback import FEEDBACK_EVENT, score_card, shown_blocks
from protocol.tasks.force_regulation import ForceRegulation
from study_app.cli.main import main

PROTOCOL = """name = "feedback"
[[targets]]
label = "GENTLE"
force_n = 0.6
[[targets]]
label = "FIRM"
force_n = 1.2
[design]
modes = ["on", "off"]
trials_per_cell = 2
ordering = "blocked_by_mode"
[trial]
max_trial_s = 4.0
pause_s = 0.5
cue_s = 0.5
[training]
enabled = true
seconds_per_target_per_mode = 4.0
[feedback]
score_card = true
show_s = 3.0
"""


def _table(**feedback: object) -> dict:
    import tomllib

    d = tomllib.loads(PROTOCOL)
    d["feedback"] = feedback
    return d


def test_off_by_default_and_stored_only_when_on() -> None:
    paper = default_protocol()
    assert not paper.feedback.score_card and "feedback" not in paper.to_dict()
    on = protocol_from_dict(_table(score_card=True, show_s=3.0))
    assert on.to_dict()["feedback"] == {"score_card": True, "show_s": 3.0, "sessions": ["training", "experiment"]}
    assert on.feedback.in_session("experiment") and on.feedback.in_session("training")
    assert not protocol_from_dict(_table(score_card=True, sessions=["training"])).feedback.in_session("experiment")


@pytest.mark.parametrize(("change", "words"), [
    ({"score_card": True, "show_s": 0.5}, "feedback.show_s"),
    ({"score_card": True, "sessions": ["practice"]}, "feedback.sessions"),
    ({"score_card": "yes"}, "feedback.score_card"),
    ({"score_card": True, "colour": "red"}, "colour"),
])
def test_bad_feedback_is_refused_in_one_line(change: dict, words: str) -> None:
    with pytest.raises(ProtocolError) as err:
        protocol_from_dict(_table(**change))
    assert words in str(err.value) and "\n" not in str(err.value)


def test_a_card_after_each_block_needs_an_ordering_by_mode() -> None:
    d = _table(score_card=True)
    d["design"]["ordering"] = "random"
    with pytest.raises(ProtocolError, match=r"feedback\.score_card = true: .*blocked_by_mode"):
        protocol_from_dict(d)


def test_the_card_against_a_hand_count() -> None:
    metrics = ForceRegulation().metrics
    block = [({"tct_s": 2.0, "rmse_n": 0.2, "max_ae_n": 0.5}, "success"),
             ({"tct_s": None, "rmse_n": 0.4, "max_ae_n": 0.9}, "timeout")]
    earlier = [(1, {"tct_s": None, "rmse_n": 0.5, "max_ae_n": 0.4}, "timeout"),
               (2, {"tct_s": 3.0, "rmse_n": 0.3, "max_ae_n": 0.6}, "success"),
               (2, {"tct_s": None, "rmse_n": 0.7, "max_ae_n": 0.8}, "timeout")]
    card = score_card(metrics, "on", block, earlier)
    rows = {label: (now, before, better) for label, now, before, better in card.rows}
    assert set(rows) == {"success rate", "TCT (s)", "RMSE (N)", "Max AE (N)"}  # the paper's primary measures
    assert rows["success rate"] == (pytest.approx(0.5), pytest.approx(1 / 3), True)  # higher is better
    assert rows["TCT (s)"] == (pytest.approx(2.0), pytest.approx(3.0), True)  # successes only; lower is better
    assert rows["RMSE (N)"] == (pytest.approx(0.3), pytest.approx(0.5), True)
    assert rows["Max AE (N)"] == (pytest.approx(0.7), pytest.approx(0.6), False)
    assert (card.n_trials, card.n_earlier) == (2, 2)
    first = score_card(metrics, "off", block, [])
    assert all(before is None and better is None for _, _, before, better in first.rows)
    assert "no earlier session" in first.lines()[0]
    gain = select(["gain"])  # nearer 1 is better (a secondary measure: not on the card)
    assert score_card(gain, "on", block, earlier).rows == ()
    assert shown_blocks([card.detail(), first.detail()]) == {"on", "off"}


def test_a_simulated_study_shows_and_stores_a_card_after_each_block(tmp_path: Path, capsys) -> None:
    proto, db, out = tmp_path / "fb.toml", tmp_path / "fb.db", tmp_path / "rep"
    proto.write_text(PROTOCOL, encoding="utf-8")
    assert main(["run", "--protocol", str(proto), "--participants", "1", "--seed", "0", "--db", str(db),
                 "--jobs", "1"]) == 0
    c = sqlite3.connect(db)
    try:
        cards = c.execute("SELECT e.session_id, s.kind, e.detail FROM events e JOIN sessions s USING (session_id) "
                          "WHERE e.kind = ? ORDER BY e.session_id, e.t_s", (FEEDBACK_EVENT,)).fetchall()
        trials = c.execute("SELECT session_id, haptic_mode, rmse_n FROM trials WHERE outcome != 'aborted'").fetchall()
    finally:
        c.close()
    assert [(kind, d.split(":")[0]) for _, kind, d in cards] in (
        [("training", "on"), ("training", "off"), ("experiment", "on"), ("experiment", "off")],
        [("training", "on"), ("training", "off"), ("experiment", "off"), ("experiment", "on")])
    for sid, kind, detail in cards:  # each block's RMSE as the stored trials give it, and the training's before it
        mode = detail.split(":")[0]
        mine = [r for s, md, r in trials if s == sid and md == mode]
        assert f"RMSE (N): {sum(mine) / len(mine):.3g}" in detail
        if kind == "experiment":
            before = [r for s, md, r in trials if s != sid and md == mode]
            assert "1 earlier session" in detail and f"your earlier sessions {sum(before) / len(before):.3g}" in detail
            assert math.isfinite(sum(before))
        else:
            assert "0 earlier sessions" in detail and "no earlier session" in detail
    capsys.readouterr()
    assert main(["report", "--db", str(db), "--out", str(out)]) == 0
    page = (out / "report.html").read_text(encoding="utf-8")
    assert "<b>Feedback to the trainee.</b> An intervention" in page and "4 cards were shown in 2 sessions" in page
