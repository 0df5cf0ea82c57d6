"""``haptic-study qualify``: qualify one arm of the real rig, and keep the record beside its calibration file.

The checks are :mod:`study_app.cli.qualify_checks`'s (docs/qualify.md: what each does, its bound and its source).
The record (:mod:`pipeline.commissioning.qualification`: ``calibration.json`` → ``calibration.qualification.json``)
is JSON: the software version, the date, the hardware file and arm, and each check's measured value, bound and
verdict.
``check-hardware`` shows it (:func:`describe_record`).  A check not done is ``NOT CHECKED`` with why, never a pass.
"""

from __future__ import annotations

import argparse
import json
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from pipeline.commissioning.qualification import read_record, record_path
from pipeline.commissioning.rig_calibration import write_text_atomically
from study_app.cli.argtypes import add_command, arm_name
from study_app.cli.error import CliError
from study_app.guide_paths import hardware_template

#: The checks by name, in the order they run.
CHECKS = ("process-death", "thermal-budget", "latency")

#: Why the latency is not a check of this command (yet): said in its record, never passed.
_LATENCY_WHY = ("not measured by qualify in this version: a real-rig session measures and stores it when it "
                "starts, and the report's methods give it")


def parse_checks(text: str) -> tuple[str, ...]:
    """``--checks``'s names (comma-separated), in :data:`CHECKS`' order; :class:`CliError` on an unknown name."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in CHECKS]
    if unknown or not names:
        raise CliError(f"--checks = {text!r}: must name one or more of {', '.join(CHECKS)} (comma-separated)")
    return tuple(c for c in CHECKS if c in names)


def qualify(hardware: str, arm: str | None, checks: tuple[str, ...]) -> tuple[dict[str, Any], Path]:
    """Run ``checks`` on the arm of ``hardware`` (``arm``: its name, None for a one-arm rig); the record and where it
    was written.  :class:`CliError` on a bad hardware file or arm, before any device is touched."""
    from foundation.version import software_version
    from pipeline.settings.hardware import HardwareError, load_hardware
    from study_app.cli.calibrate_cmds import chosen_arm
    from study_app.cli.qualify_checks import CheckResult, not_checked, process_death, thermal_budget

    try:
        hw = load_hardware(hardware)
    except HardwareError as exc:
        raise CliError(str(exc)) from None
    one = chosen_arm(tuple(a.name for a in hw.arms), arm, hardware)
    settings = next(a for a in hw.arms if a.name == one)
    results: list[CheckResult] = []
    for name in checks:
        if name == "process-death":
            results.append(process_death(hardware, settings))
        elif name == "thermal-budget":
            results.append(thermal_budget(settings))
        else:
            results.append(not_checked(name, _LATENCY_WHY))
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
    q = add_command(sub, "qualify", "qualify one arm's real haptic device (process death, thermal budget) and keep "
                    "the record beside its calibration file", "haptic-study qualify --hardware hardware.toml")
    q.add_argument("--hardware", default="hardware.toml", metavar="FILE",
                   help=f"hardware file (default ./hardware.toml; see {hardware_template()})")
    q.add_argument("--arm", type=arm_name("--arm"), default=None, metavar="NAME",
                   help="a rig of several arms: the arm to qualify")
    q.add_argument("--checks", default=",".join(CHECKS), metavar="NAMES",
                   help=f"comma-separated checks to run (default all: {', '.join(CHECKS)})")
    q.add_argument("--json", action="store_true", help="print the record as JSON")
    q.set_defaults(handler=cmd_qualify)


def cmd_qualify(args: argparse.Namespace) -> int:
    """Run ``haptic-study qualify``: 0 when no check failed (a check not done is shown, never passed), 1 when one
    failed."""
    checks = parse_checks(args.checks)
    record, path = qualify(args.hardware, args.arm, checks)
    print(json.dumps(record) if args.json else format_record(record) + f"\nrecord: {path}")
    return 1 if record["verdict"] == "FAIL" else 0
