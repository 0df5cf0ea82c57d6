"""The simulated rig with more than one arm: one :class:`pipeline.sim.rig.SimRig` per arm, on one clock.

Each arm is a whole simulated rig of its own -- its tissue contact, its UR3, its
wrist sensor (its own noise and drift, from its own seed), its Touch and the
hand on that stylus -- and :class:`SimArms` steps them all at the loop's tick,
so they share the clock.  It satisfies :class:`pipeline.devices.rig.Rig`: its
``sensor``, ``robot`` and ``haptic`` are the first arm's, and ``arms`` lists
every arm (:class:`pipeline.devices.rig.RigArm`) for the loop.  The scenario
controls (the stylus driver, fault rehearsal, teleoperation, the frame-check
pushes) act on the first arm unless an arm is named; ``rig(name)`` is that
arm's own :class:`~pipeline.sim.rig.SimRig`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

from pipeline.devices.rig import FirstArmMembers, RigArm, arm_named
from pipeline.force.frames import Vec3
from pipeline.sim.hand import HandObservation, StylusDriver
from pipeline.sim.rig import SimRig, SimRigConfig

__all__ = ["SimArms", "arm_configs"]


def arm_configs(names: Sequence[str], base: SimRigConfig) -> list[tuple[str, SimRigConfig]]:
    """One simulated rig's configuration per arm: ``base`` for the first, the same with its own seed for the others
    (every random process of an arm -- noise, drift, packet loss -- then differs from the other arms')."""
    return [(name, base if i == 0 else replace(base, seed=base.seed * 1009 + i)) for i, name in enumerate(names)]


class SimArms(FirstArmMembers):
    """Several simulated arms on one clock (see the module's docstring).

    Parameters
    ----------
    arms
        ``(name, rig)`` per arm, the first arm first.
    """

    def __init__(self, arms: Sequence[tuple[str, SimRig]]) -> None:
        if len(arms) < 1:
            raise ValueError("SimArms needs at least one arm")
        names = [n for n, _ in arms]
        if len(set(names)) != len(names):
            raise ValueError(f"arm names = {names!r}: each arm needs its own name")
        self._rigs = dict(arms)
        self.rigs: tuple[SimRig, ...] = tuple(r for _, r in arms)
        self.first: SimRig = self.rigs[0]
        self.arms: tuple[RigArm, ...] = tuple(
            RigArm(name, r.sensor, r.robot, r.haptic, r.jaw, r.true_contact_force, r.on_faults, r.stop_motion)
            for name, r in arms)

    @classmethod
    def build(cls, names: Sequence[str], base: SimRigConfig | None = None) -> SimArms:
        """Arms named ``names`` built from ``base`` (:func:`arm_configs`)."""
        return cls([(name, SimRig(cfg)) for name, cfg in arm_configs(names, base or SimRigConfig())])

    def rig(self, name: str) -> SimRig:
        """The simulated rig of the arm called ``name``."""
        return arm_named(self._rigs, name, "the arms")

    # -- Rig interface (the first arm's devices, FirstArmMembers; every arm's physics) -----------
    def advance(self, now_ns: int) -> None:
        """Step every arm's physics to ``now_ns``."""
        for r in self.rigs:
            r.advance(now_ns)

    def true_contact_force(self) -> Vec3:
        """The first arm's ground-truth contact force (each arm's is its ``RigArm.true_contact_force``)."""
        return self.first.true_contact_force()

    def close(self) -> None:
        """Close every arm (all of them, even if one fails)."""
        errors = []
        for r in self.rigs:
            try:
                r.close()
            except Exception as exc:  # close the others, report after
                errors.append(exc)
        if errors:
            raise errors[0]

    # -- scenario control (the first arm unless an arm is named) --------------------------------
    @property
    def config(self) -> SimRigConfig:
        """The first arm's configuration."""
        return self.first.config

    @property
    def driver(self) -> StylusDriver:
        """Who holds the first arm's stylus."""
        return self.first.driver

    def set_driver(self, driver: StylusDriver, arm: str | None = None) -> None:
        """Hand an arm's stylus (the first's by default) to ``driver``."""
        (self.first if arm is None else self.rig(arm)).set_driver(driver)

    def inject_fault(self, kind: str, at_ns: int, duration_s: float | None = None, arm: str | None = None) -> None:
        """Rehearse a fault on an arm (the first by default): see :meth:`pipeline.sim.rig.SimRig.inject_fault`."""
        (self.first if arm is None else self.rig(arm)).inject_fault(kind, at_ns, duration_s)

    def cancel_fault(self, kind: str, at_ns: int, arm: str | None = None) -> bool:
        """Withdraw a rehearsed fault on an arm (the first by default)."""
        return (self.first if arm is None else self.rig(arm)).cancel_fault(kind, at_ns)

    def attach_teleop(self, driver: Any, arm: str | None = None) -> None:
        """Teleoperate an arm (the first by default) with ``driver``, a
        :class:`pipeline.devices.teleop.TeleopDriver` of that arm's own Touch and robot (its own clutch and deadman
        state); see :meth:`pipeline.sim.rig.SimRig.attach_teleop`.  None detaches."""
        (self.first if arm is None else self.rig(arm)).attach_teleop(driver)

    @property
    def push_base_n(self) -> Vec3:
        """A force applied to the first arm's tip by hand, base frame, N."""
        return self.first.push_base_n

    @push_base_n.setter
    def push_base_n(self, value: Vec3) -> None:
        self.first.push_base_n = value

    @property
    def sim_time_s(self) -> float:
        """Simulated time, s."""
        return self.first.sim_time_s

    @property
    def last_observation(self) -> HandObservation:
        """What the first arm's hand saw last."""
        return self.first.last_observation

    @property
    def indentation_m(self) -> float:
        """The first arm's true tissue indentation, m."""
        return self.first.indentation_m

    @property
    def true_rot_tip_sensor(self) -> Any:
        """The first arm's true sensor mounting."""
        return self.first.true_rot_tip_sensor
