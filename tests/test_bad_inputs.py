"""A corpus of bad inputs through the real command line: exit 2, one line on stderr, nothing touched.

Every case runs the ``haptic-study`` console script in a subprocess, in a folder of its
own holding the files it needs (protocol and hardware files, study databases
good, damaged, foreign, newer and read-only).  Each must end with exit status
2, exactly one line on stderr naming what is wrong, no traceback anywhere, every
file that existed before byte-identical after, and no new file (other than
SQLite's transient ``-wal``/``-shm`` beside a database that was already there).

The cases run concurrently (they are subprocesses, mostly waiting on Python's
start-up), once per session, and each case is its own test.
"""

from __future__ import annotations

import hashlib
import os
import pwd
import random
import shutil
import sqlite3
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_PROTOCOL = (ROOT / "protocol" / "default.toml").read_text(encoding="utf-8")
EXAMPLE_HARDWARE = (ROOT / "hardware.example.toml").read_text(encoding="utf-8")
#: A one-trial study without training: the good database is made by the real command in about a second.
TINY_PROTOCOL = """name = "tiny"
[[targets]]
label = "GENTLE"
force_n = 0.6
[design]
modes = ["on"]
trials_per_cell = 1
[trial]
max_trial_s = 2.0
pause_s = 0.0
[training]
enabled = false
"""
SQLITE_COMPANIONS = ("-wal", "-shm", "-journal")
_SCRIPT = Path(sys.executable).with_name("haptic-study")
#: The command as users run it: the installed console script (``python -m study_app.cli`` where there is none).
CLI = [str(_SCRIPT)] if _SCRIPT.is_file() else [sys.executable, "-m", "study_app.cli"]

Builder = Callable[[Path, Path], None]  # (file to write, the good database to copy from)


def _text(content: str | bytes) -> Builder:
    def build(path: Path, good: Path) -> None:
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content, encoding="utf-8")

    return build


def _variant(base: str, old: str, new: str) -> Builder:
    """``base`` with exactly one occurrence of ``old`` replaced by ``new``."""
    assert base.count(old) == 1, f"{old!r} must occur exactly once"
    return _text(base.replace(old, new))


def protocol(old: str, new: str) -> Builder:
    return _variant(DEFAULT_PROTOCOL, old, new)


def hardware(old: str, new: str) -> Builder:
    return _variant(EXAMPLE_HARDWARE, old, new)


def good_db(path: Path, good: Path) -> None:
    shutil.copyfile(good, path)


def damaged_db(path: Path, good: Path) -> None:
    """The good database with 8 KiB of random bytes written over its middle (the samples' pages)."""
    data = bytearray(good.read_bytes())
    mid = len(data) // 2
    data[mid:mid + 8192] = random.Random(11).randbytes(8192)
    path.write_bytes(bytes(data))


def foreign_db(path: Path, good: Path) -> None:
    c = sqlite3.connect(path)
    c.execute("CREATE TABLE inventory (item TEXT, count INTEGER)")
    c.execute("INSERT INTO inventory VALUES ('forceps', 3)")
    c.commit()
    c.close()


def newer_db(path: Path, good: Path) -> None:
    shutil.copyfile(good, path)
    c = sqlite3.connect(path)
    c.execute("PRAGMA user_version = 99")
    c.close()


def folder(path: Path, good: Path) -> None:
    path.mkdir()
    (path / "notes.txt").write_text("a folder, not a database\n", encoding="utf-8")


@dataclass(frozen=True)
class Case:
    """One bad input: the command (``{d}`` is the case's folder), the files it finds, and what the line says."""

    id: str
    args: tuple[str, ...]
    says: str
    files: dict[str, Builder] = field(default_factory=dict)
    xfail: str = ""
    read_only: str = ""  # a file made read-only (and the command run as an unprivileged user under root)


TINY = {"tiny.toml": _text(TINY_PROTOCOL)}
RUN_NEW = ("run", "--participants", "1", "--db", "{d}/new.db", "--protocol", "{d}/p.toml")
CHECK = ("check-hardware", "--hardware", "{d}/hw.toml")
CONTINUE = ("run", "--participants", "2", "--seed", "0", "--protocol", "{d}/tiny.toml", "--continue", "--db")

CASES: list[Case] = [
    # -- protocol files -----------------------------------------------------------------------------------------
    Case("protocol: version = true", RUN_NEW, "p.toml: version = True: this software reads protocol version 1",
         {"p.toml": protocol("version = 1", "version = true")}),
    Case("protocol: modes nested in a list", RUN_NEW, "p.toml: design.modes = [['on']]: must be a non-empty list",
         {"p.toml": protocol('modes = ["on", "off"]', 'modes = [["on"]]')}),
    Case("protocol: training trials shorter than the hold", RUN_NEW,
         "p.toml: training.seconds_per_target_per_mode = 0.5: must be longer than trial.hold_s = 1",
         {"p.toml": protocol("seconds_per_target_per_mode = 20.0", "seconds_per_target_per_mode = 0.5")}),
    Case("protocol: training trials over 600 s", RUN_NEW,
         "p.toml: training.seconds_per_target_per_mode = 601.0: must be a number > 0 and ≤ 600",
         {"p.toml": protocol("seconds_per_target_per_mode = 20.0", "seconds_per_target_per_mode = 601.0")}),
    Case("protocol: trials_per_cell beyond 64 bits", RUN_NEW,
         "p.toml: design.trials_per_cell = 99999999999999999999: must be a whole number from 1 to 100",
         {"p.toml": protocol("trials_per_cell = 5 ", "trials_per_cell = 99999999999999999999 ")}),
    Case("protocol: a 5000-digit integer", RUN_NEW, "p.toml: not valid TOML (Exceeds the limit (4300 digits)",
         {"p.toml": protocol("trials_per_cell = 5 ", "trials_per_cell = " + "9" * 5000 + " ")}),
    Case("protocol: target force nan", RUN_NEW, "p.toml: targets[1].force_n = nan: must be a number > 0 and ≤ 20",
         {"p.toml": protocol("force_n = 1.2", "force_n = nan")}),
    Case("protocol: hold as text", RUN_NEW, "p.toml: trial.hold_s = '1 s': must be a number > 0 and ≤ 60",
         {"p.toml": protocol("hold_s = 1.0 ", 'hold_s = "1 s" ')}),
    Case("protocol: hold longer than the trial", RUN_NEW, "p.toml: trial.hold_s = 1.0: must be shorter than trial.max_trial_s = 0.5",
         {"p.toml": protocol("max_trial_s = 12.0 ", "max_trial_s = 0.5 ")}),
    Case("protocol: ordering in a list", RUN_NEW, "p.toml: design.ordering = ['random']: allowed values: random",
         {"p.toml": protocol('ordering = "random"', 'ordering = ["random"]')}),
    Case("protocol: unknown key with a line break", RUN_NEW, 'p.toml: trial."hold\\ns" = 1.0: unknown field',
         {"p.toml": protocol("hold_s = 1.0 ", '"hold\\ns" = 1.0 ')}),
    Case("protocol: not TOML", RUN_NEW, "p.toml: not valid TOML", {"p.toml": _text("this is not toml\n")}),
    Case("protocol: not UTF-8", RUN_NEW, "p.toml: cannot read the protocol file",
         {"p.toml": _text('name = "Studie für Kraft"\n'.encode("latin-1"))}),
    Case("protocol: no such file", RUN_NEW, "p.toml: no such protocol file"),
    Case("protocol: no such file, a line break in its name", ("run", "--db", "{d}/new.db", "--protocol", "{d}/p\n.toml"),
         "p\\n.toml: no such protocol file"),
    Case("protocol: a folder", RUN_NEW, "p.toml: cannot read the protocol file", {"p.toml": folder}),
    # -- hardware files -----------------------------------------------------------------------------------------
    Case("hardware: version = true", CHECK, "hw.toml: version = True: this software reads hardware file version 1",
         {"hw.toml": hardware("version = 1", "version = true")}),
    Case("hardware: rotation of strings", CHECK, "hw.toml: frames.rot_tip_sensor = [['1', '0', '0'], ['0', '1', '0'], ['0', '0', '1']]: must be a rotation matrix",
         {"hw.toml": hardware("rot_tip_sensor = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]",
                              'rot_tip_sensor = [["1", "0", "0"], ["0", "1", "0"], ["0", "0", "1"]]')}),
    Case("hardware: rotation of booleans", CHECK, "hw.toml: frames.rot_haptic_base = [[True, False, False], [False, False, True], [False, True, False]]: must be a rotation matrix",
         {"hw.toml": hardware("rot_haptic_base = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]",
                              "rot_haptic_base = [[true, false, false], [false, false, true], [false, true, false]]")}),
    Case("hardware: f_max above the Touch's peak", CHECK, "hw.toml: framework.f_max_n = 5.0: must be a number from 1e-06 to 3.3",
         {"hw.toml": hardware("f_max_n = 3.0", "f_max_n = 5.0")}),
    Case("hardware: f_max above the Touch's peak (gui --rig real)", ("gui", "--rig", "real", "--hardware", "{d}/hw.toml"),
         "hw.toml: framework.f_max_n = 3.5: must be a number from 1e-06 to 3.3",
         {"hw.toml": hardware("f_max_n = 3.0", "f_max_n = 3.5")}),
    Case("hardware: sensor host not an address", CHECK, "hw.toml: sensor.host = '192.168.1.300': must be an IPv4 address",
         {"hw.toml": hardware('host = "192.168.1.1"', 'host = "192.168.1.300"')}),
    Case("hardware: robot host with a space", CHECK, "hw.toml: robot.host = 'ur3 left': must be an IP address",
         {"hw.toml": hardware('host = "192.168.1.2"', 'host = "ur3 left"')}),
    Case("hardware: port = true", CHECK, "hw.toml: sensor.port = True: must be a whole port number from 1 to 65535",
         {"hw.toml": hardware("port = 49152", "port = true")}),
    Case("hardware: baud as a float", CHECK, "hw.toml: jaw.baud = 115200.0: allowed values: 9600",
         {"hw.toml": hardware("baud = 115200", "baud = 115200.0")}),
    Case("hardware: filter window 10.5", CHECK, "hw.toml: framework.filter_window = 10.5: must be a whole number of samples",
         {"hw.toml": hardware("filter_window = 10 ", "filter_window = 10.5 ")}),
    Case("hardware: teleop mode without [teleop]", CHECK, "hw.toml: teleop = None: robot.mode = 'teleop' needs a [teleop] table",
         {"hw.toml": hardware('mode = "observe"', 'mode = "teleop"')}),
    Case("hardware: unknown table", CHECK, "hw.toml: sensors = ",
         {"hw.toml": hardware("[sensor]", "[sensors]")}),
    Case("hardware: not TOML", CHECK, "hw.toml: not valid TOML", {"hw.toml": _text("[sensor\nhost = 1\n")}),
    Case("hardware: no such file", CHECK, "hw.toml: no such hardware file"),
    # -- calibrate (the commissioning chain) ---------------------------------------------------------------------
    Case("calibrate: command timeout above 50 ms", ("calibrate", "tcp", "--rig", "real", "--hardware", "{d}/hw.toml"),
         "hw.toml: haptic.command_timeout_s = 0.2: must be a number from 0.002 to 0.05 s",
         {"hw.toml": hardware("command_timeout_s = 0.010", "command_timeout_s = 0.2")}),
    Case("calibrate: calibration file not JSON", ("calibrate", "tcp", "--rig", "real", "--hardware", "{d}/hw.toml"),
         "/calibration.json: cannot be read as JSON",
         {"hw.toml": _text(EXAMPLE_HARDWARE), "calibration.json": _text("{not json\n")}),
    Case("calibrate: calibration file of another program", ("calibrate", "frames", "--rig", "real", "--hardware",
                                                             "{d}/hw.toml"),
         "/calibration.json: format = 'something else': expected 'haptic-study calibration'",
         {"hw.toml": _text(EXAMPLE_HARDWARE), "calibration.json": _text('{"format": "something else"}\n')}),
    Case("calibrate payload before tcp", ("calibrate", "payload", "--rig", "real", "--hardware", "{d}/hw.toml"),
         "calibrate payload: no TCP calibration on record for tool 'grasper'; the chain runs in order: calibrate tcp first",
         {"hw.toml": _text(EXAMPLE_HARDWARE)}),
    Case("calibrate: mount error out of range", ("calibrate", "frames", "--sim-mount-error-deg", "400"),
         "--sim-mount-error-deg = '400': must be a number from -180 to 180"),
    Case("calibrate: mount error on the real rig", ("calibrate", "frames", "--rig", "real", "--hardware", "{d}/hw.toml",
                                                    "--sim-mount-error-deg", "90"),
         "--sim-mount-error-deg applies to the simulated rig only", {"hw.toml": _text(EXAMPLE_HARDWARE)}),
    Case("gui: mount error on the real rig", ("gui", "--rig", "real", "--hardware", "{d}/hw.toml",
                                              "--sim-mount-error-deg", "90"),
         "--sim-mount-error-deg applies to the simulated rig only", {"hw.toml": _text(EXAMPLE_HARDWARE)}),
    Case("gui: mount error out of range", ("gui", "--sim-mount-error-deg", "nan"),
         "--sim-mount-error-deg = 'nan': must be a number from -180 to 180"),
    Case("calibrate: a pose set of the other step", ("calibrate", "tcp", "--poses", "quick"),
         "--poses = 'quick': allowed for tcp: 'recommended', 'minimal', 'roll only'"),
    Case("calibrate: real rig without a hardware file", ("calibrate", "tcp", "--rig", "real"),
         "--rig real needs --hardware FILE"),
    # -- command-line arguments ---------------------------------------------------------------------------------
    Case("--seed beyond SQLite's INTEGER (no database created)", ("run", "--seed", "99999999999999999999", "--db", "{d}/new.db"),
         "--seed = '99999999999999999999': must be a whole number from 0 to 9223372036854775807"),
    Case("--seed 2**63", ("sim", "--seed", str(2**63)), f"--seed = '{2**63}': must be a whole number from 0 to"),
    Case("--seed -1", ("run", "--seed", "-1", "--db", "{d}/new.db"), "--seed = '-1': must be a whole number from 0"),
    Case("--seed 1.5", ("run", "--seed", "1.5", "--db", "{d}/new.db"), "--seed = '1.5': must be a whole number from 0"),
    Case("--participants 0", ("run", "--participants", "0", "--db", "{d}/new.db"), "--participants = '0': must be a whole number from 1 to 9999"),
    Case("--participants 10**6", ("run", "--participants", "1000000", "--db", "{d}/new.db"), "--participants = '1000000': must be a whole number from 1 to 9999"),
    Case("--jobs 0", ("run", "--jobs", "0", "--db", "{d}/new.db"), "--jobs = '0': must be a whole number from 1 to 1024 (omit it"),
    Case("--seconds nan", ("sim", "--seconds", "nan"), "--seconds = 'nan': must be a number > 0 and ≤ 86400"),
    Case("--seconds 1e400", ("sim", "--seconds", "1e400"), "--seconds = '1e400': must be a number > 0 and ≤ 86400"),
    Case("bench pipeline --ticks 10**30", ("bench", "pipeline", "--ticks", str(10**30)), "--ticks = '1000000000000000000000000000000': must be a whole number from 2000 to 10000000"),
    Case("bench pipeline --loop-seconds inf", ("bench", "pipeline", "--loop-seconds", "inf"), "--loop-seconds = 'inf': must be a number from 0 to 3600"),
    Case("bench report --stats-participants 1", ("bench", "report", "--stats-participants", "1"), "--stats-participants = '1': must be a whole number from 2"),
    Case("bench study --participants 0", ("bench", "study", "--participants", "0"), "--participants = '0': must be a whole number from 1 to 1000"),
    Case("bench gui --seconds 0", ("bench", "gui", "--seconds", "0"), "--seconds = '0': must be a number > 0 and ≤ 3600"),
    Case("probe netft --host with a shell character", ("probe", "netft", "--host", "10.0.0.1;reboot"), "--host = '10.0.0.1;reboot': must be an IPv4 address"),
    Case("probe netft --port 65536", ("probe", "netft", "--host", "10.0.0.1", "--port", "65536"), "--port = '65536': must be a whole number from 1 to 65535"),
    Case("probe netft --samples 0", ("probe", "netft", "--host", "10.0.0.1", "--samples", "0"), "--samples = '0': must be a whole number from 1"),
    Case("report --confidence nan", ("report", "--db", "{d}/good.db", "--out", "{d}/out", "--confidence", "nan"), "--confidence = 'nan': must be in [0.5, 1)",
         {"good.db": good_db}),
    Case("plot-trial --session beyond SQLite's INTEGER", ("plot-trial", "--db", "{d}/good.db", "--session", "99999999999999999999", "--trial", "1", "--out", "{d}/t.png"),
         "--session = '99999999999999999999': must be a whole number from 1 to 9223372036854775807", {"good.db": good_db}),
    Case("plot-trial --trial -1", ("plot-trial", "--db", "{d}/good.db", "--session", "1", "--trial", "-1", "--out", "{d}/t.png"),
         "--trial = '-1': must be a whole number from 1", {"good.db": good_db}),
    Case("--resume and --continue together", ("run", "--db", "{d}/good.db", "--resume", "P01", "--continue"),
         "argument --continue: not allowed with argument --resume", {"good.db": good_db}),
    Case("run without --db", ("run", "--participants", "1"), "the following arguments are required: --db"),
    Case("an unknown option", ("run", "--db", "{d}/new.db", "--colour", "red"), "unrecognized arguments: --colour red"),
    Case("an unknown command", ("frobnicate",), "invalid choice: 'frobnicate'"),
    Case("no command", (), "the following arguments are required: COMMAND"),
    Case("a choice with a line break", ("sim", "--clock", "real\nvirtual"), "invalid choice: 'real\\nvirtual'"),
    Case("--resume with a bad participant code", ("run", "--db", "{d}/good.db", "--resume", "P01; DROP TABLE trials"),
         "participant code = 'P01; DROP TABLE trials': must be 1–32 characters", {"good.db": good_db}),
    # -- study databases ----------------------------------------------------------------------------------------
    Case("database: participant already has a session", ("run", "--participants", "1", "--seed", "0", "--protocol", "{d}/tiny.toml", "--db", "{d}/good.db"),
         "good.db already holds sessions for participant P01; nothing was changed", {"good.db": good_db, **TINY}),
    Case("database: --continue with another seed", ("run", "--participants", "2", "--seed", "1", "--protocol", "{d}/tiny.toml", "--continue", "--db", "{d}/good.db"),
         "was run with --seed 0, not 1; nothing was changed", {"good.db": good_db, **TINY}),
    Case("database: --continue with another protocol", ("run", "--participants", "2", "--seed", "0", "--continue", "--db", "{d}/good.db"),
         "cannot continue: P01's experiment session 1", {"good.db": good_db}),
    Case("database: foreign SQLite, run", (*CONTINUE, "{d}/other.db"), "other.db: not a haptic-study database (it has other tables: inventory)",
         {"other.db": foreign_db, **TINY}),
    Case("database: foreign SQLite, report", ("report", "--db", "{d}/other.db", "--out", "{d}/out"), "other.db: not a haptic-study database",
         {"other.db": foreign_db}),
    Case("database: newer schema, run", (*CONTINUE, "{d}/newer.db"), "newer.db: database schema version 99 is newer than this software supports",
         {"newer.db": newer_db, **TINY}),
    Case("database: newer schema, report", ("report", "--db", "{d}/newer.db", "--out", "{d}/out"), "newer.db: database schema version 99 is newer",
         {"newer.db": newer_db}),
    Case("database: not SQLite, run", (*CONTINUE, "{d}/notes.db"), "notes.db: not a haptic-study database (not an SQLite file)",
         {"notes.db": _text("minutes of the lab meeting\n" * 200), **TINY}),
    Case("database: not SQLite, plot-trial", ("plot-trial", "--db", "{d}/notes.db", "--session", "1", "--trial", "1", "--out", "{d}/t.png"),
         "notes.db: not a haptic-study database", {"notes.db": _text("minutes of the lab meeting\n" * 200)}),
    Case("database: a folder", (*CONTINUE, "{d}/study.db"), "study.db: is a directory, not a database file", {"study.db": folder, **TINY}),
    Case("database: report into a non-empty folder", ("report", "--db", "{d}/good.db", "--out", "{d}/out"),
         "out: the folder exists and holds ", {"good.db": good_db, "out": folder}),
    Case("database: read-only, run --continue", (*CONTINUE, "{d}/good.db"), "good.db: the database is not writable",
         {"good.db": good_db, **TINY}, read_only="good.db"),
    Case("database: damaged, run --continue", (*CONTINUE, "{d}/damaged.db"), "damaged.db: the database is damaged",
         {"damaged.db": damaged_db, **TINY}),
    Case("database: damaged, report", ("report", "--db", "{d}/damaged.db", "--out", "{d}/out"),
         "damaged.db: the database is damaged", {"damaged.db": damaged_db}),
    Case("database: damaged, plot-trial", ("plot-trial", "--db", "{d}/damaged.db", "--session", "1", "--trial", "1", "--out", "{d}/t.png"),
         "damaged.db: the database is damaged", {"damaged.db": damaged_db}),
]


@dataclass
class Outcome:
    returncode: int
    stdout: str
    stderr: str
    before: dict[str, str]
    after: dict[str, str]


def _snapshot(d: Path) -> dict[str, str]:
    """Every file under ``d``: relative path → SHA-256 of its bytes."""
    return {
        str(p.relative_to(d)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(d.rglob("*")) if p.is_file()
    }


def _unprivileged() -> tuple[int, int] | None:
    """(uid, gid) to run a command under when this process is root (root writes read-only files)."""
    if os.geteuid() != 0:
        return None
    try:
        pw = pwd.getpwnam("nobody")
    except KeyError:
        return None
    return pw.pw_uid, pw.pw_gid


def _run_case(case: Case, d: Path, good: Path) -> Outcome:
    for name, build in case.files.items():
        build(d / name, good)
    user = None
    if case.read_only:
        (d / case.read_only).chmod(0o444)
        user = _unprivileged()
        if user is not None:
            d.chmod(0o755)  # nobody can read the folder, and not write to it
    before = _snapshot(d)
    env = {k: v for k, v in os.environ.items()
           if not k.startswith("HAPTIC_STUDY") and k not in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM")}
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    args = [a.replace("{d}", str(d)) for a in case.args]
    proc = subprocess.run(
        [*CLI, *args], capture_output=True, text=True, timeout=120, cwd=ROOT, env=env,
        **({"user": user[0], "group": user[1], "extra_groups": []} if user else {}),
    )
    return Outcome(proc.returncode, proc.stdout, proc.stderr, before, _snapshot(d))


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
        for i, case in enumerate(CASES):
            dirs[case.id] = base / f"case{i:02d}"
            dirs[case.id].mkdir()
        t0 = time.perf_counter()
        with ThreadPoolExecutor(max_workers=3) as pool:
            futures = {case.id: pool.submit(_run_case, case, dirs[case.id], good) for case in CASES}
            results = {k: f.result() for k, f in futures.items()}
        print(f"\n{len(CASES)} bad-input cases in {time.perf_counter() - t0:.1f} s")
        yield results
    finally:
        for p in base.rglob("*"):  # read-only files and folders left by a case
            if p.is_dir() and not p.is_symlink():
                p.chmod(0o755)
        shutil.rmtree(base, ignore_errors=True)


def test_the_corpus_is_large_and_each_case_distinct() -> None:
    assert len(CASES) >= 40
    assert len({c.id for c in CASES}) == len(CASES)


@pytest.mark.parametrize(
    "case",
    [pytest.param(c, id=c.id, marks=[pytest.mark.xfail(strict=True, reason=c.xfail)] if c.xfail else []) for c in CASES],
)
def test_bad_input_exits_2_with_one_line_and_touches_nothing(case: Case, outcomes: dict[str, Outcome]) -> None:
    out = outcomes[case.id]
    assert "Traceback" not in out.stdout + out.stderr, out.stderr
    assert out.returncode == 2, (out.returncode, out.stderr)
    lines = out.stderr.splitlines()
    assert len(lines) == 1, out.stderr
    assert case.says in lines[0], lines[0]
    assert "error: " in lines[0]
    # every file that was there is byte-identical; nothing new but SQLite's own companions of a database
    for name, digest in out.before.items():
        assert out.after.get(name) == digest, f"{name} was changed or removed"
    new = set(out.after) - set(out.before)
    assert all(n.endswith(SQLITE_COMPANIONS) and n[: n.rindex("-")] in out.before for n in new), sorted(new)
