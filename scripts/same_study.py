#!/usr/bin/env python3
"""Run the same seeded simulated study with another revision's code and this tree's, and compare what they stored.

    python scripts/same_study.py --reference main [--participants 3] [--seed 7] [--keep DIR]
    python scripts/same_study.py --compare A.db B.db

A behaviour-preserving change must store the same study: every table of the two databases is compared row by
row, exactly (floats by their bits, blobs -- the recorded blocks -- by their bytes).  Rows are matched by what
they are, not by their ids (participants run in parallel get their ids in any order): a participant by its code,
a session by its participant and kind, a trial by its session and index.  Left out, because they differ by
design from run to run: the wall-clock and software columns (``sessions.started_at``/``ended_at``/
``software_*``, ``participants.created_at``), the ``leases`` table, and the runner's random token in each
recording's snapshot (it finds the snapshot in the loop's log; the rest of the snapshot is compared).

The reference's code is taken with ``git archive REV`` into a temporary folder and run with this tree's
interpreter (so the same libraries).  Exit status 0 when every table is identical, 1 otherwise.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import re
import sqlite3
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
SKIP_COLUMNS = {"sessions": {"started_at", "ended_at", "software_version", "software_commit", "software_dirty"},
                "participants": {"created_at"},
                # a block's checksum covers its place, session id included, and participants run in parallel
                # create their sessions in any order: the data are compared here, the checksums by `check`
                "session_blocks": {"crc32"}, "arm_blocks": {"crc32"}}
SKIP_TABLES = {"leases", "sqlite_sequence"}
_TOKEN = re.compile(r'^\{"token": \d+')


def _exact(value: Any) -> Any:
    if isinstance(value, str) and _TOKEN.match(value):
        return _TOKEN.sub('{"token": T', value)  # recordings.snapshot_json: the runner's random token
    return value.hex() if isinstance(value, float) else value


def table_digest(path: str, table: str) -> tuple[int, str]:
    """A table's rows (ids named by what they are), as a count and a SHA-256 of their exact values."""
    c = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        who = dict(c.execute("SELECT participant_id, code FROM participants"))
        sess = {s: (who[p], k) for s, p, k in c.execute("SELECT session_id, participant_id, kind FROM sessions")}
        name: dict[str, Callable[[Any], Any]] = {
            "participant_id": who.get, "session_id": sess.get,
            "trial_id": lambda t: (sess[t // 1_000_000], t % 1_000_000),
        }
        cols = [r[1] for r in c.execute(f"PRAGMA table_info({table})") if r[1] not in SKIP_COLUMNS.get(table, ())]
        rows = sorted((tuple(_exact(name[k](v) if k in name and v is not None else v)
                             for k, v in zip(cols, r, strict=True))
                       for r in c.execute(f"SELECT {', '.join(cols)} FROM {table}")), key=repr)
    finally:
        c.close()
    return len(rows), hashlib.sha256(repr((cols, rows)).encode()).hexdigest()


def compare(a: str, b: str) -> bool:
    """Print each table's verdict; True when all are identical."""
    c = sqlite3.connect(f"file:{a}?mode=ro", uri=True)
    tables = [r[0] for r in c.execute("SELECT name FROM sqlite_master WHERE type = 'table' ORDER BY name")]
    c.close()
    same = True
    for t in tables:
        if t in SKIP_TABLES:
            continue
        (na, ha), (nb, hb) = table_digest(a, t), table_digest(b, t)
        ok = (na, ha) == (nb, hb)
        same &= ok
        print(f"  {t:16s} {na:8d} rows  " + (f"identical (sha256 {ha[:16]})" if ok else f"DIFFERENT ({nb} rows)"))
    print("every table identical" if same else "the databases differ")
    return same


def run_study(code: Path, db: str, participants: int, seed: int) -> None:
    """``haptic-study run`` with the code in ``code`` (this interpreter, ``code`` first on the path)."""
    env = dict(os.environ, PYTHONPATH=str(code))
    cmd = [sys.executable, "-c", "import sys; from study_app.cli.main import main; sys.exit(main())",
           "run", "--participants", str(participants), "--seed", str(seed), "--db", db]
    print(f"running the study with {code} ...", flush=True)
    subprocess.run(cmd, cwd=code, env=env, check=True, stdout=subprocess.DEVNULL)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reference", metavar="REV", help="git revision to compare with (e.g. main)")
    ap.add_argument("--participants", type=int, default=3)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--keep", metavar="DIR", help="keep the two databases in DIR (default: a temporary folder)")
    ap.add_argument("--compare", nargs=2, metavar="DB", help="only compare two databases")
    args = ap.parse_args()
    if args.compare:
        return 0 if compare(*args.compare) else 1
    if not args.reference:
        ap.error("give --reference REV or --compare A.db B.db")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args.keep or tmp)
        out.mkdir(parents=True, exist_ok=True)
        ref_code = Path(tmp) / "reference"
        ref_code.mkdir()
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", args.reference], check=True, capture_output=True)
        subprocess.run(["tar", "-x", "-C", str(ref_code)], input=archive.stdout, check=True)
        dbs = [str(out / f"{which}.db") for which in ("reference", "this")]
        if any(os.path.exists(db) for db in dbs):
            print(f"same_study: {out} holds reference.db or this.db already: give another --keep", file=sys.stderr)
            return 2
        run_study(ref_code, dbs[0], args.participants, args.seed)
        run_study(ROOT, dbs[1], args.participants, args.seed)
        return 0 if compare(*dbs) else 1


if __name__ == "__main__":
    raise SystemExit(main())
