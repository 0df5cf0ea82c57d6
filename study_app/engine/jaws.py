"""Each arm's jaw, driven by that arm's own stylus buttons.

The experimenter's jaw box (Close, Step, Open) and :class:`study_app.engine.messages.JawState` are the
first arm's jaw; on a rig of several arms every other arm with a jaw gets a
:class:`pipeline.devices.jaw_control.JawController` of its own, fed by its own Touch's buttons, so a
participant's left hand never opens the right instrument.  Each command carried out is stored with the running
session, the arm named.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pipeline.assembly.engine import Engine
from pipeline.devices.jaw_control import JawController
from pipeline.settings.hardware import HardwareConfig

__all__ = ["arm_jaws", "other_arm_jaw_events"]


def arm_jaws(eng: Engine, hardware: HardwareConfig | None, devices: Callable[[str], Any]) -> dict[str, JawController]:
    """A jaw controller per arm that has a jaw, by arm name, the first arm first; each arm's stylus buttons are
    hooked to its own.

    Parameters
    ----------
    eng
        The assembled rig (its arms are ``eng.frameworks``' names).
    hardware
        The real rig's hardware file (each arm's ``[jaw]`` buttons, and whether teleoperation claims them), or None.
    devices
        An arm's devices by name (an object with ``jaw`` and ``on_buttons``; the rig itself for the first arm).
    """
    out: dict[str, JawController] = {}
    for name in eng.frameworks:
        dev = devices(name)
        jaw = getattr(dev, "jaw", None)
        if jaw is None:
            continue
        hw = hardware.arm(name) if hardware is not None else None
        if hw is not None and hw.jaw is not None:
            ctl = JawController(jaw, close_button=hw.jaw.close_button, open_button=hw.jaw.open_button,
                                stylus=hw.robot.mode != "teleop")  # teleoperation claims both buttons
        else:
            ctl = JawController(jaw)
        dev.on_buttons = ctl.buttons
        out[name] = ctl
    return out


def other_arm_jaw_events(jaws: dict[str, JawController]) -> list[str]:
    """The commands the other arms' jaws carried out since the last call, oldest first, each naming its arm."""
    out = []
    for name, ctl in jaws.items():
        while ctl.events:
            ev = ctl.events.popleft()
            out.append(f"arm {name}: {ev.source}: {ev.detail}")
    return out
