"""The bad-input corpus of tests/test_bad_inputs.py, part 1: protocol and hardware files, the command line's
arguments, and damaged, foreign and odd study databases.

A :class:`Case` is a command (``{d}`` is the case's own folder), the files it finds there, what its one line
on stderr must say and its exit status.  Part 2 (:mod:`bad_outputs_corpus`) holds the cases of outputs, links,
permissions and full or read-only file systems.
"""

from __future__ import annotations

import json
import os
import random
import re
import shutil
import sqlite3
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from tests.parts_plan import PLAN

#: What a --seconds option allows (one tick at least: issue 42)
SIM_SECONDS = "must be a number from 0.001 to 86400 (one tick of the 1 kHz loop at least)"
BENCH_SECONDS = "must be a number from 0.001 to 3600 (one tick of the 1 kHz loop at least)"

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_PROTOCOL = (ROOT / "protocol" / "study" / "default.toml").read_text(encoding="utf-8")
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
pause_s = 0.05
[training]
enabled = false
"""

Builder = Callable[[Path, Path], None]  # (file to write, the good database to copy from)


def _text(content: str | bytes) -> Builder:
    def build(path: Path, good: Path) -> None:
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content, encoding="utf-8")

    return build


def _variant(base: str, old: str, new: str) -> Builder:
    """``base`` with exactly one occurrence of ``old`` replaced by ``new`` (or, where commented-out examples repeat
    it, its one occurrence at the start of a line)."""
    if base.count(old) == 1:
        return _text(base.replace(old, new))
    at_start = [m.start() for m in re.finditer(r"(?m)^" + re.escape(old), base)]
    assert len(at_start) == 1, f"{old!r} must occur exactly once (at the start of a line)"
    return _text(base[: at_start[0]] + new + base[at_start[0] + len(old) :])


def protocol(old: str, new: str) -> Builder:
    return _variant(DEFAULT_PROTOCOL, old, new)


def hardware(old: str, new: str) -> Builder:
    return _variant(EXAMPLE_HARDWARE, old, new)


def _two_arm_example() -> str:
    """The example file's commented two-arm file, uncommented (arms right and left)."""
    lines = EXAMPLE_HARDWARE.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("# The lines below, uncommented")) + 1
    return "\n".join(line[2:] if line.startswith("# ") else line[1:] for line in lines[start:]) + "\n"


TWO_ARMS = {"hw.toml": _text(_two_arm_example())}


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


def fifo(path: Path, good: Path) -> None:
    os.mkfifo(path)


def link(target: str) -> Builder:
    """A symbolic link to ``target`` (a path relative to the case's folder; it need not exist)."""
    def build(path: Path, good: Path) -> None:
        path.symlink_to(path.parent / target)

    return build


def user_folder(path: Path, good: Path) -> None:
    """Someone's own folder, with a figure and notes the commands must never touch."""
    path.mkdir()
    (path / "figure.png").write_bytes(b"\x89PNG\r\n\x1a\n someone's own figure")
    (path / "notes.txt").write_text("my notes\n", encoding="utf-8")


def marked_folder(marker: str, files: dict[str, str], links: dict[str, str] | None = None,
                  edited: str = "") -> Builder:
    """A folder a command wrote before: ``files`` and a marker listing them with their SHA-256 (``edited``: one
    of them changed since), and ``links`` (name -> target relative to the case's folder) put there since."""
    import hashlib

    def build(path: Path, good: Path) -> None:
        path.mkdir()
        listed = {}
        for name, text in files.items():
            (path / name).parent.mkdir(parents=True, exist_ok=True)
            (path / name).write_text(text, encoding="utf-8")
            listed[name] = hashlib.sha256(text.encode()).hexdigest()
        (path / marker).write_text(json.dumps({"files": listed}), encoding="utf-8")
        if edited:
            (path / edited).write_text("edited since", encoding="utf-8")
        for name, target in (links or {}).items():
            (path / name).symlink_to(path.parent / target)

    return build


@dataclass(frozen=True)
class Mount:
    """A small tmpfs mounted at the case's ``{d}/NAME``: ``files`` put on it, then filled to leave ``free_kib``
    free (None: not filled), then remounted read-only if ``read_only``."""

    size_kib: int = 512
    read_only: bool = False
    free_kib: int | None = None
    files: dict[str, Builder] = field(default_factory=dict)


@dataclass(frozen=True)
class Case:
    """One bad input: the command (``{d}`` is the case's folder), the files it finds, and what the line says."""

    id: str
    args: tuple[str, ...]
    says: str
    files: dict[str, Builder] = field(default_factory=dict)
    xfail: str = ""
    read_only: str = ""  # a file made read-only (and the command run as an unprivileged user under root)
    exit: int = 2  # 2: refused (bad input, before any work); 1: the machine failed the command
    mounts: dict[str, Mount] = field(default_factory=dict)
    as_nobody: bool = False  # run as an unprivileged user (root may write anywhere)
    after_work: bool = False  # refused when the work was done (its progress lines on stderr before the one line)


TINY = {"tiny.toml": _text(TINY_PROTOCOL)}
RUN_NEW = ("run", "--participants", "1", "--db", "{d}/new.db", "--protocol", "{d}/p.toml")
CHECK = ("check-hardware", "--hardware", "{d}/hw.toml")
CONTINUE = ("run", "--participants", "2", "--seed", "0", "--protocol", "{d}/tiny.toml", "--continue", "--db")

CASES: list[Case] = [
    # -- protocol files -----------------------------------------------------------------------------------------
    Case("protocol: version = true", RUN_NEW, "p.toml: version = true: this software reads protocol version 1",
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
    Case("protocol: hold longer than the trial", RUN_NEW,
         "p.toml: trial.hold_s = 1.0: must be shorter than trial.max_trial_s = 0.5",
         {"p.toml": protocol("max_trial_s = 12.0 ", "max_trial_s = 0.5 ")}),
    Case("protocol: ordering in a list", RUN_NEW, "p.toml: design.ordering = ['random']: allowed values: random",
         {"p.toml": protocol('ordering = "random"', 'ordering = ["random"]')}),
    Case("protocol: unknown key with a line break", RUN_NEW, 'p.toml: trial."hold\\ns" = 1.0: unknown field',
         {"p.toml": protocol("hold_s = 1.0 ", '"hold\\ns" = 1.0 ')}),
    Case("protocol: not TOML", RUN_NEW, "p.toml: not valid TOML", {"p.toml": _text("this is not toml\n")}),
    Case("protocol: not UTF-8", RUN_NEW, "p.toml: cannot read the protocol file",
         {"p.toml": _text('name = "Studie für Kraft"\n'.encode("latin-1"))}),
    Case("protocol: no such file", RUN_NEW, "p.toml: no such protocol file"),
    Case("protocol: no such file, a line break in its name",
         ("run", "--db", "{d}/new.db", "--protocol", "{d}/p\n.toml"),
         "p\\n.toml: no such protocol file"),
    Case("protocol: a folder", RUN_NEW, "p.toml: cannot read the protocol file", {"p.toml": folder}),
    # a study of several parts (docs/study-design.md): each refusal names the part; nothing stored
    Case("parts: an unknown task kind in a part", RUN_NEW,
         "p.toml, part 'tracking' (parts[3]): task.kind = 'juggling': allowed values",
         {"p.toml": _variant(PLAN, 'kind = "force_tracking"', 'kind = "juggling"')}),
    Case("parts: a part without trials", RUN_NEW, "p.toml, part 'firm' (parts[4]): targets = []: must be a list",
         {"p.toml": _variant(PLAN, '[[parts.targets]]\nlabel = "FIRM"\nforce_n = 1.2\n', "targets = []\n")}),
    Case("parts: a counterbalance group naming an unknown part", RUN_NEW,
         "p.toml: counterbalance.parts = ['regulation', 'tracking', 'soft']: names no part 'soft'",
         {"p.toml": _variant(PLAN, '"firm"]', '"soft"]')}),
    Case("parts: a training part without training", RUN_NEW,
         "p.toml, part 'practice' (parts[1]): session = 'training': the part's training.enabled is false",
         {"p.toml": _variant(PLAN, 'session = "training"', 'session = "training"\n[parts.training]\nenabled = false')}),
    # -- hardware files -----------------------------------------------------------------------------------------
    Case("hardware: version = true", CHECK, "hw.toml: version = true: this software reads hardware file version 1",
         {"hw.toml": hardware("version = 1", "version = true")}),
    Case("hardware: rotation of strings", CHECK,
         "hw.toml: frames.rot_tip_sensor = [['1', '0', '0'], ['0', '1', '0'], ['0', '0', '1']]: "
         "must be a rotation matrix",
         {"hw.toml": hardware("rot_tip_sensor = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]",
                              'rot_tip_sensor = [["1", "0", "0"], ["0", "1", "0"], ["0", "0", "1"]]')}),
    Case("hardware: rotation of booleans", CHECK,
         "hw.toml: frames.rot_haptic_base = [[True, False, False], [False, False, True], [False, True, False]]: "
         "must be a rotation matrix",
         {"hw.toml": hardware("rot_haptic_base = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]",
                              "rot_haptic_base = [[true, false, false], [false, false, true], [false, true, false]]")}),
    Case("hardware: f_max above the Touch's peak", CHECK,
         "hw.toml: framework.f_max_n = 5.0: must be a number from 1e-06 to 3.3",
         {"hw.toml": hardware("f_max_n = 3.0", "f_max_n = 5.0")}),
    Case("hardware: f_max above the Touch's peak (gui --rig real)",
         ("gui", "--rig", "real", "--hardware", "{d}/hw.toml"),
         "hw.toml: framework.f_max_n = 3.5: must be a number from 1e-06 to 3.3",
         {"hw.toml": hardware("f_max_n = 3.0", "f_max_n = 3.5")}),
    Case("hardware: sensor host not an address", CHECK,
         "hw.toml: sensor.host = '192.168.1.300': must be an IPv4 address",
         {"hw.toml": hardware('host = "192.168.1.1"', 'host = "192.168.1.300"')}),
    Case("hardware: robot host with a space", CHECK, "hw.toml: robot.host = 'ur3 left': must be an IP address",
         {"hw.toml": hardware('host = "192.168.1.2"', 'host = "ur3 left"')}),
    Case("hardware: port = true", CHECK, "hw.toml: sensor.port = true: must be a whole port number from 1 to 65535",
         {"hw.toml": hardware("port = 49152", "port = true")}),
    Case("hardware: baud as a float", CHECK, "hw.toml: jaw.baud = 115200.0: allowed values: 9600",
         {"hw.toml": hardware("baud = 115200", "baud = 115200.0")}),
    Case("hardware: filter window 10.5", CHECK,
         "hw.toml: framework.filter_window = 10.5: must be a whole number of samples",
         {"hw.toml": hardware("filter_window = 10 ", "filter_window = 10.5 ")}),
    Case("hardware: teleop mode without [teleop]", CHECK,
         "hw.toml: teleop = None: robot.mode = 'teleop' needs a [teleop] table",
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
         "calibrate payload: no TCP calibration on record for tool 'grasper'; the chain runs in order: "
         "calibrate tcp first",
         {"hw.toml": _text(EXAMPLE_HARDWARE)}),
    Case("calibrate: mount error out of range", ("calibrate", "frames", "--sim-mount-error-deg", "400"),
         "--sim-mount-error-deg = '400': must be a number from -180 to 180"),
    Case("calibrate: mount error on the real rig", ("calibrate", "frames", "--rig", "real", "--hardware", "{d}/hw.toml",
                                                    "--sim-mount-error-deg", "90"),
         "--sim-mount-error-deg applies to the simulated rig only", {"hw.toml": _text(EXAMPLE_HARDWARE)}),
    Case("gui: mount error on the real rig", ("gui", "--rig", "real", "--hardware", "{d}/hw.toml",
                                              "--sim-mount-error-deg", "90"),
         "--sim-mount-error-deg applies to the simulated rig only", {"hw.toml": _text(EXAMPLE_HARDWARE)}),
    Case("gui: --set on the real rig",
         ("gui", "--rig", "real", "--hardware", "{d}/hw.toml", "--set", "filter_window=5"),
         "--set applies to the simulated rig only", {"hw.toml": _text(EXAMPLE_HARDWARE)}),
    Case("gui: mount error out of range", ("gui", "--sim-mount-error-deg", "nan"),
         "--sim-mount-error-deg = 'nan': must be a number from -180 to 180"),
    Case("calibrate: a pose set of the other step", ("calibrate", "tcp", "--poses", "quick"),
         "--poses = 'quick': allowed for tcp: 'recommended', 'minimal', 'roll only'"),
    Case("calibrate: real rig without a hardware file", ("calibrate", "tcp", "--rig", "real"),
         "--rig real needs --hardware FILE"),
    Case("calibrate: two arms, no --arm", ("calibrate", "tcp", "--rig", "real", "--hardware", "{d}/hw.toml"),
         "hw.toml has 2 arms (right, left): name the one to commission with --arm (e.g. --arm right)", TWO_ARMS),
    Case("calibrate: --arm not in the file", ("calibrate", "payload", "--rig", "real", "--hardware", "{d}/hw.toml",
                                              "--arm", "middle"),
         "--arm = 'middle': ", TWO_ARMS),
    Case("calibrate: --arm not a name", ("calibrate", "tcp", "--arm", "two words"),
         "--arm = 'two words': must be a name of letters"),
    Case("calibrate: --arm not among --sim-arms", ("calibrate", "tcp", "--sim-arms", "left,right", "--arm", "middle"),
         "--arm = 'middle': the simulated rig (--sim-arms left,right) has no such arm; its arms: left, right"),
    Case("calibrate: --sim-arms on the real rig", ("calibrate", "tcp", "--rig", "real", "--hardware", "{d}/hw.toml",
                                                   "--sim-arms", "left,right"),
         "--sim-arms applies to the simulated rig only", TWO_ARMS),
    Case("check-hardware: --arm not in the file", (*CHECK, "--arm", "middle"),
         "hw.toml has no such arm; its arms: right, left", TWO_ARMS),
    # -- participants described, questionnaires, notes (issue 44) -----------------------------------------------
    Case("protocol: a Likert item without a scale", RUN_NEW,
         "p.toml: questionnaires[0].items[0].scale = None: every Likert item needs its scale",
         {"p.toml": _text(DEFAULT_PROTOCOL + '\n[[questionnaires]]\nname = "q"\nkind = "likert"\nafter = "session"\n'
                          '[[questionnaires.items]]\nid = "a"\ntext = "A?"\n')}),
    Case("protocol: a covariate's range backwards", RUN_NEW,
         "p.toml: covariates[0].max = 0: must be greater than covariates[0].min = 50",
         {"p.toml": _text(DEFAULT_PROTOCOL + '\n[[covariates]]\nname = "years"\nkind = "integer"\nmin = 50\n'
                          'max = 0\n')}),
    Case("run --covariate outside its range", (*RUN_NEW, "--covariate", "years=-3"),
         "covariate years = '-3': must be a whole number from 0 to 50",
         {"p.toml": _text(DEFAULT_PROTOCOL + '\n[[covariates]]\nname = "years"\nkind = "integer"\nmin = 0\n'
                          'max = 50\n')}),
    Case("run --covariate the protocol does not declare", ("run", "--db", "{d}/new.db", "--covariate", "group=novice"),
         "covariate group = 'novice': the protocol declares no such covariate (it declares none)"),
    Case("note on a trial the session does not have", ("note", "--db", "{d}/good.db", "--session", "1", "--trial",
                                                       "99", "text"),
         "--trial 99: session 1 has trials 1 to 1; nothing was changed", {"good.db": good_db}),
    Case("note on no such session", ("note", "--db", "{d}/good.db", "--session", "7", "text"),
         "--session 7: no such session in", {"good.db": good_db}),
    # -- command-line arguments ---------------------------------------------------------------------------------
    Case("--seed beyond SQLite's INTEGER (no database created)",
         ("run", "--seed", "99999999999999999999", "--db", "{d}/new.db"),
         "--seed = '99999999999999999999': must be a whole number from 0 to 9223372036854775807"),
    Case("--seed 2**63", ("sim", "--seed", str(2**63)), f"--seed = '{2**63}': must be a whole number from 0 to"),
    Case("--seed -1", ("run", "--seed", "-1", "--db", "{d}/new.db"), "--seed = '-1': must be a whole number from 0"),
    Case("--seed 1.5", ("run", "--seed", "1.5", "--db", "{d}/new.db"), "--seed = '1.5': must be a whole number from 0"),
    Case("--participants 0", ("run", "--participants", "0", "--db", "{d}/new.db"),
         "--participants = '0': must be a whole number from 1 to 9999"),
    Case("--participants 10**6", ("run", "--participants", "1000000", "--db", "{d}/new.db"),
         "--participants = '1000000': must be a whole number from 1 to 9999"),
    Case("--jobs 0", ("run", "--jobs", "0", "--db", "{d}/new.db"),
         "--jobs = '0': must be a whole number from 1 to 1024 (omit it"),
    Case("--sim-arms bad name", ("run", "--sim-arms", "left,2x", "--db", "{d}/new.db"),
         "--sim-arms = 'left,2x': each arm must be a name of letters, digits, '_' and '-', starting with a letter"),
    Case("--sim-arms twice", ("run", "--sim-arms", "left,left", "--db", "{d}/new.db"),
         "--sim-arms = 'left,left': must be 1 to 4 distinct arm names"),
    Case("gui --sim-arms bad name", ("gui", "--sim-arms", "left,left"),
         "--sim-arms = 'left,left': must be 1 to 4 distinct arm names"),
    Case("gui --sim-arms on the real rig",
         ("gui", "--rig", "real", "--hardware", "{d}/hw.toml", "--sim-arms", "left,right"),
         "--sim-arms applies to the simulated rig only", {"hw.toml": hardware("version = 1", "version = 1")}),
    Case("--sim-arms without the task arm", ("run", "--sim-arms", "left,centre", "--db", "{d}/new.db"),
         "design.task_arm is not set and the rig has 2 arms (left, centre), none called 'right'"),
    Case("protocol: task_arm the rig lacks", RUN_NEW, "design.task_arm = 'left': the rig has no such arm",
         {"p.toml": protocol('# task_arm = "left"', 'task_arm = "left"')}),
    Case("protocol: task_arm 2x", RUN_NEW, "design.task_arm = '2x': must be a name of letters",
         {"p.toml": protocol('# task_arm = "left"', 'task_arm = "2x"')}),
    # run --set and sweep --set: the pipeline's settings, checked against the configuration's own limits
    Case("run --set an unknown setting", ("run", "--db", "{d}/new.db", "--set", "gain=2"),
         "--set = 'gain=2': unknown setting 'gain': allowed are filter_window, f_scale_n, f_max_n, slew_n_per_s"),
    Case("run --set filter_window 0", ("run", "--db", "{d}/new.db", "--set", "filter_window=0"),
         "--set = 'filter_window=0': filter_window = 0: must be a whole number of samples from 1 to 1000"),
    Case("run --set f_scale nan", ("run", "--db", "{d}/new.db", "--set", "f_scale=nan"),
         "--set = 'f_scale=nan': f_scale_n = 'nan': must be a finite number"),
    Case("run --set slew beyond its limit", ("run", "--db", "{d}/new.db", "--set", "slew=1e9"),
         "--set = 'slew=1e9': safety.slew_n_per_s = 1000000000.0: must be a number from 0.001 to 1e+06 N/s"),
    Case("run --set without =", ("run", "--db", "{d}/new.db", "--set", "filter_window"),
         "--set = 'filter_window': must be NAME=VALUE"),
    Case("run --set a list", ("run", "--db", "{d}/new.db", "--set", "filter_window=1,10"),
         "--set = 'filter_window=1,10': filter_window: one value here (lists of values are for haptic-study sweep)"),
    Case("run --set a setting twice", ("run", "--db", "{d}/new.db", "--set", "f_scale=3", "--set", "f_scale_n=4"),
         "--set f_scale_n: given twice (3 and 4); give each setting once"),
    Case("run --set a ramp-in longer than a trial", ("run", "--db", "{d}/new.db", "--set", "ramp_in_s=20"),
         "protocol with the pipeline's settings: trial.max_trial_s = 12.0: must be at least trial.hold_s = 1 + the "
         "feedback's 20 s ramp-in"),
    Case("sweep --set a ramp-in longer than a trial", ("sweep", "--set", "ramp_in=0.5,20", "--out", "{d}/out"),
         "protocol with --set ramp_in_s=20: trial.max_trial_s = 12.0: must be at least trial.hold_s = 1"),
    Case("sweep without --set", ("sweep", "--out", "{d}/out"), "--set: give at least one setting to sweep"),
    Case("sweep --set an unknown setting", ("sweep", "--set", "window=1,2", "--out", "{d}/out"),
         "--set = 'window=1,2': unknown setting 'window'"),
    Case("sweep --set a bad value", ("sweep", "--set", "filter_window=1,0", "--out", "{d}/out"),
         "--set = 'filter_window=1,0': filter_window = 0: must be a whole number of samples from 1 to 1000"),
    Case("sweep --set an empty list", ("sweep", "--set", "filter_window=", "--out", "{d}/out"),
         "--set = 'filter_window=': filter_window: an empty value"),
    Case("sweep --set a value twice", ("sweep", "--set", "f_max=2,3,2.0", "--out", "{d}/out"),
         "--set = 'f_max=2,3,2.0': f_max_n: a value is given twice"),
    Case("sweep --set a setting twice", ("sweep", "--set", "f_max=2,3", "--set", "f_max_n=1", "--out", "{d}/out"),
         "--set f_max_n: given twice; give each setting once"),
    Case("sweep: a grid of 56 settings",
         ("sweep", "--set", "filter_window=1,2,3,4,5,6,7,8", "--set", "f_scale=1,2,3,4,5,6,7", "--out", "{d}/out"),
         "--set: the grid has 56 settings (8 x 7); at most 50"),
    Case("sweep --out a file", ("sweep", "--set", "filter_window=1,10", "--out", "{d}/notes.txt"),
         "--out {d}/notes.txt: exists and is not a folder", {"notes.txt": _text("mine")}),
    Case("sweep --studies 0", ("sweep", "--set", "filter_window=1,10", "--studies", "0"),
         "--studies = '0': must be a whole number from 1 to 50"),
    Case("sweep --participants 201", ("sweep", "--set", "filter_window=1,10", "--participants", "201"),
         "--participants = '201': must be a whole number from 1 to 200"),
    Case("--seconds nan", ("sim", "--seconds", "nan"), "--seconds = 'nan': " + SIM_SECONDS),
    Case("--seconds below one tick", ("sim", "--seconds", "1e-300"),  # (issue 42: a traceback after the run)
         "--seconds = '1e-300': " + SIM_SECONDS),
    Case("bench --loop-seconds below one tick", ("bench", "pipeline", "--loop-seconds", "1e-300"),
         "--loop-seconds = '1e-300': must be 0 (skips the loop) or a number from 0.001 to 3600 (one tick of the 1 kHz "
         "loop at least)"),
    Case("--seconds 1e400", ("sim", "--seconds", "1e400"), "--seconds = '1e400': " + SIM_SECONDS),
    Case("bench pipeline --ticks 10**30", ("bench", "pipeline", "--ticks", str(10**30)),
         "--ticks = '1000000000000000000000000000000': must be a whole number from 2000 to 10000000"),
    Case("bench pipeline --loop-seconds inf", ("bench", "pipeline", "--loop-seconds", "inf"),
         "--loop-seconds = 'inf': must be 0 (skips the loop) or a number from 0.001 to 3600 (one tick of "
         "the 1 kHz loop at least)"),
    Case("bench report --stats-participants 1", ("bench", "report", "--stats-participants", "1"),
         "--stats-participants = '1': must be a whole number from 2"),
    Case("bench study --participants 0", ("bench", "study", "--participants", "0"),
         "--participants = '0': must be a whole number from 1 to 1000"),
    Case("bench gui --seconds 0", ("bench", "gui", "--seconds", "0"),
         "--seconds = '0': " + BENCH_SECONDS),
    Case("probe netft --host with a shell character", ("probe", "netft", "--host", "10.0.0.1;reboot"),
         "--host = '10.0.0.1;reboot': must be an IPv4 address"),
    Case("probe netft --port 65536", ("probe", "netft", "--host", "10.0.0.1", "--port", "65536"),
         "--port = '65536': must be a whole number from 1 to 65535"),
    Case("probe netft --samples 0", ("probe", "netft", "--host", "10.0.0.1", "--samples", "0"),
         "--samples = '0': must be a whole number from 1"),
    Case("report --confidence nan", ("report", "--db", "{d}/good.db", "--out", "{d}/out", "--confidence", "nan"),
         "--confidence = 'nan': must be in [0.5, 1)",
         {"good.db": good_db}),
    Case("plot-trial --session beyond SQLite's INTEGER",
         ("plot-trial", "--db", "{d}/good.db", "--session", "99999999999999999999", "--trial", "1", "--out",
              "{d}/t.png"),
         "--session = '99999999999999999999': must be a whole number from 1 to 9223372036854775807",
              {"good.db": good_db}),
    Case("plot-trial --trial -1",
         ("plot-trial", "--db", "{d}/good.db", "--session", "1", "--trial", "-1", "--out", "{d}/t.png"),
         "--trial = '-1': must be a whole number from 1", {"good.db": good_db}),
    Case("--resume and --continue together", ("run", "--db", "{d}/good.db", "--resume", "P01", "--continue"),
         "argument --continue: not allowed with argument --resume", {"good.db": good_db}),
    Case("run without --db", ("run", "--participants", "1"), "the following arguments are required: --db"),
    Case("an unknown option", ("run", "--db", "{d}/new.db", "--colour", "red"), "unrecognized arguments: --colour red"),
    Case("an unknown command", ("frobnicate",), "invalid choice: 'frobnicate'"),
    Case("no command", (), "the following arguments are required: COMMAND"),
    Case("a choice with a line break", ("sim", "--clock", "real\nvirtual"), "invalid choice: 'real\\nvirtual'"),
    Case("--resume with a bad participant code", ("run", "--db", "{d}/good.db", "--resume", "P01; DROP TABLE trials"),
         "--resume: 'P01; DROP TABLE trials': must be 1–32 characters", {"good.db": good_db}),
    # -- study databases ----------------------------------------------------------------------------------------
    Case("database: participant already has a session",
         ("run", "--participants", "1", "--seed", "0", "--protocol", "{d}/tiny.toml", "--db", "{d}/good.db"),
         "good.db already holds sessions for participant P01; nothing was changed", {"good.db": good_db, **TINY}),
    Case("database: --continue with another seed",
         ("run", "--participants", "2", "--seed", "1", "--protocol", "{d}/tiny.toml", "--continue", "--db",
              "{d}/good.db"),
         "was run with --seed 0, not 1; nothing was changed", {"good.db": good_db, **TINY}),
    Case("database: --continue with another protocol",
         ("run", "--participants", "2", "--seed", "0", "--continue", "--db", "{d}/good.db"),
         "cannot continue: P01's experiment session 1", {"good.db": good_db}),
    Case("database: --continue with other pipeline settings", (*CONTINUE, "{d}/good.db", "--set", "filter_window=50"),
         "P01's experiment session 1 ran with the pipeline settings: the paper's; this command's: filter_window=50; "
         "one study runs one pipeline, nothing was changed", {"good.db": good_db, **TINY}),
    Case("database: foreign SQLite, run", (*CONTINUE, "{d}/other.db"),
         "other.db: not a haptic-study database (it has other tables: inventory)",
         {"other.db": foreign_db, **TINY}),
    Case("database: foreign SQLite, report", ("report", "--db", "{d}/other.db", "--out", "{d}/out"),
         "other.db: not a haptic-study database",
         {"other.db": foreign_db}),
    Case("database: newer schema, run", (*CONTINUE, "{d}/newer.db"),
         "newer.db: database schema version 99 is newer than this software supports",
         {"newer.db": newer_db, **TINY}),
    Case("database: newer schema, report", ("report", "--db", "{d}/newer.db", "--out", "{d}/out"),
         "newer.db: database schema version 99 is newer",
         {"newer.db": newer_db}),
    Case("database: not SQLite, run", (*CONTINUE, "{d}/notes.db"),
         "notes.db: not a haptic-study database (not an SQLite file)",
         {"notes.db": _text("minutes of the lab meeting\n" * 200), **TINY}),
    Case("database: not SQLite, plot-trial",
         ("plot-trial", "--db", "{d}/notes.db", "--session", "1", "--trial", "1", "--out", "{d}/t.png"),
         "notes.db: not a haptic-study database", {"notes.db": _text("minutes of the lab meeting\n" * 200)}),
    Case("database: a folder", (*CONTINUE, "{d}/study.db"), "study.db: is a directory, not a database file",
         {"study.db": folder, **TINY}),
    Case("database: report into a non-empty folder", ("report", "--db", "{d}/good.db", "--out", "{d}/out"),
         "out: the folder exists and holds ", {"good.db": good_db, "out": folder}),
    Case("database: read-only, run --continue", (*CONTINUE, "{d}/good.db"), "good.db: the database is not writable",
         {"good.db": good_db, **TINY}, read_only="good.db"),
    Case("database: damaged, run --continue", (*CONTINUE, "{d}/damaged.db"), "damaged.db: the database is damaged",
         {"damaged.db": damaged_db, **TINY}),
    Case("database: damaged, report", ("report", "--db", "{d}/damaged.db", "--out", "{d}/out"),
         "damaged.db: the database is damaged", {"damaged.db": damaged_db}),
    Case("database: damaged, plot-trial",
         ("plot-trial", "--db", "{d}/damaged.db", "--session", "1", "--trial", "1", "--out", "{d}/t.png"),
         "damaged.db: the database is damaged", {"damaged.db": damaged_db}),
]



GOOD = {"good.db": good_db}
HW_CHECK = ("check-hardware", "--hardware", "{d}/hw.toml")
CAL_FRAMES = ("calibrate", "frames", "--rig", "real", "--hardware", "{d}/hw.toml")
_TIP = "rot_tip_sensor = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]     # sensor coaxial with the instrument"
_HAPTIC = "rot_haptic_base = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]   # experimenter facing the robot along base +y"


def _teleop_hw(extra: str) -> Builder:
    """The example file in teleop mode, with ``extra`` lines in its [teleop] table."""
    text = EXAMPLE_HARDWARE.replace('mode = "observe"', 'mode = "teleop"')
    text += f"\n[teleop]\nworkspace_min_m = [0.2, -0.1, 0.05]\nworkspace_max_m = [0.4, 0.1, 0.25]\n{extra}\n"
    return _text(text)


# -- part 1, added by issue 22: values valid alone but not together, what sets a force's direction or size, odd
# -- files where a file was expected, the arguments of the commands that write, and every command on a bad database
CASES += [
    # protocol: values valid alone but not together (the ramps are the safety stage's, pipeline/force/safety.py)
    Case("protocol: a trial shorter than ramp-in + hold", RUN_NEW,
         "p.toml: trial.max_trial_s = 1.2: must be at least trial.hold_s = 1 + the feedback's 0.5 s ramp-in",
         {"p.toml": protocol("max_trial_s = 12.0 ", "max_trial_s = 1.2 ")}),
    Case("protocol: the issue's 2 ms trial", RUN_NEW,
         "p.toml: trial.max_trial_s = 0.002: must be at least trial.hold_s = 0.001 + the feedback's 0.5 s ramp-in",
         {"p.toml": _text(DEFAULT_PROTOCOL.replace("max_trial_s = 12.0 ", "max_trial_s = 0.002 ")
                          .replace("hold_s = 1.0 ", "hold_s = 0.001 "))}),
    Case("protocol: training trials shorter than ramp-in + hold", RUN_NEW,
         "p.toml: training.seconds_per_target_per_mode = 1.25: must be at least trial.hold_s = 1 + the feedback's",
         {"p.toml": protocol("seconds_per_target_per_mode = 20.0", "seconds_per_target_per_mode = 1.25")}),
    Case("protocol: a pause shorter than the ramp-out", RUN_NEW,
         "p.toml: trial.pause_s = 0.03: must be at least the feedback's 0.04 s ramp-out (safety.fault_ramp_s)",
         {"p.toml": protocol("pause_s = 2.0 ", "pause_s = 0.03 ")}),
    Case("protocol: no pause with haptics ON", RUN_NEW, "p.toml: trial.pause_s = 0.0: must be at least the feedback's",
         {"p.toml": protocol("pause_s = 2.0 ", "pause_s = 0.0 ")}),
    Case("protocol: no targets", RUN_NEW, "p.toml: targets = []: must be a list of 1 to 8 [[targets]] tables",
         {"p.toml": _text(DEFAULT_PROTOCOL.split("[[targets]]")[0] + "targets = []\n"
                          + DEFAULT_PROTOCOL[DEFAULT_PROTOCOL.index("[design]"):])}),
    Case("protocol: a target of 0 N", RUN_NEW, "p.toml: targets[0].force_n = 0.0: must be a number > 0 and ≤ 20",
         {"p.toml": protocol("force_n = 0.6", "force_n = 0.0")}),
    Case("protocol: a target of 21 N", RUN_NEW, "p.toml: targets[1].force_n = 21.0: must be a number > 0 and ≤ 20",
         {"p.toml": protocol("force_n = 1.2", "force_n = 21.0")}),
    Case("protocol: a zero tolerance", RUN_NEW, "p.toml: trial.tolerance_fraction = 0.0: must be a number > 0",
         {"p.toml": protocol("tolerance_fraction = 0.10 ", "tolerance_fraction = 0.0 ")}),
    Case("protocol: a negative cue", RUN_NEW, "p.toml: trial.cue_s = -1.0: must be a number from 0 to 60",
         {"p.toml": protocol("cue_s = 1.0 ", "cue_s = -1.0 ")}),
    Case("protocol: a cue longer than the trial cap (issue 40, item 9)", RUN_NEW,
         "p.toml: trial.cue_s = 30.0: must be shorter than trial.max_trial_s = 12",
         {"p.toml": protocol("cue_s = 1.0 ", "cue_s = 30.0 ")}),
    Case("protocol: a mode twice", RUN_NEW, "p.toml: design.modes = ['on', 'on']: must be a non-empty list of distinct",
         {"p.toml": protocol('modes = ["on", "off"]', 'modes = ["on", "on"]')}),
    Case("protocol: version 2", RUN_NEW, "p.toml: version = 2: this software reads protocol version 1",
         {"p.toml": protocol("version = 1", "version = 2")}),
    Case("protocol: training enabled as text", RUN_NEW, "p.toml: training.enabled = 'yes': must be true or false",
         {"p.toml": protocol("enabled = true", 'enabled = "yes"')}),
    Case("protocol: a trial cap of 601 s", RUN_NEW, "p.toml: trial.max_trial_s = 601.0: must be a number > 0 and ≤ 600",
         {"p.toml": protocol("max_trial_s = 12.0 ", "max_trial_s = 601.0 ")}),
    Case("protocol: a FIFO", RUN_NEW, "--protocol {d}/p.toml: is a FIFO (named pipe), not a protocol file",
         {"p.toml": fifo}),
    Case("protocol: a device", ("run", "--participants", "1", "--db", "{d}/new.db", "--protocol", "/dev/zero"),
         "--protocol /dev/zero: is a device, not a protocol file"),
    # hardware: what sets a rendered force's direction or size has no default on a real rig
    Case("hardware: no rot_tip_sensor, check-hardware", HW_CHECK,
         "hw.toml: frames.rot_tip_sensor = None: required on a real rig: the sensor's mounting on the instrument",
         {"hw.toml": hardware(_TIP, "")}),
    Case("hardware: no rot_tip_sensor, calibrate frames", CAL_FRAMES,
         "hw.toml: frames.rot_tip_sensor = None: required on a real rig", {"hw.toml": hardware(_TIP, "")}),
    Case("hardware: no rot_tip_sensor, gui --rig real", ("gui", "--rig", "real", "--hardware", "{d}/hw.toml"),
         "hw.toml: frames.rot_tip_sensor = None: required on a real rig", {"hw.toml": hardware(_TIP, "")}),
    Case("hardware: no rot_haptic_base", HW_CHECK,
         "hw.toml: frames.rot_haptic_base = None: required on a real rig: how the experimenter faces the robot",
         {"hw.toml": hardware(_HAPTIC, "")}),
    Case("hardware: no f_max", HW_CHECK, "hw.toml: framework.f_max_n = None: required on a real rig",
         {"hw.toml": hardware("f_max_n = 3.0", "")}),
    Case("hardware: no f_scale", HW_CHECK, "hw.toml: framework.f_scale_n = None: required on a real rig",
         {"hw.toml": hardware("f_scale_n = 7.0", "")}),
    Case("hardware: counts without their unit", HW_CHECK,
         "hw.toml: sensor.force_unit = None: required with sensor.counts_per_force",
         {"hw.toml": hardware("# counts_per_force = 1000000  # ... unless given here (both or neither), e.g. when "
                              "the web page is disabled\n# counts_per_torque = 1000000",
                              "counts_per_force = 1000000\ncounts_per_torque = 1000000")}),
    Case("hardware: a robot too slow for the watchdog", HW_CHECK,
         "hw.toml: robot.frequency_hz = 10: must be above 20 Hz: the watchdog faults when the robot pose is older",
         {"hw.toml": hardware("frequency_hz = 125 ", "frequency_hz = 10 ")}),
    Case("hardware: a teleop pose age below the robot's period", HW_CHECK,
         "hw.toml: teleop.pose_max_age_s = 0.005: must be longer than the robot's pose period",
         {"hw.toml": _teleop_hw("pose_max_age_s = 0.005")}),
    Case("hardware: a reflection for a rotation", HW_CHECK, "hw.toml: frames.rot_tip_sensor = ",
         {"hw.toml": hardware("rot_tip_sensor = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]",
                              "rot_tip_sensor = [[1, 0, 0], [0, 1, 0], [0, 0, -1]]")}),
    Case("hardware: f_scale of 0", HW_CHECK, "hw.toml: framework.f_scale_n = 0.0: must be a number > 0",
         {"hw.toml": hardware("f_scale_n = 7.0", "f_scale_n = 0.0")}),
    Case("hardware: a command timeout of 1 ms", HW_CHECK,
         "hw.toml: haptic.command_timeout_s = 0.001: must be a number from 0.002 to 0.05",
         {"hw.toml": hardware("command_timeout_s = 0.010", "command_timeout_s = 0.001")}),
    Case("hardware: both jaw buttons the same", HW_CHECK,
         "hw.toml: jaw.open_button = 1: must differ from jaw.close_button",
         {"hw.toml": hardware("open_button = 2 ", "open_button = 1 ")}),
    Case("hardware: an inverted teleop box", HW_CHECK, "hw.toml: teleop.workspace_max_m = ",
         {"hw.toml": _text(EXAMPLE_HARDWARE.replace('mode = "observe"', 'mode = "teleop"')
                           + "\n[teleop]\nworkspace_min_m = [0.4, 0.1, 0.25]\nworkspace_max_m = [0.2, -0.1, 0.05]\n")}),
    Case("hardware: a FIFO", HW_CHECK, "--hardware {d}/hw.toml: is a FIFO (named pipe), not a hardware file",
         {"hw.toml": fifo}),
    Case("hardware: a folder", HW_CHECK, "hw.toml: cannot read the hardware file", {"hw.toml": folder}),
    # the arguments of the commands that write
    Case("power --n 1", ("power", "--db", "{d}/good.db", "--out", "{d}/p", "--n", "1"),
         "--n = '1': each n must be a whole number from 2 to 10000", GOOD),
    Case("power --n 10001", ("power", "--db", "{d}/good.db", "--out", "{d}/p", "--n", "6,10001"),
         "--n = '6,10001': each n must be a whole number from 2 to 10000", GOOD),
    Case("power --resamples 0", ("power", "--db", "{d}/good.db", "--out", "{d}/p", "--resamples", "0"),
         "--resamples = '0': must be a whole number from 1 to 1000000", GOOD),
    Case("power --resamples 10**7", ("power", "--db", "{d}/good.db", "--out", "{d}/p", "--resamples", "10000000"),
         "--resamples = '10000000': must be a whole number from 1 to 1000000", GOOD),
    Case("power --alpha 1", ("power", "--db", "{d}/good.db", "--out", "{d}/p", "--alpha", "1"),
         "--alpha = '1': must be a number with 0 < alpha < 1", GOOD),
    Case("power --alpha nan", ("power", "--db", "{d}/good.db", "--out", "{d}/p", "--alpha", "nan"),
         "--alpha = 'nan': must be a number with 0 < alpha < 1", GOOD),
    Case("power without --out", ("power", "--db", "{d}/good.db"), "--out: give the output folder", GOOD),
    Case("power with --db and --simulated", ("power", "--db", "{d}/good.db", "--simulated", "--out", "{d}/p"),
         "--db and --simulated: give one or the other", GOOD),
    Case("power --pool without --simulated", ("power", "--db", "{d}/good.db", "--pool", "50", "--out", "{d}/p"),
         "--pool = '50': only with --simulated", GOOD),
    Case("power without a source", ("power", "--out", "{d}/p"), "power needs a source"),
    Case("power --simulated --pool 3", ("power", "--simulated", "--pool", "3", "--out", "{d}/p"),
         "--pool = '3': must be a whole number from 4 to 10000"),
    Case("export --format parquet to standard output", ("export", "samples", "--db", "{d}/good.db", "--format",
                                                       "parquet", "--out", "-"),
         "--out -: standard output takes --format csv only", GOOD),
    Case("export --format xlsx", ("export", "samples", "--db", "{d}/good.db", "--format", "xlsx", "--out", "{d}/x"),
         "invalid choice: 'xlsx'", GOOD),
    Case("export --session 0", ("export", "samples", "--db", "{d}/good.db", "--session", "0", "--out", "{d}/x.csv"),
         "--session = '0': must be a whole number from 1", GOOD),
    Case("replay --filter-window 0", ("replay", "--db", "{d}/good.db", "--session", "1", "--filter-window", "0"),
         "--filter-window = '0': must be a whole number from 1 to 1000", GOOD),
    Case("replay --f-scale -1", ("replay", "--db", "{d}/good.db", "--session", "1", "--f-scale", "-1"),
         "--f-scale = '-1': must be a number from 1e-06 to 1000", GOOD),
    Case("replay --f-max inf", ("replay", "--db", "{d}/good.db", "--session", "1", "--f-max", "inf"),
         "--f-max = 'inf': must be a number from 1e-06 to 100", GOOD),
    # below the scaling law's own bound: refused in the option's name before any work, not as safety.f_max_n after it
    Case("replay --f-max 1e-7", ("replay", "--db", "{d}/good.db", "--session", "1", "--f-max", "1e-7"),
         "--f-max = '1e-7': must be a number from 1e-06 to 100", GOOD),
    Case("replay --f-scale 1e-9", ("replay", "--db", "{d}/good.db", "--session", "1", "--f-scale", "1e-9"),
         "--f-scale = '1e-9': must be a number from 1e-06 to 1000", GOOD),
    Case("plot-session --out a .jpg", ("plot-session", "--db", "{d}/good.db", "--session", "1", "--out", "{d}/s.jpg"),
         "s.jpg: must end in .png, .pdf or .svg", GOOD),
    Case("plot-trial --out a .txt", ("plot-trial", "--db", "{d}/good.db", "--session", "1", "--trial", "1", "--out",
                                    "{d}/t.txt"), "the file name must end in .png, .pdf or .svg", GOOD),
    Case("report --zero-method median", ("report", "--db", "{d}/good.db", "--out", "{d}/r", "--zero-method", "median"),
         "invalid choice: 'median'", GOOD),
    Case("report --confidence 1", ("report", "--db", "{d}/good.db", "--out", "{d}/r", "--confidence", "1"),
         "--confidence = '1': must be in [0.5, 1)", GOOD),
    Case("report without --out", ("report", "--db", "{d}/good.db"), "the following arguments are required: --out",
         GOOD),
    Case("gui --force without --screenshot", ("gui", "--force"), "--force applies to --screenshot DIR only"),
    Case("gui --screenshot on the real rig", ("gui", "--screenshot", "{d}/s", "--rig", "real", "--hardware",
                                              "{d}/hw.toml"),
         "--screenshot runs on the simulated rig only", {"hw.toml": _text(EXAMPLE_HARDWARE)}),
    Case("run --inject-fault of an unknown kind", ("run", "--db", "{d}/new.db", "--inject-fault", "fire@P01:2"),
         "--inject-fault = 'fire@P01:2': kind 'fire' is not one of"),
    Case("run --inject-fault at trial 0", ("run", "--db", "{d}/new.db", "--inject-fault", "kill@P01:0"),
         "--inject-fault = 'kill@P01:0': trial '0' must be a whole number ≥ 1"),
    # every command on a bad database: one line, the file untouched
    *[Case(f"database: {what}, {cmd[0]}", (*cmd[:1], "--db", f"{{d}}/{name}", *cmd[1:]), says, {name: build})
      for name, build, what, says in (("damaged.db", damaged_db, "damaged", "damaged.db: the database is damaged"),
                                      ("other.db", foreign_db, "foreign", "other.db: not a haptic-study database"),
                                      ("newer.db", newer_db, "newer", "newer.db: database schema version 99 is newer"))
      for cmd in (("replay", "--session", "1"), ("plot-session", "--session", "1", "--out", "{d}/s.png"),
                  ("sessions",))],
    Case("database: damaged, export", ("export", "samples", "--db", "{d}/damaged.db", "--out", "{d}/x.csv"),
         "damaged.db: the database is damaged", {"damaged.db": damaged_db}),
    Case("database: foreign, export", ("export", "samples", "--db", "{d}/other.db", "--out", "{d}/x.csv"),
         "other.db: not a haptic-study database", {"other.db": foreign_db}),
    Case("database: damaged, power", ("power", "--db", "{d}/damaged.db", "--out", "{d}/p"),
         "damaged.db: the database is damaged", {"damaged.db": damaged_db}),
    Case("database: an empty file, sessions", ("sessions", "--db", "{d}/empty.db"), "empty.db: ",
         {"empty.db": _text(b"")}),
    Case("database: a FIFO, report", ("report", "--db", "{d}/study.db", "--out", "{d}/r"),
         "--db {d}/study.db: is a FIFO (named pipe), not a database file", {"study.db": fifo}),
    Case("database: a FIFO, run", ("run", "--db", "{d}/study.db"),
         "--db {d}/study.db: is a FIFO (named pipe), not a database file", {"study.db": fifo}),
    Case("database: a FIFO, replay", ("replay", "--db", "{d}/study.db", "--session", "1"),
         "--db {d}/study.db: is a FIFO (named pipe), not a database file", {"study.db": fifo}),
    Case("database: a FIFO, power", ("power", "--db", "{d}/study.db", "--out", "{d}/p"),
         "--db {d}/study.db: is a FIFO (named pipe), not a database file", {"study.db": fifo}),
    Case("database: a device, sessions", ("sessions", "--db", "/dev/zero"), "--db /dev/zero: is a device"),
    Case("database: a device, run", ("run", "--db", "/dev/null"), "--db /dev/null: is a device"),
    Case("database: a folder, sessions", ("sessions", "--db", "{d}/study.db"),
         "study.db': is a folder, not a database file",
         {"study.db": folder}),
    Case("database: no such file, replay", ("replay", "--db", "{d}/none.db", "--session", "1"), "none.db: "),
    Case("database: no such file, export", ("export", "samples", "--db", "{d}/none.db", "--out", "{d}/x.csv"),
         "none.db: "),
    Case("database: no such session, replay", ("replay", "--db", "{d}/good.db", "--session", "7"),
         "--session 7: no such session", GOOD),
    Case("database: no such session, plot-session", ("plot-session", "--db", "{d}/good.db", "--session", "7",
                                                     "--out", "{d}/s.png"), "--session 7: no such session", GOOD),
    Case("database: no such session, export", ("export", "samples", "--db", "{d}/good.db", "--session", "7",
                                               "--out", "{d}/x.csv"), "no session 7", GOOD),
]
