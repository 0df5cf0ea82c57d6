"""The participants who withdrew (``haptic-study withdraw``), as the report states them.

A withdrawal erased the participant's data from the study database and left a record of it (the code, the time,
the reason and the counts removed; :mod:`protocol.storage.withdrawal`).  Nothing of theirs is analysed, because
nothing of theirs is left; the report says so, and says that the remaining participants were not renumbered: each
keeps the participant number, and so the seeded schedule and counterbalancing position, they were run with.
"""

from __future__ import annotations

import html
import os
from collections.abc import Sequence
from dataclasses import asdict

import pandas as pd

from analysis.reading.errors import AnalysisError
from analysis.reading.load import StudyData
from protocol.storage import StorageError, StudyReader
from protocol.study.labels import plural

__all__ = ["study_withdrawals", "withdrawals_html"]


def study_withdrawals(databases: Sequence[str | os.PathLike[str]]) -> pd.DataFrame:
    """Every withdrawal recorded in the study's databases: one row each, ``database`` first, oldest first."""
    rows = []
    for path in databases:
        try:
            reader = StudyReader(path, check=False)  # (load_study checked the file)
        except StorageError as exc:
            raise AnalysisError(str(exc)) from None
        with reader:
            rows += [{"database": str(path), **asdict(w)} for w in reader.withdrawals()]
    return pd.DataFrame(rows, columns=["database", "code", "withdrawn_at", "reason", "removed_sessions",
                                       "removed_trials", "removed_events", "removed_blocks", "removed_records",
                                       "removed_samples"])


def _first_modes(study: StudyData) -> pd.Series:
    """The haptic mode each remaining participant's experiment began with (their counterbalancing position)."""
    exp = study.trials[study.trials["session_kind"] == "experiment"].sort_values(["session_id", "trial_index"])
    return exp.drop_duplicates("participant_code").set_index("participant_code")["haptic_mode"]


def withdrawals_html(frame: pd.DataFrame, study: StudyData) -> str:
    """The report's section on withdrawals ("" when nobody withdrew)."""
    if frame.empty:
        return ""
    n = len(frame)
    who = "; ".join(f"{html.escape(str(r.code))} ({html.escape(str(r.withdrawn_at)[:10])}: "
                    f"{html.escape(str(r.reason))})" for r in frame.itertuples())
    numbers = sorted(int(x) for x in study.sessions["participant_number"].unique())
    first = _first_modes(study).value_counts()
    began = ", ".join(f"{int(first.get(m, 0))} with haptics {m.upper()}" for m in ("on", "off"))
    rows = "".join(
        f"<tr><td>{html.escape(str(r.code))}</td><td>{html.escape(str(r.withdrawn_at)[:16].replace('T', ' '))}</td>"
        f"<td class=\"m\">{html.escape(str(r.reason))}</td><td>{int(r.removed_sessions)}</td>"
        f"<td>{int(r.removed_trials)}</td><td>{int(r.removed_records):,}</td>"
        f"<td class=\"m\">{html.escape(os.path.basename(str(r.database)))}</td></tr>"
        for r in frame.itertuples())
    return (
        f"<h2>Withdrawals</h2><p class=\"warn\">{plural(n, 'participant')} withdrew; excluded: {who}.</p>"
        f"<p>At {'their' if n > 1 else 'the participant’s'} request every record of theirs was erased from the "
        "study database (<code>haptic-study withdraw</code>): "
        "nothing of theirs is analysed in this report, and the database keeps only the code, the time, the reason "
        "and how much was removed. The counterbalancing of the remaining participants is unchanged: nobody was "
        "renumbered or re-assigned, each keeps the participant number, and so the seeded schedule, they were run "
        f"with (numbers {', '.join(map(str, numbers))}); their experiments began {began}.</p>"
        '<div class="scroll"><table><thead><tr><th>code</th><th>withdrawn (UTC)</th><th>reason</th>'
        "<th>sessions removed</th><th>trials removed</th><th>1 kHz records removed</th><th>database</th></tr>"
        f"</thead><tbody>{rows}</tbody></table></div>"
    )
