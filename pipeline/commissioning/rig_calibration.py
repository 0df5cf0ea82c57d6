"""The calibration file: what is on record for each instrument, and whether a session may start.

The commissioning chain runs in order -- **TCP** (:mod:`pipeline.commissioning.tcp`),
**payload/bias** (:mod:`pipeline.force.payload_compensator`), **frames and signs**
(:mod:`pipeline.commissioning.frame_check`) -- and each accepted result is saved, with its
date, under the name of the mounted tool in one JSON file (the hardware file's
``[calibration] file``, ``calibration.json`` next to it by default)::

    {"format": "haptic-study calibration", "version": 1,
     "tools": {"grasper": {"tcp":     {"date": "...", ...TipCalibration.to_dict()},
                           "payload": {"date": "...", ...PayloadCalibration.to_dict()},
                           "frames":  {"date": "...", ...FrameCheck.to_dict()}}}}

One file holds every tool of the lab (the paper's instrument takes
interchangeable tips), so changing ``[calibration] tool`` switches to that
tool's record without losing the others.  A file holding a bare payload
calibration (``PayloadCalibration.to_dict()``, the earlier format) reads as
that payload, date unknown, for whichever tool is mounted.

:meth:`ToolCalibration.missing` is the gate of the real rig: a session starts
only with a TCP, a payload and a passed frame check on record for the mounted
tool (the frame check made with the ``[frames]`` rotations in use), checked
in that order so the one line names the first step to do.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from pipeline.commissioning.frame_check import FrameCheck
from pipeline.commissioning.tcp import TipCalibration
from pipeline.force.frames import Mat3
from pipeline.force.payload_compensator import PayloadCalibration

__all__ = [
    "CALIBRATION_FORMAT",
    "STEPS",
    "CalibrationFileError",
    "RigCalibrationFile",
    "ToolCalibration",
    "now_iso",
    "write_text_atomically",
]

CALIBRATION_FORMAT = "haptic-study calibration"
_VERSION = 1
#: The commissioning steps, in the order they must be done.
STEPS = ("tcp", "payload", "frames")
#: How each step is run, for the gate's message.
_HOW = {
    "tcp": "haptic-study calibrate tcp --rig real --hardware FILE (or the calibration wizard's TCP step)",
    "payload": "haptic-study calibrate payload --rig real --hardware FILE (or the wizard's Payload step)",
    "frames": "haptic-study calibrate frames --rig real --hardware FILE (or the wizard's Frames step)",
}


class CalibrationFileError(ValueError):
    """The calibration file cannot be read or written; the message names it and why."""


def now_iso() -> str:
    """The current time, UTC, ISO 8601 to the second (the date stored with each step)."""
    return _dt.datetime.now(_dt.UTC).replace(microsecond=0).isoformat()


@dataclass(frozen=True)
class ToolCalibration:
    """What is on record for one tool: each step's result and when it was accepted ("" = not on record)."""

    tool: str
    tcp: TipCalibration | None = None
    tcp_date: str = ""
    payload: PayloadCalibration | None = None
    payload_date: str = ""
    frames: FrameCheck | None = None
    frames_date: str = ""

    def with_step(self, step: str, result: Any, date: str | None = None) -> ToolCalibration:
        """A copy with ``step``'s result replaced (dated now unless ``date`` is given)."""
        if step not in STEPS:
            raise ValueError(f"calibration step = {step!r}: allowed values are {', '.join(STEPS)}")
        return replace(self, **{step: result, f"{step}_date": date if date is not None else now_iso()})

    def missing(self, rot_tip_sensor: Mat3, rot_haptic_base: Mat3) -> str:
        """"" when a session may start; else one line naming the first step to do (and how)."""
        t = self.tool
        if self.tcp is None:
            why = f"no TCP calibration on record for tool {t!r}"
            step = "tcp"
        elif self.payload is None:
            why = f"no payload calibration on record for tool {t!r}"
            step = "payload"
        elif self.frames is None:
            why = f"no frame and sign check on record for tool {t!r}"
            step = "frames"
        elif not self.frames.matches(rot_tip_sensor, rot_haptic_base):
            why = (f"the frame check on record for tool {t!r} was made with other [frames] rotations than the ones "
                   "in use")
            step = "frames"
        elif not self.frames.passed:
            why = f"the frame check on record for tool {t!r} failed ({self.frames.summary().split(': ', 1)[1]})"
            step = "frames"
        else:
            return ""
        return f"{why}: run {_HOW[step]}"

    def status(self) -> list[tuple[str, bool, str]]:
        """Per step: (name, on record and usable, one-line summary) -- for displays."""
        out: list[tuple[str, bool, str]] = []
        if self.tcp is not None:
            x, y, z = (v * 1e3 for v in self.tcp.tip_in_flange_m)
            out.append(("TCP", True, f"tip ({x:.1f}, {y:.1f}, {z:.1f}) mm in the flange frame, RMS residual "
                                     f"{self.tcp.rms_residual_m * 1e3:.2f} mm ({_date(self.tcp_date)})"))
        else:
            out.append(("TCP", False, "not on record"))
        if self.payload is not None:
            p = self.payload
            out.append(("payload", True, f"{p.mass_kg:.3f} kg, RMS residual {p.rms_force_residual_n * 1e3:.1f} mN "
                                         f"({_date(self.payload_date)})"))
        else:
            out.append(("payload", False, "not on record"))
        if self.frames is not None:
            out.append(("frames", self.frames.passed, ("passed" if self.frames.passed else "FAILED")
                        + f" ({_date(self.frames_date)})"))
        else:
            out.append(("frames", False, "not on record"))
        return out

    def to_dict(self) -> dict[str, Any]:
        """The tool's entry of the file."""
        out: dict[str, Any] = {}
        for step in STEPS:
            res = getattr(self, step)
            if res is not None:
                out[step] = {"date": getattr(self, f"{step}_date"), **res.to_dict()}
        return out

    @classmethod
    def from_dict(cls, tool: str, d: Mapping[str, Any]) -> ToolCalibration:
        """A tool's entry of the file; :class:`ValueError` naming the step and field."""
        if not isinstance(d, Mapping):
            raise ValueError(f"tool {tool!r}: must be a table of steps")
        kwargs: dict[str, Any] = {}
        for step, parse in (("tcp", TipCalibration.from_dict), ("payload", PayloadCalibration.from_dict),
                            ("frames", FrameCheck.from_dict)):
            if step in d:
                entry = d[step]
                if not isinstance(entry, Mapping):
                    raise ValueError(f"tool {tool!r} {step}: must be a table")
                try:
                    kwargs[step] = parse(entry)
                except ValueError as exc:
                    raise ValueError(f"tool {tool!r} {step}: {exc}") from None
                kwargs[f"{step}_date"] = str(entry.get("date", ""))
        return cls(tool, **kwargs)


def _date(iso: str) -> str:
    return iso.replace("T", " ").replace("+00:00", " UTC") if iso else "date unknown"


@dataclass
class RigCalibrationFile:
    """The calibration file of a rig: every tool's record (read with :meth:`load`, written with :meth:`save`)."""

    path: str
    tools: dict[str, ToolCalibration] = field(default_factory=dict)
    #: The file held a bare payload calibration (the earlier format): it applies to whichever tool is mounted.
    legacy_payload: PayloadCalibration | None = None

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> RigCalibrationFile:
        """Read the file; a file that does not exist yet is an empty record.

        Raises
        ------
        CalibrationFileError
            One line naming the file and what is wrong with it.
        """
        p = str(path)
        if not os.path.exists(p):
            return cls(p)
        try:
            with open(p, encoding="utf-8") as fh:
                data = json.load(fh)
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise CalibrationFileError(f"calibration file {p}: cannot be read as JSON ({exc})") from None
        if not isinstance(data, dict):
            raise CalibrationFileError(f"calibration file {p}: must hold a JSON object")
        try:
            if data.get("format") != CALIBRATION_FORMAT:
                if "mass_kg" in data and "model" in data:  # a bare PayloadCalibration.to_dict(): the earlier format
                    return cls(p, legacy_payload=PayloadCalibration.from_dict(data))
                raise ValueError(f"format = {data.get('format')!r}: expected {CALIBRATION_FORMAT!r}")
            if data.get("version") != _VERSION:
                raise ValueError(f"version = {data.get('version')!r}: this software reads version {_VERSION}")
            tools = data.get("tools", {})
            if not isinstance(tools, dict):
                raise ValueError("tools: must be a table of tool names")
            return cls(p, {str(k): ToolCalibration.from_dict(str(k), v) for k, v in tools.items()})
        except ValueError as exc:
            raise CalibrationFileError(f"calibration file {p}: {exc}") from None

    def tool(self, name: str) -> ToolCalibration:
        """What is on record for ``name`` (an empty record if nothing is)."""
        rec = self.tools.get(name)
        if rec is not None:
            return rec
        if self.legacy_payload is not None:
            return ToolCalibration(name, payload=self.legacy_payload)
        return ToolCalibration(name)

    def record(self, tool: str, step: str, result: Any) -> ToolCalibration:
        """Put ``step``'s accepted result on record for ``tool`` (dated now) and :meth:`save`; the new record."""
        rec = self.tool(tool).with_step(step, result)
        self.tools[tool] = rec
        self.save()
        return rec

    def to_dict(self) -> dict[str, Any]:
        """The whole file."""
        return {"format": CALIBRATION_FORMAT, "version": _VERSION,
                "tools": {name: rec.to_dict() for name, rec in sorted(self.tools.items())}}

    def save(self) -> None:
        """Write the file atomically (a crash leaves the old or the new file, never half of one)."""
        p = Path(self.path)
        try:
            write_text_atomically(p, json.dumps(self.to_dict(), indent=2) + "\n")
        except OSError as exc:
            raise CalibrationFileError(f"calibration file {p}: cannot be written ({exc})") from None
        self.legacy_payload = None


def write_text_atomically(path: Path, text: str) -> None:
    """Write ``path`` whole or not at all (a crash leaves the old file or the new one, never half of one), through
    a temporary file of a fresh name beside it -- it can overwrite no file it did not make, and removes only its own
    on failure.  OSError as the system gives it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
