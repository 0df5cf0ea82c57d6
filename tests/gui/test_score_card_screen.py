"""The participant screen shows a block's score card (feedback the protocol allows) until the next trial."""

from __future__ import annotations

from study_app.engine import messages as m
from study_app.models.participant import ParticipantScreenModel


def test_the_card_is_shown_between_blocks_and_gone_at_the_next_trial() -> None:
    md = ParticipantScreenModel()
    md.apply(m.ScoreCardShown(1, "on", ("RMSE (N): 0.31   (your earlier sessions 0.42)  ▲ better",)))
    assert md.screen.headline == "Your haptics ON block"
    assert md.screen.subline == "RMSE (N): 0.31   (your earlier sessions 0.42)  ▲ better"
    assert not md.screen.show_gauge and md.screen.gauge_force_n is None  # never a live force
    md.apply(m.TrialStarted(5.0, 2, 3, 4, "GENTLE", 0.6, "off"))
    assert md.card is None and "better" not in md.screen.subline
