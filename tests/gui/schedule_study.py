"""A short study with a schedule of visits, and a database of it whose first visit was made days ago (for the schedule
view's tests): the headless ``run --visit`` of the first visit with the storage's clock set back -- the product's
own storage, on the virtual clock, nobody waits for the days."""

from __future__ import annotations

import datetime as _dt
from pathlib import Path

import pytest
from conftest import SHORT_PROTOCOL

#: Practice and a test at baseline (day 0), the test again at the post-test (day 7 ± 1) and a retention test (day 30
#: ± 3): each part a 2-trial session of the short protocol.
VISITS = SHORT_PROTOCOL + """
[[parts]]
name = "practice"
session = "training"
[[parts]]
name = "test"
[[visits]]
name = "baseline"
day = 0
parts = ["practice", "test"]
role = "baseline"
[[visits]]
name = "post"
day = 7
window_days = 1
parts = ["test"]
role = "post"
[[visits]]
name = "retention"
day = 30
window_days = 3
parts = ["test"]
role = "retention"
"""


def first_visit_days_ago(monkeypatch: pytest.MonkeyPatch, db: Path, protocol: Path, days: int) -> None:
    """P01's first visit (baseline: practice and test) run headless into ``db``, stored as started ``days`` ago."""
    import protocol.storage.database as database
    from protocol.study.config import load_protocol
    from study_app.headless.plan_visits import VisitRequest
    from study_app.headless.study import run_visit

    then = _dt.datetime.now(_dt.UTC) - _dt.timedelta(days=days)
    with monkeypatch.context() as patch:  # the storage's wall clock, back by ``days``, for this run only
        patch.setattr(database, "now_iso", lambda: then.isoformat(timespec="milliseconds"))
        run_visit(str(db), VisitRequest("baseline", day=0), participants=1, seed=0, protocol=load_protocol(protocol),
                  clock="virtual", jobs=1)
