"""``haptic-study qualify``: qualify one arm of the real rig, and keep the record beside its calibration file.

The checks are :mod:`study_app.cli.qualify_checks`'s and :mod:`study_app.cli.qualify_engine`'s (docs/qualify.md:
what each does, its bound and its source).  Progress goes to stderr, one ``qualify: …`` line at a time.
The record (:mod:`pipeline.commissioning.qualification`: ``calibration.json`` → ``calibration.qualification.json``)
is JSON: the software version, the date, the hardware file and arm, and each check's measured value, bound and
verdict.
``check-hardware`` shows it (:func:`describe_record`).  A check not done is ``NOT CHECKED`` with why, never a pass.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from pipeline.commissioning.qualification import CHECKS, read_record, record_path
from pipeline.commissioning.rig_calibration import write_text_atomically
from study_app.cli.argtypes import add_command, arm_name
from study_app.cli.error import CliError
from study_app.guide_paths import hardware_template

#: The checks that run the loop on the rig (one engine run serves both: :mod:`study_app.cli.qualify_engine`).
ENGINE_CHECKS = ("latency", "loop-under-load")
#: How long the loop-under-load check measures by default, s (the bench's quiet-machine figure is 30 s; a minute
#: catches the few-a-minute stalls a machine may have).
DEFAULT_SECONDS = 60.0
#: The most ``--seconds`` allows, s.
MAX_SECONDS = 3600.0


def parse_checks(text: str) -> tuple[str, ...]:
    """``--checks``'s names (comma-separated), in :data:`CHECKS`' order; :class:`CliError` on an unknown name."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in CHECKS]
    if unknown or not names:
        raise CliError(f"--checks = {text!r}: must name one or more of {', '.join(CHECKS)} (comma-separated)")
    return tuple(c for c in CHECKS if c in names)


def parse_seconds(text: str) -> float:
    """``--seconds``: how long the loop is measured; :class:`CliError` outside 1 s … :data:`MAX_SECONDS`."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 1.0 <= value <= MAX_SECONDS:  # (NaN fails too)
        raise CliError(f"--seconds = {text!r}: must be a number of seconds from 1 to {MAX_SECONDS:g}")
    return value


def _say(line: str) -> None:
    """Progress, on stderr (the record is stdout's; the GUI shows these lines as they come)."""
    print(f"qualify: {line}", file=sys.stderr, flush=True)


def qualify(hardware: str, arm: str | None, checks: tuple[str, ...],
            seconds: float = DEFAULT_SECONDS) -> tuple[dict[str, Any], Path]:
    """Run ``checks`` on the arm of ``hardware`` (``arm``: its name, None for a one-arm rig); the record and where it
    was written.  :class:`CliError` on a bad hardware file or arm, before any device is touched."""
    from foundation.version import software_version
    from pipeline.settings.hardware import HardwareError, load_hardware
    from study_app.cli.calibrate_cmds import chosen_arm
    from study_app.cli.qualify_checks import CheckResult, process_death, thermal_budget
    from study_app.cli.qualify_engine import engine_checks

    try:
        hw = load_hardware(hardware)
    except HardwareError as exc:
        raise CliError(str(exc)) from None
    one = chosen_arm(tuple(a.name for a in hw.arms), arm, hardware)
    settings = next(a for a in hw.arms if a.name == one)
    results: list[CheckResult] = []
    engine: dict[str, CheckResult] = {}
    for name in checks:
        _say(f"{name}: running")
        if name == "process-death":
            results.append(process_death(hardware, settings))
        elif name == "thermal-budget":
            results.append(thermal_budget(settings))
        else:
            if not engine:
                engine = engine_checks(hardware, settings, tuple(c for c in checks if c in ENGINE_CHECKS), seconds,
                                       _say)
            results.append(engine[name])
        _say(f"{name}: {results[-1].verdict}")
    verdicts = {r.verdict for r in results}
    record = {
        "software_version": software_version(),
        "date": datetime.now(UTC).isoformat(timespec="seconds"),
        "hardware_file": str(Path(hardware).resolve()),
        "arm": settings.name,
        "device": {"model": settings.haptic.model, "name": settings.haptic.device_name},
        "verdict": "FAIL" if "FAIL" in verdicts else "PASS" if verdicts == {"PASS"} else "PARTIAL",
        "checks": [r.as_dict() for r in results],
    }
    path = record_path(settings.calibration_file)
    _write_atomically(path, json.dumps(record, indent=2) + "\n")
    return record, path


def _write_atomically(path: Path, text: str) -> None:
    """Write ``path`` whole or not at all, as the calibration file beside it is written."""
    try:
        write_text_atomically(path, text)
    except OSError as exc:
        raise CliError(f"{path}: the qualification record cannot be written ({exc.strerror or exc})",
                       status=1) from None


def format_record(record: dict[str, Any]) -> str:
    """A line per check, and the verdict."""
    width = max(len(c["name"]) for c in record["checks"])
    lines = [f"qualify {record['arm']} ({record['device']['name']}), software {record['software_version']}, "
             f"{record['date']}"]
    for c in record["checks"]:
        text = c["measured"] if c["verdict"] != "NOT CHECKED" else f"({c['why']})"
        if c["verdict"] == "FAIL":
            text += f": {c['why']}"
        lines.append(f"  {c['name']:<{width}} {c['verdict']:<11} {text}" + (f"  [bound {c['bound']}]"
                                                                           if c["bound"] else ""))
    lines.append(f"verdict: {record['verdict']}")
    return "\n".join(lines)


def describe_record(calibration_file: str | None) -> str | None:
    """The arm's qualification in one line for ``check-hardware`` (None when it was never qualified)."""
    try:
        record = read_record(calibration_file)
        if record is None:
            return None
        checks = ", ".join(f"{c['name']} {c['verdict']}" for c in record["checks"])
        return f"{record['verdict']} on {record['date']} (software {record['software_version']}): {checks}"
    except (OSError, ValueError, KeyError, TypeError) as exc:
        return f"unreadable qualification record ({exc})"


def add_qualify_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``qualify``."""
    q = add_command(sub, "qualify", "qualify one arm of the real rig (process death, thermal budget, end-to-end "
                    "latency, the loop under the lab's load) and keep the record beside its calibration file",
                    "haptic-study qualify --hardware hardware.toml")
    q.add_argument("--hardware", default="hardware.toml", metavar="FILE",
                   help=f"hardware file (default ./hardware.toml; see {hardware_template()})")
    q.add_argument("--arm", type=arm_name("--arm"), default=None, metavar="NAME",
                   help="a rig of several arms: the arm to qualify")
    q.add_argument("--checks", default=",".join(CHECKS), metavar="NAMES",
                   help=f"comma-separated checks to run (default all: {', '.join(CHECKS)})")
    q.add_argument("--seconds", default=repr(DEFAULT_SECONDS), metavar="S",
                   help=f"how long loop-under-load measures the loop (default {DEFAULT_SECONDS:g} s; 1 to "
                        f"{MAX_SECONDS:g}): run it while the machine is as the lab uses it")
    q.add_argument("--json", action="store_true", help="print the record as JSON")
    q.set_defaults(handler=cmd_qualify)


def cmd_qualify(args: argparse.Namespace) -> int:
    """Run ``haptic-study qualify``: 0 when no check failed (a check not done is shown, never passed), 1 when one
    failed."""
    checks = parse_checks(args.checks)
    seconds = parse_seconds(args.seconds)
    record, path = qualify(args.hardware, args.arm, checks, seconds)
    print(json.dumps(record) if args.json else format_record(record) + f"\nrecord: {path}")
    return 1 if record["verdict"] == "FAIL" else 0
