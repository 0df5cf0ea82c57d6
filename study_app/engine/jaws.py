"""Each arm's jaw, driven by that arm's own stylus buttons.

The experimenter's jaw box (Close, Step, Open) and :class:`study_app.engine.messages.JawState` are the
first arm's jaw; on a rig of several arms every other arm with a jaw gets a
:class:`pipeline.devices.jaw_control.JawController` of its own, fed by its own Touch's buttons, so a
participant's left hand never opens the right instrument.  Each command carried out is stored with the running
session, the arm named.  :class:`EngineJaws` is the study engine's room for them: it starts and closes them,
applies the window's jaw commands to the first arm's and hands on what each carried out.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pipeline.assembly.engine_view import EngineView
from pipeline.devices.jaw_control import JawController
from pipeline.settings.hardware import HardwareConfig
from study_app.engine import messages as m

__all__ = ["EngineJaws", "arm_jaws", "other_arm_jaw_events"]


def arm_jaws(eng: EngineView, hardware: HardwareConfig | None,
             devices: Callable[[str], Any]) -> dict[str, JawController]:
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


class EngineJaws:
    """The study engine's jaws (driver thread only): the first arm's, which the window's jaw box drives too, and the
    other arms', which follow their own stylus buttons only.

    Parameters
    ----------
    eng, hardware, devices
        As :func:`arm_jaws` takes them.
    first_arm
        The first arm's name (the task arm): its jaw is :attr:`first`.
    publish
        Called with each :class:`study_app.engine.messages.JawState` of the first arm's jaw.
    """

    def __init__(self, eng: EngineView, hardware: HardwareConfig | None, devices: Callable[[str], Any], first_arm: str,
                 publish: Callable[[object], None]) -> None:
        jaws = arm_jaws(eng, hardware, devices)
        #: The first arm's jaw (the simulated one, or the Arduino of the hardware file); None: there is none.
        self.first = jaws.pop(first_arm, None)
        #: The other arms' jaws, by arm name.
        self.others = jaws
        self.publish = publish

    def start(self) -> None:
        """Start every jaw; announce the first arm's state."""
        for ctl in self.others.values():
            ctl.start()
        if self.first is not None:
            self.first.start()
            self._publish_state("")

    def close(self) -> None:
        """Close every jaw."""
        for ctl in (self.first, *self.others.values()):
            if ctl is not None:
                ctl.close()

    @property
    def pending(self) -> bool:
        """A jaw carried out a command not yet handed on."""
        return any(ctl.events for ctl in (self.first, *self.others.values()) if ctl is not None)

    def command(self, cmd: m.JawCommand) -> None:
        """The window's jaw box: move the first arm's jaw."""
        if self.first is None:
            raise RuntimeError("jaw: no jaw actuator on this rig (add a [jaw] table to the hardware file)")
        self.first.submit(cmd.action)

    def drain(self, store: Callable[[str], None]) -> None:
        """Every jaw command carried out: each to ``store`` (the running session's events), the first arm's to the
        display too."""
        for text in other_arm_jaw_events(self.others):
            store(text)
        while self.first is not None and self.first.events:
            ev = self.first.events.popleft()
            text = f"{ev.source}: {ev.detail}"
            store(text)
            self.publish(m.JawState(ev.fraction_open, ev.pulse_us, ev.at_limit, ev.fault, text))

    def _publish_state(self, last: str) -> None:
        assert self.first is not None
        s = self.first.jaw.status
        self.publish(m.JawState(float(s.fraction_open), int(s.pos_us), bool(s.at_limit), str(s.fault), last))
