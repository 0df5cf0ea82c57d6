"""The session's actions as the experimenter window's buttons, keys and menu trigger them, each destructive one
asked first: start (from the form; without training or without the calibration chain, each with a typed reason),
resume an interrupted session, abort the trial (with an optional reason) or the session, note, restart the engine, quit
during a session."""

from __future__ import annotations

from collections.abc import Callable

from PySide6.QtWidgets import QInputDialog, QWidget

from study_app.engine import messages as m
from study_app.gui.confirm import Confirmation
from study_app.gui.note_dialog import NoteDialog
from study_app.gui.setup_panel import QtSetupPanel
from study_app.models.app import AppModel
from study_app.models.notes import note_subjects

__all__ = ["SessionActions"]


class SessionActions:
    """Asks before a destructive action (default No; closed as No when an engine event makes it moot), then acts.

    Parameters
    ----------
    window
        The experimenter window: a typed reason is asked over it; a quit answered Yes closes it.
    model
        The app model whose controls act.
    setup_panel
        The setup form (what a start reads, and the interrupted session selected).
    question_parent
        The window a question opens over (the one the experimenter is looking at).
    save_settings
        Called after a start: the form's values are remembered.
    """

    def __init__(self, window: QWidget, model: AppModel, setup_panel: QtSetupPanel,
                 question_parent: Callable[[], QWidget], save_settings: Callable[[], None]) -> None:
        self.window = window
        self.model = model
        self.setup_panel = setup_panel
        self.question_parent = question_parent
        self.save_settings = save_settings
        #: None: destructive actions ask in a dialog bound to what it asks about (default No).  Scripted runs
        #: (the screenshot tour, benchmarks, tests) set a function that answers at once instead.
        self.confirm: Callable[[str, str], bool] | None = None
        self.questions: dict[str, Confirmation] = {}
        #: The reason a scripted run gives an abort (the dialog's field, when a person answers).
        self.scripted_reason = ""
        #: The Note dialog while it is open.
        self.note_dialog: NoteDialog | None = None
        self._quit_confirmed = False

    # -- questions -----------------------------------------------------------------------------------------
    def ask(self, key: str, title: str, text: str, on_yes: Callable[[], object], *,
            moot_when: Callable[[object], bool] | None = None, moot_text: str = "", reason: str = "") -> None:
        """Ask before a destructive action: default No, closed as No when ``moot_when`` an engine event; with
        ``reason`` (its field's placeholder) the question offers a field for an optional typed reason, which
        :attr:`Confirmation.reason` holds when ``on_yes`` runs (a scripted run: :attr:`scripted_reason`)."""
        if self.confirm is not None:
            if self.confirm(title, text):
                on_yes()
            return
        old = self.questions.pop(key, None)
        if old is not None:
            old.dismiss()
            old.box.deleteLater()
        say = (lambda: self.model.notices.notify("info", moot_text)) if moot_text else None
        q = Confirmation(self.question_parent(), title, text, on_yes, moot_when=moot_when, on_moot=say, reason=reason)
        self.questions[key] = q
        q.show()

    def event(self, ev: object) -> None:
        """An engine event: the questions it makes moot close."""
        for q in list(self.questions.values()):
            q.event(ev)

    def dismiss(self) -> None:
        """Close every open question (the window closes)."""
        for q in self.questions.values():
            q.dismiss()

    def _reason(self, title: str, prompt: str) -> str:
        """The experimenter's typed reason ("" when none was given)."""
        if self.confirm is not None:  # a scripted run answers at once
            return "scripted override" if self.confirm(title, prompt) else ""
        reason, ok = QInputDialog.getText(self.window, title, prompt)
        return reason if ok else ""

    # -- starting ------------------------------------------------------------------------------------------
    def start_session(self) -> None:
        """Space: start a session from the setup form (or resume a paused one); asks first on a warning."""
        model = self.model
        if model.actions.can("resume") and model.session.state == "paused":
            model.control.resume()
            return
        if model.session.running:
            return
        model.setup.update(db_path=self.setup_panel.db.text(), protocol_path=self.setup_panel.protocol.text())
        warnings = model.setup.warnings
        if warnings and model.actions.can("start"):
            self.ask("start", "Start anyway?", "\n\n".join(warnings.values()) + "\n\nStart the session anyway?",
                     self._start, moot_when=lambda ev: isinstance(ev, (m.SessionStarted, m.EngineStopped)))
        else:
            self._start()

    def _start(self) -> None:
        if self.model.setup.schedule.refusal and self.model.actions.can("start"):
            self.start_off_schedule()
        elif self.model.control.start():
            self.save_settings()

    def start_off_schedule(self) -> None:
        """A visit out of order or outside its window (the form's schedule says which rule): asked with a field for
        the experimenter's reason, stored as a ``deviation`` with the session as ``run --visit`` stores it."""
        setup = self.model.setup
        v = setup.values

        def start() -> None:
            asked = self.questions.get("visit_deviation")
            why = asked.reason if asked is not None and self.confirm is None else self.scripted_reason
            if not why.strip():
                self.model.notices.notify("info", "Nothing was started: a visit out of its schedule needs a reason.",
                                          "StartSession")
            elif self.model.control.start(visit_reason=why):
                self.save_settings()

        self.ask("visit_deviation", "Visit out of schedule",
                 f"Start {v.code}'s {v.part} in visit {v.visit} anyway?\n\nThe schedule refuses it: "
                 f"{setup.schedule.refusal}.\n\nThe session is stored with this deviation from the protocol and "
                 "your reason; the study report lists it.", start,
                 moot_when=lambda ev: isinstance(ev, (m.SessionStarted, m.EngineStopped)),
                 reason="Reason (required, stored as a deviation), then Yes")

    def start_with_override(self) -> None:
        """Real rig, calibration incomplete: ask for a reason, then start anyway (the reason is stored)."""
        model = self.model
        missing = model.actions.calibration_missing()
        if not missing or not model.actions.can("start"):
            return
        model.setup.update(db_path=self.setup_panel.db.text(), protocol_path=self.setup_panel.protocol.text())
        reason = self._reason("Start without calibration", model.commissioning.override_prompt())
        if reason.strip() and model.control.start(override_reason=reason):
            self.save_settings()

    def start_without_training(self) -> None:
        """An experiment for a participant without the completed training the protocol requires: only with a
        typed reason, which the engine stores as a ``deviation`` event (listed in the report)."""
        model = self.model
        missing = model.setup.training_missing
        if not missing or not model.actions.can("start_without_training"):
            return
        code = model.setup.values.code
        prompt = (f"{missing.split('. ')[0]}.\n\nStart {code}'s experiment anyway? The session is stored with "
                  "this deviation from the protocol and your reason; the study report lists it.\n\nReason:")
        reason = self._reason("Start without training", prompt)
        if not reason.strip():
            model.notices.notify("info", "Nothing was started: a start without training needs a reason.",
                                 "StartSession")
            return
        if model.control.start(training_override=reason):
            self.save_settings()

    def resume_selected(self) -> None:
        """Continue the interrupted session selected in the list."""
        sid = self.setup_panel.selected_session()
        if sid is not None and self.model.actions.can("resume_session"):
            self.model.control.resume_session(sid)

    # -- stopping ------------------------------------------------------------------------------------------
    def abort_trial(self) -> None:
        """Esc: abort the running trial after confirmation -- that trial only, however late the answer."""
        tr = self.model.session.trial
        if not self.model.actions.can("abort_trial") or tr is None:
            return
        k = tr.trial_index

        def moot(ev: object) -> bool:
            return ((isinstance(ev, m.TrialEnded) and ev.record.trial_index == k)
                    or (isinstance(ev, m.TrialStarted) and ev.trial_index != k)
                    or isinstance(ev, (m.SessionEnded, m.EngineStopped)))

        def abort() -> None:
            q = self.questions.get("abort_trial")
            why = q.reason if q is not None and self.confirm is None else self.scripted_reason
            self.model.control.abort_trial(k, why)

        self.ask("abort_trial", "Abort trial",
                 f"Abort trial {k + 1} ({tr.target_label}, haptics {tr.haptic_mode.upper()})? It is stored as aborted "
                 "and run again later.\n\nIf the trial ends before you answer, this question closes and nothing is "
                 "aborted.", abort, moot_when=moot,
                 moot_text=f"Trial {k + 1} ended before you answered: nothing was aborted.",
                 reason="Reason (optional, stored with the trial as a note), then Yes")

    def note(self, selected: int | None = None) -> None:
        """The Note dialog: a note on the session or one of its trials (the running one proposed), stored on the
        session clock; ``selected``: the trial selected in the table (its index)."""
        if not self.model.actions.can("note"):
            return
        if self.note_dialog is not None:
            self.note_dialog.raise_()
            return
        dlg = self.note_dialog = NoteDialog(self.question_parent(), note_subjects(self.model.session, selected),
                                            self.model.control.note)
        dlg.finished.connect(lambda _r: setattr(self, "note_dialog", None))
        dlg.open()

    def skip_questionnaire(self) -> None:
        """Skip the questionnaire waiting for the participant, after confirmation with an optional reason: stored as
        skipped, a deviation (moot once it is answered or the session ends)."""
        q = self.model.questionnaire
        if q.questionnaire is None or q.sent:
            return
        name, block = q.questionnaire.name, q.block
        after = "the session" if block == "session" else f"the haptics {block.upper()} block"

        def skip() -> None:
            asked = self.questions.get("skip_questionnaire")
            why = asked.reason if asked is not None and self.confirm is None else self.scripted_reason
            q.skip(why)

        self.ask("skip_questionnaire", "Skip questionnaire",
                 f"Skip the questionnaire \"{name}\" after {after}? The participant does not answer it; it is stored "
                 "as skipped, a deviation from the protocol the study report lists, and the next trial no longer "
                 "waits for it.", skip,
                 moot_when=lambda ev: (isinstance(ev, m.QuestionnaireAnswered) and (ev.questionnaire, ev.block)
                                       == (name, block)) or isinstance(ev, (m.SessionEnded, m.EngineStopped)),
                 moot_text=f"The questionnaire \"{name}\" was answered before you answered: nothing was skipped.",
                 reason="Reason (optional, stored with the deviation), then Yes")

    def abort_session(self) -> None:
        """Abort the session after confirmation (that session only)."""
        s = self.model.session.session
        if not self.model.actions.can("abort_session") or s is None:
            return
        sid = s.session_id
        self.ask("abort_session", "Abort session", self.model.session.abort_session_question(),
                 lambda: self.model.control.abort_session(sid),
                 moot_when=lambda ev: isinstance(ev, (m.SessionEnded, m.EngineStopped)),
                 moot_text=f"Session {sid} ended before you answered: nothing was aborted.")

    def restart_engine(self) -> None:
        """Restart engine: at once if it is dead; asks first if it still runs a session (a stalled loop)."""
        s = self.model.session.session
        if not self.model.actions.can("restart_engine"):
            return
        if self.model.session.running and s is not None:
            sid = s.session_id
            self.ask("restart", "Restart engine",
                     f"Restart the study engine? Session {sid} stops here: the running trial is stored as aborted if "
                     "the engine can still store it, and the session can be resumed after the restart.",
                     self.model.engine.restart,
                     moot_when=lambda ev: isinstance(ev, (m.SessionEnded, m.EngineStopped)))
        else:
            self.model.engine.restart()

    def may_quit(self) -> bool:
        """Whether the window may close now: during a session only when the experimenter says so (asked in a
        question whose Yes closes the window again)."""
        if not self.model.session.running or self._quit_confirmed:
            return True
        title = "Quit"
        text = ("A session is running. Quit anyway? A trial still running is stored as aborted and the session "
                "can be resumed later.")
        if self.confirm is not None:  # a scripted run answers at once
            return self.confirm(title, text)
        self.ask("quit", title, text, self._quit,
                 moot_when=lambda ev: isinstance(ev, (m.SessionEnded, m.EngineStopped)))
        return False

    def _quit(self) -> None:
        self._quit_confirmed = True
        self.window.close()
