"""The assembled engine as the code that drives it sees it, wherever its loop runs.

Two things satisfy :class:`EngineView`: an :class:`pipeline.assembly.engine.Engine` built in the driver's own
process, and :class:`pipeline.assembly.remote_engine.RemoteEngine`, the stand-in for one whose rig, frameworks and
loop run in the loop's own process.  The study engine's rooms read only this.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol

from pipeline.core.clock import Clock
from pipeline.force.payload_compensator import PayloadCalibration
from pipeline.runtime.loop_view import FrameworkHolder, LoopView
from pipeline.runtime.ring import RingBuffer

__all__ = ["EngineView"]


class EngineView(Protocol):
    """An assembled rig, Algorithm 1 per arm and the loop (see the module's docstring).

    ``rig`` is the rig's devices (the first arm's; other arms by ``rig(name)`` on the simulated rig, ``arm(name)`` on
    the real one: :func:`pipeline.assembly.engine.arm_devices`).  ``calibrations`` is the one mapping a driver
    changes: the calibration in use per arm, as it installs new ones in the loop.
    """

    @property
    def rig(self) -> Any: ...

    @property
    def loop(self) -> LoopView: ...

    @property
    def clock(self) -> Clock: ...

    @property
    def simulated(self) -> bool: ...

    @property
    def tool(self) -> str: ...

    @property
    def calibration_file(self) -> Any: ...

    @property
    def framework(self) -> FrameworkHolder: ...

    @property
    def ring(self) -> RingBuffer | None: ...

    @property
    def calibration(self) -> PayloadCalibration: ...

    @property
    def frameworks(self) -> Mapping[str, FrameworkHolder]: ...

    @property
    def rings(self) -> Mapping[str, RingBuffer | None]: ...

    @property
    def calibrations(self) -> dict[str, PayloadCalibration]: ...
