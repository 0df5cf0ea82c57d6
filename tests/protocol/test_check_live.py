"""``check`` on a study being written (issue 42, class 3): one snapshot, and a live session's unwritten tail is not
damage -- silent over every check while a ``run`` writes, and still finding what is wrong."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

from protocol.storage import EmptyDatabase, StudyDatabase
from protocol.storage.audit import audit_database
from tests.cli_subprocess import CLI, tiny_protocol


def _check(db_path: Path) -> tuple[list[str], bool] | None:
    try:
        db = StudyDatabase(str(db_path), readonly=True, check=False)
    except EmptyDatabase:
        return None  # the run has not stored its schema yet
    try:
        writers = db.sessions_being_written()
        return audit_database(db.conn, str(db_path), writers=writers).problems, bool(writers)
    finally:
        db.close()


def test_check_is_silent_on_a_healthy_study_while_it_is_written(tmp_path: Path) -> None:
    (tmp_path / "tiny.toml").write_text(tiny_protocol("live", max_trial_s=3.0, hold_s=0.5), encoding="utf-8")
    env = {k: v for k, v in os.environ.items() if not k.startswith("HAPTIC_STUDY")}
    db = tmp_path / "live.db"
    run = subprocess.Popen([*CLI, "run", "--participants", "4", "--jobs", "1", "--protocol", "tiny.toml",
                            "--db", "live.db"], cwd=tmp_path, env=env, stdout=subprocess.DEVNULL,
                           stderr=subprocess.PIPE, text=True)
    checks = live = 0
    try:
        while run.poll() is None or checks < 50:
            if not db.exists() or db.stat().st_size == 0:
                continue  # the run has not created its schema yet
            found = _check(db)
            if found is None:
                continue
            problems, was_live = found
            assert problems == [], f"check {checks + 1} (live: {was_live}): {problems}"
            checks += 1
            live += was_live
    finally:
        run.wait(timeout=600)
    assert run.returncode == 0, run.stderr.read() if run.stderr else ""
    assert live >= 5, f"only {live} of {checks} checks ran while the study was written: the test proves little"
