"""Teleoperation of each arm of a simulated rig of two arms: each Touch drives its own robot, with its own clutch and
deadman (a real HapticLoop on :class:`pipeline.sim.arms.SimArms`, on the virtual clock).

Both hands sweep their stylus up and down with the deadman held, so both arms move; then the clutch is held on the
left stylus only: the left robot holds its target while the right one keeps following its stylus, and releasing the
right deadman stops the right robot only.
"""

from __future__ import annotations

import math

from pipeline.assembly.engine import EngineConfig, build_sim_engine
from pipeline.devices.teleop import TeleopConfig, TeleopController, TeleopDriver, TeleopState
from pipeline.sim.arms import SimArms
from pipeline.sim.hand import HandObservation

DEADMAN, CLUTCH = 1, 2  # the controller's default buttons (dark grey, light grey)
LO, HI = (0.2, -0.1, 0.105), (0.4, 0.1, 0.2)  # the tool stays above the tissue (surface at z = 0.10 m)


class Sweep:
    """The hand moves the stylus 0..20 mm up and back (1 s period): the arm is always moving."""

    def equilibrium_y(self, obs: HandObservation) -> float:
        return 0.01 * (1.0 - math.cos(2.0 * math.pi * obs.t_s))


def _z_span_m(eng, rigs, n: int) -> dict[str, float]:
    """Run ``n`` ticks; how far each arm's tool moved in z meanwhile, m."""
    zs: dict[str, list[float]] = {name: [] for name in rigs}
    for _ in range(n):
        eng.loop.run_ticks(1)
        for name, r in rigs.items():
            zs[name].append(r.robot.position_m[2])
    return {name: max(z) - min(z) for name, z in zs.items()}


def test_each_arm_has_its_own_clutch_and_deadman() -> None:
    eng = build_sim_engine(EngineConfig(clock="virtual", calibrate=False, driver="hold", arms=("left", "right")))
    arms = eng.rig
    assert isinstance(arms, SimArms)
    rigs = {name: arms.rig(name) for name in ("left", "right")}
    ctls: dict[str, TeleopController] = {}
    for name, r in rigs.items():
        r.set_driver(Sweep())
        ctls[name] = TeleopController(TeleopConfig(LO, HI, max_speed_m_s=0.1, rot_haptic_base=r.config.rot_haptic_base))
        arms.attach_teleop(TeleopDriver(ctls[name], r.haptic, r.robot, r.robot), arm=name)
    assert all(r.teleop is not None and r.teleop.controller is ctls[n] for n, r in rigs.items())
    try:
        for r in rigs.values():
            r.haptic.buttons = DEADMAN
        _z_span_m(eng, rigs, 300)
        assert {n: c.state for n, c in ctls.items()} == {"left": TeleopState.ENGAGED, "right": TeleopState.ENGAGED}
        moving = _z_span_m(eng, rigs, 100)
        assert min(moving.values()) > 2e-3  # both arms follow their stylus

        rigs["left"].haptic.buttons = DEADMAN | CLUTCH  # clutch on the left stylus only
        _z_span_m(eng, rigs, 200)  # the left arm settles on its held target (the servo converges within ~150 ms)
        clutched = _z_span_m(eng, rigs, 200)
        assert ctls["left"].state is TeleopState.CLUTCHED and ctls["right"].state is TeleopState.ENGAGED
        assert clutched["left"] < 1e-5 < 2e-3 < clutched["right"]  # the left holds, the right keeps moving

        rigs["right"].haptic.buttons = 0  # the right deadman released: the right robot stops, the left stays clutched
        _z_span_m(eng, rigs, 20)
        stopped = _z_span_m(eng, rigs, 200)
        assert ctls["right"].state is TeleopState.IDLE and ctls["left"].state is TeleopState.CLUTCHED
        assert stopped["right"] < 1e-5 and not rigs["right"].robot.servoing

        rigs["left"].haptic.buttons = DEADMAN  # the left clutch released: the left follows its stylus again
        _z_span_m(eng, rigs, 100)
        assert ctls["left"].state is TeleopState.ENGAGED and _z_span_m(eng, rigs, 200)["left"] > 2e-3
    finally:
        arms.close()
