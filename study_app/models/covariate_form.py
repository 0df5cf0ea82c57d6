"""The setup form's questions about the participant: the protocol's covariates, asked when a participant is
registered (their first session), shown read-only afterwards.

The form is built from the protocol's ``[[covariates]]`` (none by default: the paper's protocol asks nothing about
the person).  Each answer is checked as the engine checks it (:func:`protocol.study.covariates.checked_values`): a
value outside its declaration, or a required one left empty, is the form's error -- one line naming the
covariate, the value and what is allowed -- and Start waits.  A participant who is registered already (the
database holds their covariates, or any session of theirs) is not asked again: their stored values are shown.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from protocol.study.covariates import Covariate, CovariateError, checked_values
from study_app.models import Emitter

__all__ = ["CovariateForm"]


@dataclass
class CovariateForm:
    """What the form asks about the participant, what was typed, and what the database holds of them.

    ``registered`` is the participant's stored covariates when they are registered already (None: a new
    participant, who is asked).  ``changed`` fires when the questions change (another protocol, another
    participant): the view rebuilds its fields.
    """

    declared: tuple[Covariate, ...] = ()
    texts: dict[str, str] = field(default_factory=dict)
    registered: dict[str, Any] | None = None
    changed: Emitter = field(default_factory=Emitter)

    def set_questions(self, declared: Sequence[Covariate], registered: dict[str, Any] | None) -> None:
        """The protocol's covariates and the participant's stored ones (None: not registered yet)."""
        declared = tuple(declared)
        if declared == self.declared and registered == self.registered:
            return
        names = {c.name for c in declared}
        self.texts = {k: v for k, v in self.texts.items() if k in names}  # what was typed stays for the same names
        self.declared, self.registered = declared, registered
        self.changed.emit()

    def set_text(self, name: str, text: str) -> None:
        """The experimenter typed or chose ``text`` for covariate ``name``."""
        self.texts[name] = text

    def clear(self) -> None:
        """A new participant: nothing typed."""
        if self.texts:
            self.texts = {}
            self.changed.emit()

    @property
    def asking(self) -> bool:
        """The form asks (a protocol with covariates, a participant not registered yet)."""
        return bool(self.declared) and self.registered is None

    def error(self) -> str:
        """Why the answers cannot be stored ("" when they can, or nothing is asked): a line for each covariate
        whose answer the engine would refuse, naming it, the value and what is allowed."""
        if not self.asking:
            return ""
        lines = []
        for c in self.declared:  # each alone: every wrong answer is said at once, not the first only
            try:
                checked_values((c,), {c.name: self.texts.get(c.name, "")})
            except CovariateError as exc:
                lines.append(str(exc))
        return "\n".join(lines)

    def typed(self) -> dict[str, Any]:
        """The answers as stored (typed), when they are valid ({} else)."""
        try:
            return dict(checked_values(self.declared, self.values()))
        except CovariateError:
            return {}

    def values(self) -> dict[str, str]:
        """What a start sends: the answers given (none for a registered participant)."""
        return {k: v.strip() for k, v in self.texts.items() if v.strip()} if self.asking else {}

    def registered_text(self) -> str:
        """The stored values in words (``group = surgeon · years_experience = 14``; "" when none)."""
        if not self.registered:
            return ""
        units = {c.name: c.unit for c in self.declared}
        return " · ".join(f"{k} = {v}{' ' + units[k] if units.get(k) else ''}" for k, v in self.registered.items())
