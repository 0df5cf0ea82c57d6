"""What the experimenter's *Note* action offers: what a note may be about, and which is proposed.

A note is about the session or one of its trials: the running trial (proposed while one runs), a trial the
experimenter selected in the table, or any trial that has ended (:func:`note_subjects`).  The note is sent with
:meth:`study_app.models.session_control.SessionControl.note` and stored by the engine on the session clock.
"""

from __future__ import annotations

from study_app.models.session import SessionModel

__all__ = ["note_subjects"]


def note_subjects(session: SessionModel, selected: int | None = None) -> tuple[list[tuple[str, int | None]], int]:
    """The choices of what a note is about -- (label, trial index; None: the session) -- and the one proposed:
    the running trial, else the trial ``selected`` in the table (its index), else the last that ended, else the
    session."""
    choices: list[tuple[str, int | None]] = [("the session", None)]
    tr = session.trial if session.phase in ("active", "cued", "answer") else None
    if tr is not None:
        choices.append((f"trial {tr.trial_index + 1} (running: {tr.target_label}, haptics {tr.haptic_mode.upper()})",
                        tr.trial_index))
    for row in reversed(session.table.rows):
        choices.append((f"trial {row.trial_index + 1} ({row.target_label}, haptics {str(row.haptic_mode).upper()}, "
                        f"{row.outcome})", row.trial_index))
    indices = [i for _, i in choices]
    proposed = (tr.trial_index if tr is not None else selected if selected in indices
                else session.table.rows[-1].trial_index if session.table.rows else None)
    return choices, indices.index(proposed)
