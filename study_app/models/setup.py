"""Session setup: what the experimenter enters before a session, validated field by field."""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace

from protocol.config import ProtocolError, load_protocol
from protocol.storage import StorageError, validate_code
from study_app import messages as m
from study_app.models import Emitter

__all__ = ["SessionSetup", "SetupModel", "KINDS"]

KINDS = ("training", "experiment")


@dataclass(frozen=True, slots=True)
class SessionSetup:
    """The setup form's values."""

    db_path: str = ""
    code: str = ""
    participant_number: int = 1
    kind: str = "experiment"
    protocol_path: str = ""  # empty: the paper's protocol
    seed: int = 0


@dataclass
class SetupModel:
    """The form's state, its validation errors (field → message), and the resumable sessions of the database."""

    values: SessionSetup = field(default_factory=SessionSetup)
    errors: dict[str, str] = field(default_factory=dict)
    resumable: list[dict[str, object]] = field(default_factory=list)
    changed: Emitter = field(default_factory=Emitter)
    resumable_changed: Emitter = field(default_factory=Emitter)

    def update(self, **kwargs: object) -> None:
        """Change fields and re-validate."""
        self.values = replace(self.values, **kwargs)  # type: ignore[arg-type]
        self.validate()

    def validate(self) -> dict[str, str]:
        """Check every field as the engine will; returns (and stores) the errors."""
        v = self.values
        errors: dict[str, str] = {}
        if not v.db_path.strip():
            errors["db_path"] = "study database: choose a file (it is created if missing)"
        else:
            p = os.path.abspath(v.db_path)
            parent = os.path.dirname(p)
            if os.path.isdir(p):
                errors["db_path"] = f"study database = {v.db_path!r}: is a folder, not a file"
            elif not os.path.isdir(parent):
                errors["db_path"] = f"study database = {v.db_path!r}: the folder {parent} does not exist"
            elif not os.access(p if os.path.exists(p) else parent, os.W_OK):
                errors["db_path"] = f"study database = {v.db_path!r}: not writable"
        try:
            validate_code(v.code)
        except StorageError as exc:
            errors["code"] = str(exc)
        if v.kind not in KINDS:
            errors["kind"] = f"session kind = {v.kind!r}: allowed values are training, experiment"
        if v.protocol_path.strip():
            try:
                load_protocol(v.protocol_path)
            except ProtocolError as exc:
                errors["protocol_path"] = str(exc)
        if not (isinstance(v.seed, int) and v.seed >= 0):
            errors["seed"] = f"seed = {v.seed!r}: must be a whole number ≥ 0"
        if not (isinstance(v.participant_number, int) and v.participant_number >= 1):
            errors["participant_number"] = f"participant number = {v.participant_number!r}: must be a whole number ≥ 1"
        self.errors = errors
        self.changed.emit()
        return errors

    @property
    def valid(self) -> bool:
        """True when every field passed :meth:`validate`."""
        return not self.errors

    def start_command(self) -> m.StartSession:
        """The command that starts this session (validate first)."""
        errors = self.validate()
        if errors:
            raise ValueError("; ".join(errors.values()))
        v = self.values
        return m.StartSession(os.path.abspath(v.db_path), v.code, v.kind, v.protocol_path.strip() or None, v.seed,
                              v.participant_number)

    def set_resumable(self, sessions: list[dict[str, object]]) -> None:
        """Interrupted sessions listed by the engine."""
        self.resumable = list(sessions)
        self.resumable_changed.emit()

    @staticmethod
    def describe_resumable(s: dict[str, object]) -> str:
        """One line for the resume list."""
        return (f"session {s['session_id']}: {s['code']} {s['kind']}, {s['trials_done']}/{s['trials_total']} trials "
                f"stored, started {str(s['started_at'])[:16].replace('T', ' ')}")
