"""A corpus of bad inputs through the real command line: one line on stderr, the right exit status, nothing touched.

Every case runs the ``haptic-study`` command in a process of its own, in a folder of its
own holding the files it needs (protocol and hardware files, study databases
good, damaged, foreign, newer and read-only, FIFOs and links, small full or
read-only tmpfs mounts).  Each must end with its exit status (2: refused; 1: the
file system failed while writing), exactly one line on stderr naming what is
wrong, no traceback anywhere, every file, link and folder that existed before
unchanged after (bytes, mode, link target), and nothing new (other than SQLite's
transient ``-wal``/``-shm`` beside a database that was already there).

The cases (tests/bad_inputs_corpus.py: files, arguments, databases;
tests/bad_outputs_corpus.py: outputs, links, permissions, file systems) run
once per session, three at a time, each a fork of one process that imported the
command line once (tests/cli_zygote.py: a new interpreter per case spent most of
the corpus's time importing), and each case is its own test.  The cases of
:data:`END_TO_END` also run through the installed console script, as a user types
them, and must end exactly as their forks did.  The mounts need root: where the
tests may not mount, those cases skip and say why.
"""

from __future__ import annotations

import errno
import hashlib
import json
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
#: The cases run end to end through the installed script too (a new interpreter, as a user types them): a refusal
#: of argparse, of a protocol, a hardware file, a database, a FIFO, a folder the user may not write, a full disk
#: mid-write, and one after the work; :func:`test_a_forked_command_ends_as_the_script_does` compares them.
END_TO_END = frozenset({
    "no command", "protocol: version = true", "hardware: no such file", "database: damaged, sessions",
    "protocol: a FIFO", "report --out a folder it may not write", "full while writing: plot-trial",
    "full: export, larger than the space left",
})


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


@dataclass
class _Prepared:
    """A case's folder made ready: its files and mounts in place, the user it runs as, what was there before."""

    case: Case
    folder: Path
    args: list[str]
    user: tuple[int, int] | None
    mounted: list[Path]
    before: dict[str, str]


def _prepare(case: Case, d: Path, good: Path) -> _Prepared:
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
    args = [a.replace("{d}", str(d)) for a in case.args]
    return _Prepared(case, d, args, user, mounted, _snapshot(d))


def _command_env() -> dict[str, str]:
    """The environment a command gets: none of ours (no worker count, no display), no byte-code written."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith("HAPTIC_STUDY") and k not in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM")}
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    return env


def _hung(p: _Prepared) -> Outcome:
    return Outcome(-9, "", f"Traceback: no answer within {CASE_TIMEOUT_S} s (it hung)", p.before, _snapshot(p.folder),
                   str(p.folder))


def _run_script(p: _Prepared) -> Outcome:
    """The case through the installed console script, in a new interpreter (the end-to-end cases)."""
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(
            [*CLI, *p.args], capture_output=True, text=True, timeout=CASE_TIMEOUT_S, cwd=ROOT, env=_command_env(),
            **({"user": p.user[0], "group": p.user[1], "extra_groups": []} if p.user else {}),
        )
    except subprocess.TimeoutExpired:  # a hang (a FIFO read for ever) fails its own case, not the corpus
        return _hung(p)
    return Outcome(proc.returncode, proc.stdout, proc.stderr, p.before, _snapshot(p.folder), str(p.folder),
                   time.perf_counter() - t0)


def _run_forked(prepared: list[_Prepared], scratch: Path) -> dict[str, Outcome]:
    """The cases as forks of one process that imported the command line once (tests/cli_zygote.py), 3 at once."""
    requests = [{"id": p.case.id, "args": p.args, "cwd": str(ROOT), "env": _command_env(),
                 "user": list(p.user) if p.user else None, "out": str(scratch / f"{i}.out"),
                 "err": str(scratch / f"{i}.err"), "timeout_s": CASE_TIMEOUT_S} for i, p in enumerate(prepared)]
    zygote = subprocess.run([sys.executable, str(Path(__file__).with_name("cli_zygote.py")), "3"],
                            input=json.dumps(requests), capture_output=True, text=True, cwd=ROOT, env=_command_env(),
                            timeout=CASE_TIMEOUT_S + 60 * len(requests))
    assert zygote.returncode == 0, zygote.stderr
    ended = {r["id"]: r for r in map(json.loads, zygote.stdout.splitlines())}
    assert set(ended) == {p.case.id for p in prepared}, zygote.stdout
    results = {}
    for p, req in zip(prepared, requests, strict=True):
        r = ended[p.case.id]
        if r["returncode"] == -9:
            results[p.case.id] = _hung(p)
            continue
        results[p.case.id] = Outcome(r["returncode"], Path(req["out"]).read_text(errors="replace"),
                                     Path(req["err"]).read_text(errors="replace"), p.before, _snapshot(p.folder),
                                     str(p.folder), r["seconds"])
    return results


def _make_good_database(made: Path) -> Path:
    """The good study database, made by the real command (a success, end to end) and checkpointed into one file."""
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
    return good


def _run_corpus(base: Path, good: Path) -> tuple[dict[str, Outcome], dict[str, Outcome]]:
    """Every runnable case forked, and the end-to-end cases once more through the console script (in folders of
    their own, prepared the same way): (forked outcomes, script outcomes)."""
    runnable = [c for c in CASES if not (c.mounts and _MOUNT)]
    twice = [c for c in runnable if c.id in END_TO_END]
    prepared: list[_Prepared] = []
    try:
        for i, case in enumerate([*runnable, *twice]):
            d = base / f"case{i:03d}"
            d.mkdir()
            prepared.append(_prepare(case, d, good))
        scratch = base / "streams"
        scratch.mkdir()
        forked = _run_forked(prepared[:len(runnable)], scratch)
        script = {p.case.id: _run_script(p) for p in prepared[len(runnable):]}
        return forked, script
    finally:
        for p in prepared:
            for where in p.mounted:
                unmount(where)


@pytest.fixture(scope="module")
def corpus() -> Iterator[tuple[dict[str, Outcome], dict[str, Outcome]]]:
    """Every case run once (forked, see :func:`_run_forked`), the end-to-end ones also through the script; the good
    study database is made first by the real command."""
    base = Path(tempfile.mkdtemp(prefix="haptic-bad-inputs-"))
    base.chmod(0o755)  # the read-only case may run as an unprivileged user
    try:
        made = base / "made"
        made.mkdir()
        good = _make_good_database(made)
        t0 = time.perf_counter()
        forked, script = _run_corpus(base, good)
        print(f"\n{len(forked)} bad-input cases (and {len(script)} through the script) in "
              f"{time.perf_counter() - t0:.1f} s; the slowest:")
        for case_id, out in sorted(forked.items(), key=lambda kv: -kv[1].seconds)[:12]:
            print(f"  {out.seconds:5.1f} s  {case_id}")
        yield forked, script
    finally:
        for p in base.rglob("*"):  # read-only files and folders left by a case
            if p.is_dir() and not p.is_symlink():
                p.chmod(0o755)
        shutil.rmtree(base, ignore_errors=True)


@pytest.fixture(scope="module")
def outcomes(corpus: tuple[dict[str, Outcome], dict[str, Outcome]]) -> dict[str, Outcome]:
    return corpus[0]


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
    _ends_in_one_line_and_touches_nothing(case, outcomes[case.id])


def test_a_forked_command_ends_as_the_script_does(corpus: tuple[dict[str, Outcome], dict[str, Outcome]]) -> None:
    """The end-to-end cases through the console script (a new interpreter): each passes the corpus's checks, and
    ends exactly as its fork did (status, both streams, what changed in its folder)."""
    forked, script = corpus
    by_id = {c.id: c for c in CASES}
    assert set(by_id) >= END_TO_END
    assert set(script) == {i for i in END_TO_END if not (by_id[i].mounts and _MOUNT)}
    for case_id, out in script.items():
        _ends_in_one_line_and_touches_nothing(by_id[case_id], out)
        fork = forked[case_id]
        assert out.returncode == fork.returncode, case_id
        assert out.stdout.replace(out.folder, "{d}") == fork.stdout.replace(fork.folder, "{d}"), case_id
        assert out.stderr.replace(out.folder, "{d}") == fork.stderr.replace(fork.folder, "{d}"), case_id
        assert set(out.after) - set(out.before) == set(fork.after) - set(fork.before), case_id


def _ends_in_one_line_and_touches_nothing(case: Case, out: Outcome) -> None:
    """The corpus's checks of one outcome: no traceback, its status, one line saying what it must, nothing
    changed or left behind."""
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
