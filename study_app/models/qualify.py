"""Qualify the real rig from the window: the model of the commissioning view's Qualify step.

The window runs ``haptic-study qualify --json`` as a child process, so the record is written by the command itself,
exactly as the CLI writes it (beside the arm's calibration file); this model builds its command line, reads its
progress (stderr: ``qualify: CHECK: running``, ``qualify: CHECK: VERDICT`` and other ``qualify: …`` lines) and its
record (stdout, JSON), and says when it may not run.  The study engine holds the rig's devices, which qualify opens
itself: the window stops the engine before the run and restarts it after (docs/gui.md, "Qualifying the rig").
"""

from __future__ import annotations

import json
import sys
from typing import Any

from pipeline.commissioning.qualification import CHECKS
from study_app.models import Emitter

__all__ = ["QualifyModel"]

#: The loop check's default length in the window, s (the command's default).
DEFAULT_SECONDS = 60.0
_PREFIX = "qualify: "
#: What a check's own progress line says of it (``qualify: CHECK: …``); any other line is what it is doing.
_STATES = ("running", "PASS", "FAIL", "NOT CHECKED")


class QualifyModel:
    """One qualification run at a time: its checks' verdicts as they come, the record, what went wrong.

    Parameters
    ----------
    hardware
        The real rig's hardware file (None on the simulated rig: nothing to qualify).
    python
        The interpreter the command runs with (this one: the same installation).
    """

    def __init__(self, hardware: str | None, python: str = sys.executable) -> None:
        self.hardware = hardware
        self.python = python
        #: Anything shown changed.
        self.changed = Emitter()
        self.seconds = DEFAULT_SECONDS
        #: ``idle``, ``running``, ``done`` (a record was written) or ``failed`` (the command wrote none).
        self.state = "idle"
        self.arm = ""
        #: The check running now ("" between checks).
        self.current = ""
        #: Each check's entry of the record as it came (name → verdict, measured, bound, why).
        self.results: dict[str, dict[str, str]] = {}
        self.record: dict[str, Any] | None = None
        self.record_path = ""
        self.error = ""
        self.lines: list[str] = []
        #: What the running check is doing, in the command's words ("" when it did not say).
        self.detail = ""

    def refusal(self, calibration_refusal: str) -> str:
        """Why a qualification may not start now ("" when it may); ``calibration_refusal``: the window's reason
        no commissioning step may run (a session runs, the engine is down)."""
        if not self.hardware:
            return ("qualify needs the real rig: start the window with --rig real --hardware FILE "
                    "(haptic-study qualify is the command line's way)")
        if self.state == "running":
            return "a qualification is running"
        return calibration_refusal

    def command(self) -> list[str]:
        """The command line of the run (the arm's name only on a rig of several arms)."""
        if not self.hardware:
            raise ValueError("no hardware file: nothing to qualify")
        return [self.python, "-m", "study_app.cli", "qualify", "--hardware", self.hardware, "--json", "--seconds",
                f"{self.seconds:g}", *(["--arm", self.arm] if self.arm else [])]

    def start(self, arm: str, seconds: float) -> None:
        """A run starts on ``arm`` ("" on a rig of one arm) with the loop measured for ``seconds``."""
        self.arm, self.seconds = arm, float(seconds)
        self.state, self.current, self.results, self.record = "running", "", {}, None
        self.record_path = self.error = self.detail = ""
        self.lines = []
        self.changed.emit()

    def progress(self, line: str) -> None:
        """One stderr line of the command."""
        text = line.strip()
        if not text:
            return
        self.lines.append(text)
        if text.startswith(_PREFIX):
            name, _, what = text[len(_PREFIX):].partition(": ")
            if name in CHECKS and what in _STATES:
                self.current = name if what == "running" else ""
                self.detail = ""
                if what != "running":
                    self.results[name] = {"verdict": what}
            else:  # what the running check is doing ("the loop runs on the rig: …")
                self.detail = text[len(_PREFIX):]
        self.changed.emit()

    def finish(self, exit_code: int, stdout: str) -> None:
        """The command ended: its record (exit 0 or 1) or why there is none (exit 2: its one line)."""
        self.current = ""
        try:
            record = json.loads(stdout.strip().splitlines()[-1]) if stdout.strip() else None
        except (json.JSONDecodeError, IndexError):
            record = None
        if exit_code in (0, 1) and isinstance(record, dict) and "checks" in record:
            self.record, self.state = record, "done"
            self.results = {c["name"]: c for c in record["checks"]}
            from pipeline.commissioning.qualification import record_path

            self.record_path = str(record_path(self._calibration_file()))
        else:
            self.state = "failed"
            said = [ln for ln in self.lines if not ln.startswith(_PREFIX)]
            self.error = said[-1] if said else f"haptic-study qualify ended with exit status {exit_code}"
        self.changed.emit()

    def _calibration_file(self) -> str | None:
        from pipeline.settings.hardware import HardwareError, load_hardware

        try:
            arms = load_hardware(str(self.hardware)).arms
        except HardwareError:
            return None
        arm = next((a for a in arms if a.name == self.arm), arms[0])
        return arm.calibration_file

    @property
    def done_checks(self) -> int:
        """Checks with a verdict (the progress bar's value)."""
        return sum(1 for n in CHECKS if "verdict" in self.results.get(n, {}))

    def rows(self) -> list[tuple[str, str, str]]:
        """(check, verdict or where it is, what it measured or why) for each check, in the order they run."""
        out = []
        for name in CHECKS:
            r = self.results.get(name)
            if r is None:
                out.append((name, "running…" if name == self.current else
                            ("waiting" if self.state == "running" else "–"), ""))
                continue
            text = r.get("measured", "") if r.get("verdict") == "PASS" else r.get("why", "")
            if r.get("verdict") == "FAIL" and r.get("measured"):
                text = f"{r['why']}: {r['measured']}"
            out.append((name, r["verdict"], text))
        return out

    def summary(self) -> str:
        """One line: where the run is, or its verdict and where the record is."""
        if self.state == "running":
            where = f"running {self.current}" if self.current else "starting"
            where += f" ({self.detail})" if self.detail else ""
            return (f"Qualifying{' ' + self.arm if self.arm else ''}: {where} ({self.done_checks} of {len(CHECKS)} "
                    "checks done); the study engine is stopped until it ends")
        if self.state == "failed":
            return f"No qualification record: {self.error}"
        if self.record is not None:
            return (f"Verdict {self.record['verdict']} ({self.record['date']}); the record: {self.record_path}")
        return "Not run in this window (check-hardware shows the arm's last record)."
