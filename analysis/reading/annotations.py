"""What a study records beside its trials, read into tidy tables: who the participants are, the experimenter's
notes and the questionnaires' answers (:mod:`protocol.storage.annotations`), merged over the study's databases.

Each table is empty (with its columns) when the study has none: the paper's protocol declares no covariate and no
questionnaire, and its report is what it was (no column, no file added).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import dataclass

import pandas as pd

from protocol.storage import StorageError, StudyReader
from protocol.storage.annotations import answers, covariates_by_code, notes
from protocol.study.config import protocol_from_dict
from protocol.study.covariates import Covariate
from protocol.study.groups import GroupDesign
from protocol.study.questionnaires import Questionnaire

__all__ = ["ANSWER_COLUMNS", "NOTE_COLUMNS", "Annotations", "read_annotations"]

#: The columns of :attr:`Annotations.notes` (notes.csv).
NOTE_COLUMNS = ("participant_code", "session_id", "trial_number", "t_s", "written_after", "deviation", "text",
                "written_at", "database")
#: The columns of :attr:`Annotations.answers` (one row per answered question).
ANSWER_COLUMNS = ("participant_code", "participant_number", "session_id", "questionnaire", "kind", "block", "item",
                  "rating", "choice", "answered_at_s", "database")


@dataclass(frozen=True, slots=True)
class Annotations:
    """Covariates (one row per participant: ``participant_code`` and a column per declared covariate), the notes
    (:data:`NOTE_COLUMNS`), the answers (:data:`ANSWER_COLUMNS`), and the declarations they were made under: the
    covariates and questionnaires of the studies' protocols, by name, first declared first."""

    covariates: pd.DataFrame
    notes: pd.DataFrame
    answers: pd.DataFrame
    declared: tuple[Covariate, ...]
    questionnaires: tuple[Questionnaire, ...]
    #: The between-group design of the studies' protocols (the first declared; None: no ``[groups]``).
    groups: GroupDesign | None = None


def _declarations(db: StudyReader) -> tuple[list[Covariate], list[Questionnaire], GroupDesign | None]:
    covs: dict[str, Covariate] = {}
    qs: dict[str, Questionnaire] = {}
    groups: GroupDesign | None = None
    for s in db.sessions():
        try:
            p = protocol_from_dict(json.loads(s.protocol_json), f"session {s.session_id} protocol")
        except ValueError:
            continue  # (load_study refuses such a protocol with its own line)
        for c in p.covariates:
            covs.setdefault(c.name, c)
        for q in p.questionnaires:
            qs.setdefault(q.name, q)
        groups = groups or p.groups
    return list(covs.values()), list(qs.values()), groups


def read_annotations(paths: Sequence[str | os.PathLike[str]]) -> Annotations:
    """Read the covariates, notes and answers of every database of a study (read-only)."""
    cov_rows: list[dict[str, object]] = []
    note_rows: list[tuple[object, ...]] = []
    answer_rows: list[tuple[object, ...]] = []
    declared: dict[str, Covariate] = {}
    kinds: dict[str, Questionnaire] = {}
    grouping: GroupDesign | None = None
    for path in paths:
        try:
            db = StudyReader(path, check=False)
        except StorageError:
            continue  # (load_study names it)
        try:
            base = os.path.basename(str(path))
            covs, qs, groups = _declarations(db)
            grouping = grouping or groups
            for c in covs:
                declared.setdefault(c.name, c)
            for declared_q in qs:
                kinds.setdefault(declared_q.name, declared_q)
            sessions = {s.session_id: s for s in db.sessions()}
            for code, values in covariates_by_code(db.conn).items():
                cov_rows.append({"participant_code": code, **values})
            for n in notes(db.conn):
                s = sessions.get(n.session_id)
                note_rows.append((s.code if s else "", n.session_id,
                                  None if n.trial_index is None else n.trial_index + 1, n.t_s, n.t_s is None,
                                  n.deviation, n.text, n.written_at, base))
            for a in answers(db.conn):
                s = sessions.get(a.session_id)
                kind = kinds[a.questionnaire].kind if a.questionnaire in kinds else ""
                answer_rows.append((s.code if s else "", s.participant_number if s else None, a.session_id,
                                    a.questionnaire, kind, a.block, a.item, a.rating, a.choice,
                                    a.answered_at_s, base))
        finally:
            db.close()
    names = list(declared)
    covariates = pd.DataFrame(cov_rows, columns=["participant_code", *names]) if cov_rows else \
        pd.DataFrame(columns=["participant_code", *names])
    return Annotations(covariates.drop_duplicates("participant_code"),
                       pd.DataFrame(note_rows, columns=list(NOTE_COLUMNS)),
                       pd.DataFrame(answer_rows, columns=list(ANSWER_COLUMNS)),
                       tuple(declared.values()), tuple(kinds.values()), grouping)
