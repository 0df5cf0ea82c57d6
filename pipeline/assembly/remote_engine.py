"""The assembled engine whose rig, frameworks and loop run in the loop's own process, as its driver holds it.

:class:`RemoteEngine` is an :class:`pipeline.assembly.engine_view.EngineView`: each arm's ring (attached, capped at
what the link has delivered: :meth:`pipeline.runtime.ring.RingBuffer.cap`), framework settings and calibration, the
loop's stand-in (:class:`pipeline.assembly.loop_client.RemoteLoop`), and :class:`RemoteDevices` -- an arm's devices,
whose calls (a robot pose, a rehearsed fault) go to the loop's process between two ticks.  The jaws are the
driver's own (the loop needs only the stylus buttons, which it forwards).  :func:`connect` waits for the loop's
process to assemble the rig and attaches to it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from pipeline.assembly.loop_client import LoopLink, RemoteLoop, Settings
from pipeline.core.clock import Clock, MonotonicClock
from pipeline.devices.interfaces import HapticState, PoseSample
from pipeline.force.payload_compensator import PayloadCalibration
from pipeline.runtime.loop_link import Assembled, BuildFailed, Opening
from pipeline.runtime.ring import RingBuffer

__all__ = ["RemoteDevices", "RemoteEngine", "connect"]


class RemoteDevices:
    """An arm's devices in the loop's process, as the driver reaches them: fixed facts here, calls over the link.

    ``jaw`` is the driver's own, set by it (None: the arm has none); ``on_buttons``, when set, gets the arm's stylus
    buttons.
    """

    def __init__(self, loop: RemoteLoop, index: int, name: str, facts: dict[str, Any],
                 others: Mapping[str, RemoteDevices] | None = None) -> None:
        self._loop, self._index, self._arm = loop, index, name
        self._facts = facts
        #: The simulated rig's configuration of this arm (None on the real rig).
        self.config = facts.get("sim_config")
        self.sensor = _Sensor(facts.get("counts_per_unit"))
        self.robot = _Robot(loop.link, name)
        self.haptic = _Haptic(loop, index, name, facts)
        self.jaw: Any = None
        self._others = others or {}

    @property
    def on_buttons(self) -> Callable[[int, int], None] | None:
        """The arm's stylus-button hook (called with the time and the buttons as they change, and while held)."""
        return self._loop.button_hooks.get(self._index)

    @on_buttons.setter
    def on_buttons(self, hook: Callable[[int, int], None] | None) -> None:
        self._loop.button_hooks[self._index] = hook

    def inject_fault(self, kind: str, at_ns: int, duration_s: float | None = None) -> None:
        """Rehearse a fault on the simulated rig (:meth:`pipeline.sim.rig.SimRig.inject_fault`)."""
        self._loop.link.call(self._arm, "inject_fault", kind, at_ns, duration_s)

    def cancel_fault(self, kind: str, at_ns: int) -> bool:
        """Withdraw a rehearsed fault; True if there was one."""
        return bool(self._loop.link.call(self._arm, "cancel_fault", kind, at_ns))

    def rig(self, name: str) -> RemoteDevices:
        """The simulated rig of another arm."""
        return self._others[name]

    def arm(self, name: str) -> RemoteDevices:
        """The real rig's other arm."""
        return self._others[name]

    def close(self) -> None:
        """Close the driver's own jaws (the loop's process closes the rest)."""
        for dev in (self, *self._others.values()):
            jaw = dev.jaw
            if jaw is not None and hasattr(jaw, "close"):
                jaw.close()


class _Sensor:
    def __init__(self, counts_per_unit: Any) -> None:
        if counts_per_unit is not None:
            self.counts_per_unit = counts_per_unit


class _Robot:
    """An arm's robot in the loop's process: its pose and its TCP correction, through the link."""

    def __init__(self, link: LoopLink, arm: str) -> None:
        self._link, self._arm = link, arm

    def read_pose(self) -> PoseSample:
        pose: PoseSample = self._link.call(self._arm, "robot.read_pose")
        return pose

    @property
    def tcp_correction_m(self) -> Any:
        return self._link.call(self._arm, "robot.tcp_correction_m")

    @tcp_correction_m.setter
    def tcp_correction_m(self, value: Any) -> None:
        self._link.call(self._arm, "robot.tcp_correction_m", tuple(value), assign=True)


class _Haptic:
    """An arm's haptic device: its ratings, and its heat and force limit (the first arm's from the status)."""

    def __init__(self, loop: RemoteLoop, index: int, arm: str, facts: dict[str, Any]) -> None:
        self._loop, self._index, self._arm = loop, index, arm
        self.peak_force_n = float(facts.get("peak_force_n", math.nan))
        self.continuous_force_n = float(facts.get("continuous_force_n", math.nan))

    def read_state(self) -> HapticState:
        if self._index:
            state: HapticState = self._loop.link.call(self._arm, "haptic.read_state")
            return state
        heat, limit = self._loop.heat
        return HapticState(0, (math.nan, math.nan, math.nan), force_limit_n=limit, heat_fraction=heat)


@dataclass
class RemoteEngine:
    """An assembled engine whose rig, frameworks and loop live in the loop's own process (see the module)."""

    rig: RemoteDevices
    loop: RemoteLoop
    simulated: bool
    tool: str
    frameworks: dict[str, Settings]
    rings: dict[str, RingBuffer | None]
    calibrations: dict[str, PayloadCalibration]
    status: RingBuffer
    calibration_file: Any = None
    clock: Clock = field(default_factory=MonotonicClock)

    @property
    def framework(self) -> Settings:
        """The first arm's settings."""
        return next(iter(self.frameworks.values()))

    @property
    def ring(self) -> RingBuffer | None:
        """The first arm's ring."""
        return next(iter(self.rings.values()))

    @property
    def calibration(self) -> PayloadCalibration:
        """The first arm's calibration in use."""
        return next(iter(self.calibrations.values()))

    def release(self) -> None:
        """Close the rings' mappings; free the segments of a loop process that could not free them itself."""
        orphaned = self.loop.link.closed is None
        names = [r.segment for r in (*self.rings.values(), self.status) if r is not None]
        for r in (*self.rings.values(), self.status):
            if r is not None:
                r.close()
        if orphaned:
            for name in names:
                if name:
                    RingBuffer.free_orphaned(name)


def connect(link: LoopLink, *, on_open: Callable[[str], None] | None, timeout_s: float = 180.0) -> RemoteEngine:
    """Wait for the loop's process to assemble the rig (announcing each device it opens), then attach to it.

    The arms' jaws are the driver's to open and set (:attr:`RemoteDevices.jaw`).

    Raises
    ------
    RuntimeError
        One line: why the rig could not be assembled, or that the process ended or did not answer in time.
    """
    got: list[object] = []

    def handle(msg: object) -> None:
        if isinstance(msg, Opening) and on_open is not None:
            on_open(msg.device)
        elif isinstance(msg, (Assembled, BuildFailed)):
            got.append(msg)

    link.handle = handle
    if not link.wait(lambda: bool(got), timeout_s):
        link.end(1.0)
        why = f"it ended ({link.exit_status})" if link.gone or not link.alive else f"no answer in {timeout_s:g} s"
        raise RuntimeError(f"the haptic loop's process could not assemble the rig: {why}")
    msg = got[0]
    if isinstance(msg, BuildFailed):
        link.end(5.0)
        raise RuntimeError(msg.reason)
    assert isinstance(msg, Assembled)
    rings = {name: RingBuffer.attach(ring) for name, ring, _, _, _ in msg.arms}
    loop = RemoteLoop(link, msg, rings, RingBuffer.attach(msg.status_ring))
    devices: dict[str, RemoteDevices] = {}
    for i, (name, _, _, _, facts) in enumerate(msg.arms[1:], start=1):
        devices[name] = RemoteDevices(loop, i, name, facts)
    first_name, _, _, _, first_facts = msg.arms[0]
    rig = RemoteDevices(loop, 0, first_name, first_facts, devices)
    return RemoteEngine(
        rig=rig, loop=loop, simulated=msg.simulated, tool=msg.tool,
        frameworks={name: Settings(cfg) for name, _, cfg, _, _ in msg.arms},
        rings=dict(rings), calibrations={name: cal for name, _, _, cal, _ in msg.arms}, status=loop.status)
