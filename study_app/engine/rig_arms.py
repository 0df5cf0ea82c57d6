"""The study engine's rig as arms by name: which arm a command names, each arm's devices and hardware table."""

from __future__ import annotations

from typing import Any

from pipeline.assembly.engine import arm_devices
from pipeline.assembly.engine_view import EngineView
from pipeline.settings.hardware import HardwareConfig

__all__ = ["RigArms"]


class RigArms:
    """The rig's arms by name, the first (the task arm) first; each is commissioned, and has its jaw, on its own.

    Parameters
    ----------
    eng
        The assembled rig (its arms are ``eng.frameworks``' names).
    hardware
        The real rig's hardware file, None on the simulated rig.
    """

    def __init__(self, eng: EngineView, hardware: HardwareConfig | None) -> None:
        self.eng = eng
        self.hardware = hardware
        self.names: tuple[str, ...] = tuple(eng.frameworks)

    @property
    def first(self) -> str:
        """The first arm: the task arm, whose ring is the session's."""
        return self.names[0]

    def of(self, name: str) -> str:
        """The arm a command names ("": the first), checked: a name the rig lacks is a ValueError naming its arms."""
        if not name:
            return self.first
        if name not in self.names:
            raise ValueError(f"arm = {name!r}: this rig has no such arm; its arms: {', '.join(self.names)}")
        return name

    def devices(self, arm: str) -> Any:
        """An arm's devices (``sensor``, ``robot``; simulated: its whole rig): the rig itself for the first arm,
        whose calls it forwards, else the arm's own."""
        return arm_devices(self.eng, arm)

    def hardware_arm(self, arm: str) -> Any:
        """The hardware file's table of an arm (real rig), None on the simulated rig."""
        return self.hardware.arm(arm) if self.hardware is not None else None
