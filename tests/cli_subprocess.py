"""The ``haptic-study`` command run as a user runs it (a subprocess of the installed script), and the tiny protocol
the end-to-end tests of resume, damage and rehearsal share (and its two groups)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

_SCRIPT = Path(sys.executable).with_name("haptic-study")
#: The installed console script, or the module where the package is not installed.
CLI = [str(_SCRIPT)] if _SCRIPT.is_file() else [sys.executable, "-m", "study_app.cli"]


def cli(args: list[str], cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    """Run ``haptic-study ARGS`` in ``cwd`` without the caller's HAPTIC_STUDY_* settings; its output as text."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("HAPTIC_STUDY")}
    return subprocess.run([*CLI, *args], check=False, capture_output=True, text=True, timeout=timeout, cwd=cwd, env=env)


def tiny_protocol(name: str, max_trial_s: float = 1.5, hold_s: float = 0.3, pause_s: float = 0.3) -> str:
    """A protocol file's text: one target (GENTLE 0.6 N), both modes, 2 trials per cell, no training."""
    return f"""name = "{name}"
[[targets]]
label = "GENTLE"
force_n = 0.6
[design]
modes = ["on", "off"]
trials_per_cell = 2
[trial]
max_trial_s = {max_trial_s}
hold_s = {hold_s}
pause_s = {pause_s}
[training]
enabled = false
"""


#: A protocol's two groups (a protocol's text + this): novices and surgeons placed in turn, the surgeons simulated
#: with the experienced profile (docs/groups.md).
TWO_GROUPS = """
[[covariates]]
name = "group"
kind = "category"
levels = ["novice", "surgeon"]
required = true

[groups]
by = "group"
simulated = ["novice", "surgeon"]
experienced = ["surgeon"]
"""
