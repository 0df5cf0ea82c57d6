"""The devices the haptic loop owns (:class:`pipeline.runtime.loop.HapticLoop`), real or simulated, as one interface.

:class:`pipeline.assembly.real_rig.RealRig` and :class:`pipeline.sim.rig.SimRig`
satisfy it.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from pipeline.devices.interfaces import Fault, ForceSensor, HapticDevice, Robot
from pipeline.force.frames import Vec3

__all__ = ["ARM_NAME", "ARM_NAME_WHAT", "SINGLE_ARM_NAME", "FirstArmMembers", "Rig", "RigArm", "arm_named", "rig_arms"]

#: The name of the one arm of a rig that does not name its arms.  ``right``: the protocol's default task arm, so a
#: one-arm rig (and a one-arm hardware file of before the arms) is the task arm, and a lab that adds its second
#: instrument adds ``left`` beside the arm it has commissioned.
SINGLE_ARM_NAME = "right"
#: What an arm's name may be (the hardware file's ``[[arm]] name``, the protocol's ``design.task_arm``): a letter,
#: then up to 31 letters, digits, ``_`` or ``-`` (it names the arm in events, files and options).
ARM_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]{0,31}\Z")
#: :data:`ARM_NAME` in words, for refusals.
ARM_NAME_WHAT = ("a name of letters, digits, '_' and '-', starting with a letter, at most 32 characters "
                 "(e.g. 'left', 'right')")


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


def _no_truth() -> Vec3 | None:
    return None


@dataclass(frozen=True, slots=True)
class RigArm:
    """One arm of a rig: its sensor, robot and haptic device (and jaw), with the arm's optional hooks.

    A rig with more than one arm lists them as ``arms`` (a sequence of these, the first arm first); its
    ``sensor``, ``robot`` and ``haptic`` are then the first arm's.  ``on_faults`` and ``stop_motion`` are the
    per-arm forms of the rig's hooks (see :class:`Rig`); ``true_contact_force`` the arm's ground truth.
    """

    name: str
    sensor: ForceSensor
    robot: Robot
    haptic: HapticDevice
    jaw: Any = None
    true_contact_force: Callable[[], Vec3 | None] = _no_truth
    on_faults: Callable[[Fault], None] | None = None
    stop_motion: Callable[[str], None] | None = None


def rig_arms(rig: Rig) -> tuple[RigArm, ...]:
    """The arms of ``rig``: its ``arms`` if it lists them, else the one arm it is (named :data:`SINGLE_ARM_NAME`,
    or the rig's ``arm_name``).

    Raises
    ------
    ValueError
        Two arms share a name (an arm's records, events and calibration are kept under its name).
    """
    arms = getattr(rig, "arms", None)
    if arms:
        out = tuple(arms)
        names = [a.name for a in out]
        if len(set(names)) != len(names):
            raise ValueError(f"rig arms = {names!r}: each arm needs its own name")
        return out
    return (RigArm(str(getattr(rig, "arm_name", SINGLE_ARM_NAME)), rig.sensor, rig.robot, rig.haptic,
                   getattr(rig, "jaw", None), rig.true_contact_force, getattr(rig, "on_faults", None),
                   getattr(rig, "stop_motion", None)),)


class FirstArmMembers:
    """What a rig of several arms offers as a one-arm rig: its first arm's devices and stylus hook (a mixin).

    The real rig (:class:`pipeline.assembly.real_rig.RealRig`) and the simulated rig of several arms
    (:class:`pipeline.sim.arms.SimArms`) set ``first`` to their first arm; code that knows one arm then reads and
    hooks the first, and the loop takes every arm from the rig's ``arms``.
    """

    first: Any

    @property
    def sensor(self) -> Any:
        """The first arm's F/T sensor."""
        return self.first.sensor

    @property
    def robot(self) -> Any:
        """The first arm's robot."""
        return self.first.robot

    @property
    def haptic(self) -> Any:
        """The first arm's haptic device."""
        return self.first.haptic

    @property
    def jaw(self) -> Any:
        """The first arm's jaw actuator (None: it has none)."""
        return self.first.jaw

    @property
    def on_buttons(self) -> Callable[[int, int], None] | None:
        """The first arm's stylus-button hook (called with the time and the buttons every tick)."""
        hook: Callable[[int, int], None] | None = self.first.on_buttons
        return hook

    @on_buttons.setter
    def on_buttons(self, hook: Callable[[int, int], None] | None) -> None:
        self.first.on_buttons = hook


_A = TypeVar("_A")


def arm_named(arms: Mapping[str, _A], name: str, what: str = "the rig's arms") -> _A:
    """The arm called ``name`` of ``arms`` (by name); :class:`KeyError` naming the arms there are."""
    try:
        return arms[name]
    except KeyError:
        raise KeyError(f"no arm {name!r}; {what}: {', '.join(arms)}") from None
