"""A corpus of bad inputs through the real command line: one line on stderr, the right exit status, nothing touched.

Every case runs the ``haptic-study`` console script in a subprocess, in a folder of its
own holding the files it needs (protocol and hardware files, study databases
good, damaged, foreign, newer and read-only, FIFOs and links, small full or
read-only tmpfs mounts).  Each must end with its exit status (2: refused; 1: the
file system failed while writing), exactly one line on stderr naming what is
wrong, no traceback anywhere, every file, link and folder that existed before
unchanged after (bytes, mode, link target), and nothing new (other than SQLite's
transient ``-wal``/``-shm`` beside a database that was already there).

The cases (tests/bad_inputs_corpus.py: files, arguments, databases;
tests/bad_outputs_corpus.py: outputs, links, permissions, file systems) run
concurrently (they are subprocesses, mostly waiting on Python's start-up), once
per session, and each case is its own test.  The mounts need root: where the
tests may not mount, those cases skip and say why.
"""

from __future__ import annotations

import errno
import hashlib
import os
import pwd
import shutil
import sqlite3
import stat
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import pytest
from bad_inputs_corpus import CASES as INPUT_CASES
from bad_inputs_corpus import ROOT, TINY_PROTOCOL, Case
from bad_outputs_corpus import CASES as OUTPUT_CASES
from mounts import can_mount, mount_tmpfs, unmount

SQLITE_COMPANIONS = ("-wal", "-shm", "-journal")
_SCRIPT = Path(sys.executable).with_name("haptic-study")
#: The command as users run it: the installed console script (``python -m study_app.cli.main`` where there is none).
CLI = [str(_SCRIPT)] if _SCRIPT.is_file() else [sys.executable, "-m", "study_app.cli"]
CASES: list[Case] = [*INPUT_CASES, *OUTPUT_CASES]
#: A case that has not answered by then hung (the slowest take a few seconds on a loaded 2-core machine).
CASE_TIMEOUT_S = 180
#: One worker runs the whole corpus (pytest runs with --dist loadfile: a module in one worker, its fixture once).
_MOUNT = can_mount()


@dataclass
class Outcome:
    returncode: int
    stdout: str
    stderr: str
    before: dict[str, str]
    after: dict[str, str]
    folder: str  # the case's folder ({d})
    seconds: float = 0.0  # the command's wall time (on a loaded machine: for finding the slow cases only)


def _snapshot(d: Path) -> dict[str, str]:
    """Every entry under ``d`` (links not followed): relative path -> what it is (mode and bytes, or its target)."""
    out = {}
    for p in sorted(d.rglob("*")):
        st = p.lstat()
        mode = f"{stat.S_IMODE(st.st_mode):o}"
        if stat.S_ISLNK(st.st_mode):
            out[str(p.relative_to(d))] = f"link -> {os.readlink(p)}"
        elif stat.S_ISREG(st.st_mode):
            out[str(p.relative_to(d))] = f"file {mode} {hashlib.sha256(p.read_bytes()).hexdigest()}"
        elif stat.S_ISDIR(st.st_mode):
            out[str(p.relative_to(d))] = f"folder {mode}"
        else:
            out[str(p.relative_to(d))] = f"{stat.S_IFMT(st.st_mode):o} {mode}"
    return out


def _unprivileged() -> tuple[int, int] | None:
    """(uid, gid) to run a command under when this process is root (root writes read-only files)."""
    if os.geteuid() != 0:
        return None
    try:
        pw = pwd.getpwnam("nobody")
    except KeyError:
        return None
    return pw.pw_uid, pw.pw_gid


def _fill(where: Path, free_kib: int) -> None:
    """Take the space of a file system until ``free_kib`` KiB are left (0: until it is full)."""
    st = os.statvfs(where)
    size = max(0, st.f_bavail * st.f_frsize - free_kib * 1024)
    with open(where / "filler", "wb", buffering=0) as f:
        try:
            f.write(b"\0" * size)
            if free_kib == 0:
                while True:
                    f.write(b"\0" * 4096)
        except OSError as exc:
            if exc.errno != errno.ENOSPC:
                raise


def _mount(case: Case, d: Path, good: Path) -> list[Path]:
    mounted = []
    for name, m in case.mounts.items():
        where = d / name
        where.mkdir()
        mount_tmpfs(where, m.size_kib)
        mounted.append(where)
        for fname, build in m.files.items():
            build(where / fname, good)
        if m.free_kib is not None:
            _fill(where, m.free_kib)
        if m.read_only:
            subprocess.run(["mount", "-o", "remount,ro", str(where)], check=True, capture_output=True)
    return mounted


def _run_case(case: Case, d: Path, good: Path) -> Outcome:
    for name, build in case.files.items():
        build(d / name, good)
    mounted = _mount(case, d, good)
    user = None
    if case.read_only or case.as_nobody:
        if case.read_only:
            (d / case.read_only).chmod(0o444)
        user = _unprivileged()
        if user is not None:
            d.chmod(0o755)  # nobody can read the folder, and not write to it
    try:
        before = _snapshot(d)
        env = {k: v for k, v in os.environ.items()
               if not k.startswith("HAPTIC_STUDY") and k not in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM")}
        env["PYTHONDONTWRITEBYTECODE"] = "1"
        args = [a.replace("{d}", str(d)) for a in case.args]
        t0 = time.perf_counter()
        try:
            proc = subprocess.run(
                [*CLI, *args], capture_output=True, text=True, timeout=CASE_TIMEOUT_S, cwd=ROOT, env=env,
                **({"user": user[0], "group": user[1], "extra_groups": []} if user else {}),
            )
        except subprocess.TimeoutExpired:  # a hang (a FIFO read for ever) fails its own case, not the corpus
            return Outcome(-9, "", f"Traceback: no answer within {CASE_TIMEOUT_S} s (it hung)", before,
                           _snapshot(d), str(d))
        return Outcome(proc.returncode, proc.stdout, proc.stderr, before, _snapshot(d), str(d),
                       time.perf_counter() - t0)
    finally:
        for where in mounted:
            unmount(where)


@pytest.fixture(scope="module")
def outcomes() -> Iterator[dict[str, Outcome]]:
    """Every case run once, three at a time; the good study database is made first by the real command."""
    base = Path(tempfile.mkdtemp(prefix="haptic-bad-inputs-"))
    base.chmod(0o755)  # the read-only case may run as an unprivileged user
    try:
        made = base / "made"
        made.mkdir()
        (made / "tiny.toml").write_text(TINY_PROTOCOL, encoding="utf-8")
        good = made / "good.db"
        r = subprocess.run(
            [*CLI, "run", "--participants", "1", "--seed", "0", "--jobs", "1",
             "--db", str(good), "--protocol", str(made / "tiny.toml")],
            capture_output=True, text=True, timeout=300, cwd=ROOT,
        )
        assert r.returncode == 0, r.stderr
        c = sqlite3.connect(good)
        c.execute("PRAGMA wal_checkpoint(TRUNCATE)")  # everything in the one file: copies of it are complete
        c.close()
        dirs = {}
        runnable = [c for c in CASES if not (c.mounts and _MOUNT)]
        for i, case in enumerate(runnable):
            dirs[case.id] = base / f"case{i:03d}"
            dirs[case.id].mkdir()
        t0 = time.perf_counter()
        with ThreadPoolExecutor(max_workers=3) as pool:
            futures = {case.id: pool.submit(_run_case, case, dirs[case.id], good) for case in runnable}
            results = {k: f.result() for k, f in futures.items()}
        print(f"\n{len(runnable)} bad-input cases in {time.perf_counter() - t0:.1f} s; the slowest:")
        for case_id, out in sorted(results.items(), key=lambda kv: -kv[1].seconds)[:12]:
            print(f"  {out.seconds:5.1f} s  {case_id}")
        yield results
    finally:
        for p in base.rglob("*"):  # read-only files and folders left by a case
            if p.is_dir() and not p.is_symlink():
                p.chmod(0o755)
        shutil.rmtree(base, ignore_errors=True)


def test_the_corpus_is_large_and_each_case_distinct() -> None:
    assert len(CASES) >= 150
    assert len({c.id for c in CASES}) == len(CASES)


@pytest.mark.parametrize(
    "case",
    [pytest.param(c, id=c.id, marks=[pytest.mark.xfail(strict=True, reason=c.xfail)] if c.xfail else [])
     for c in CASES],
)
def test_bad_input_ends_in_one_line_with_its_status_and_touches_nothing(case: Case,
                                                                     outcomes: dict[str, Outcome]) -> None:
    if case.mounts and _MOUNT:
        pytest.skip(_MOUNT)
    out = outcomes[case.id]
    assert "Traceback" not in out.stdout + out.stderr, out.stderr
    assert out.returncode == case.exit, (out.returncode, out.stderr)
    lines = out.stderr.splitlines()
    if case.exit == 1 or case.after_work:  # it did its work first: its progress lines, then the one line
        assert not [line for line in lines[:-1] if "error" in line], out.stderr
        lines = lines[-1:]
    assert len(lines) == 1, out.stderr
    assert case.says.replace("{d}", out.folder) in lines[0], lines[0]
    assert "error: " in lines[0]
    # everything that was there is as it was (bytes, mode, link target); nothing new but SQLite's own companions
    for name, what in out.before.items():
        assert out.after.get(name) == what, f"{name} was changed or removed"
    new = set(out.after) - set(out.before)
    assert all(n.endswith(SQLITE_COMPANIONS) and n[: n.rindex("-")] in out.before for n in new), sorted(new)


@pytest.mark.skipif(bool(_MOUNT), reason=_MOUNT or "mounting works")
def test_run_on_a_disk_that_fills_ends_in_one_line_and_continue_completes_the_study(tmp_path: Path) -> None:
    """The disk fills mid-study: one line, exit 1, the database intact; with room again, --continue completes it."""
    from mounts import tmpfs

    protocol = tmp_path / "tiny.toml"
    protocol.write_text(TINY_PROTOCOL, encoding="utf-8")
    with tmpfs(tmp_path / "disk", 1100) as disk:
        run = [*CLI, "run", "--participants", "8", "--seed", "0", "--jobs", "1", "--protocol", str(protocol),
               "--db", str(disk / "study.db")]
        r = subprocess.run(run, capture_output=True, text=True, timeout=300, cwd=ROOT)
        assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
        line = r.stderr.splitlines()[-1]
        assert line == (f"haptic-study: error: --db {disk / 'study.db'}: SQLite says 'database or disk is full': no "
                        "space left on the device; free some space or write to another disk; then complete the study "
                        "with the same command and --continue (what was committed is kept)")
        c = sqlite3.connect(f"file:{disk / 'study.db'}?mode=ro", uri=True)
        assert c.execute("PRAGMA quick_check").fetchone()[0] == "ok"
        done = c.execute("SELECT COUNT(*) FROM sessions WHERE status = 'completed'").fetchone()[0]
        c.close()
        assert 0 < done < 8  # part of the study was stored, and is intact
        subprocess.run(["mount", "-o", "remount,size=8m", str(disk)], check=True, capture_output=True)
        r = subprocess.run([*run, "--continue"], capture_output=True, text=True, timeout=300, cwd=ROOT)
        assert r.returncode == 0, r.stderr
        c = sqlite3.connect(f"file:{disk / 'study.db'}?mode=ro", uri=True)
        rows = c.execute("SELECT p.code, s.status, (SELECT COUNT(*) FROM trials t WHERE t.session_id = s.session_id "
                         "AND t.outcome != 'aborted') FROM sessions s JOIN participants p USING (participant_id) "
                         "ORDER BY p.code").fetchall()
        c.close()
    assert rows == [(f"P{k:02d}", "completed", 1) for k in range(1, 9)]
