"""Where an arm's qualification record lies and how it is read (``haptic-study qualify`` writes it; docs/qualify.md).

The record is JSON beside the arm's calibration file, named after it (``calibration.json`` →
``calibration.qualification.json``): the software version, the date, and each check's measured value, bound and
verdict.  ``check-hardware`` shows it and a real-rig session stores it in its ``config_json`` (``qualification``),
so the report's methods can name it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

__all__ = ["CHECKS", "read_record", "record_path"]

#: The checks of ``haptic-study qualify`` by name, in the order they run (docs/qualify.md).
CHECKS = ("process-death", "thermal-budget", "latency", "loop-under-load")

#: The calibration file's name when the hardware file names none (pipeline.settings.hardware's default).
_DEFAULT_CALIBRATION = "calibration.json"


def record_path(calibration_file: str | None) -> Path:
    """Where an arm's qualification record lies: beside its calibration file, named after it."""
    cal = Path(calibration_file or _DEFAULT_CALIBRATION)
    return cal.with_name(cal.stem + ".qualification.json")


def read_record(calibration_file: str | None) -> dict[str, Any] | None:
    """The arm's qualification record (None when it was never qualified).

    Raises
    ------
    ValueError
        The record is not a qualification record (not JSON, or without its verdict, date, version and checks).
    OSError
        It cannot be read.
    """
    path = record_path(calibration_file)
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    if not (isinstance(record, dict) and {"verdict", "date", "software_version", "checks"} <= record.keys()
            and isinstance(record["checks"], list)):
        raise ValueError(f"{path}: not a qualification record")
    return record
