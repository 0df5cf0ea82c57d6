"""The devices the haptic loop owns (:class:`pipeline.runtime.loop.HapticLoop`), real or simulated, as one interface.

:class:`pipeline.devices.real_rig.RealRig` and :class:`pipeline.sim.rig.SimRig`
satisfy it.
"""

from __future__ import annotations

from typing import Protocol

from pipeline.devices.interfaces import ForceSensor, HapticDevice, Robot
from pipeline.force.frames import Vec3

__all__ = ["Rig"]


class Rig(Protocol):
    """The devices the loop owns, and a hook to advance simulated physics.

    A rig that moves a robot itself (app-side teleoperation) also offers two
    optional hooks, looked up once when the loop is built:

    * ``on_faults(faults: Fault) -> None`` -- called whenever the loop's
      latched fault set changes (a new fault, an operator stop, a reset),
      from the loop thread, before the event is emitted.  Any fault must stop
      the robot at once and keep it stopped while the set is non-empty.
    * ``stop_motion(reason: str) -> None`` -- called when the loop stops
      (:meth:`HapticLoop.ramp_down`): stop the robot, nobody will drive it.

    Neither runs in the fault-free steady state, so the tick costs nothing extra.
    """

    # read-only members: a rig may hold a more specific device (the simulated rig's SimTouch is a HapticDevice)
    @property
    def sensor(self) -> ForceSensor: ...

    @property
    def robot(self) -> Robot: ...

    @property
    def haptic(self) -> HapticDevice: ...

    def advance(self, now_ns: int) -> None:
        """Bring the rig to time ``now_ns`` (simulated rig: step the physics)."""
        ...

    def true_contact_force(self) -> Vec3 | None:
        """Ground-truth tip contact force in the base frame, N (simulation only; None on hardware)."""
        ...

    def close(self) -> None:
        """Release every device."""
        ...
