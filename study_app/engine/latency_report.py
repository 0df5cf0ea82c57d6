"""The end-to-end latency the study engine reports and stores: the simulated rig's stages with the pipeline's settings,
the running loop's own share from its records, and the real robot's share from the hardware file
(:mod:`pipeline.assembly.latency`)."""

from __future__ import annotations

from pipeline.assembly.engine_view import EngineView
from pipeline.assembly.latency import Latency, Stage, live_stages, robot_stage, simulated_stages
from pipeline.devices.registry import robot_model
from pipeline.settings.hardware import HardwareConfig

__all__ = ["LIVE_RECORDS", "LatencyReport"]

#: How many of the newest records the loop's own share is the median of (2 s at 1 kHz).
LIVE_RECORDS = 2000


class LatencyReport:
    """The engine's latency breakdown, on the real clock (on the virtual clock computing takes no time and nobody
    feels the force: there is none to report).

    Parameters
    ----------
    eng
        The assembled rig: its first arm's pipeline settings and ring.
    hardware
        The real rig's hardware file (its robot's mode and look-ahead), None on the simulated rig.
    """

    def __init__(self, eng: EngineView, hardware: HardwareConfig | None) -> None:
        self.eng = eng
        self.hardware = hardware
        self._fixed: tuple[Stage, ...] | None = None

    def measure(self) -> None:
        """Measure the stages that do not change while the engine runs (~0.5 s of this process's time: before the
        loop starts, so that it competes with nothing)."""
        self._stages()

    def _stages(self) -> tuple[Stage, ...]:
        """The stages that do not change while the engine runs (measured once)."""
        if self._fixed is None:
            eng, hw = self.eng, self.hardware
            sim = eng.rig.config if eng.simulated else None
            stages = simulated_stages(eng.framework.config, sim)
            if hw is not None:  # the real robot's share replaces the simulated one; the sensor's transport: tap test
                a = hw.arms[0]
                teleop = a.teleop.lookahead_s if a.robot.mode == "teleop" and a.teleop is not None else None
                rate = robot_model(a.robot.model).rate_hz(a.robot.frequency_hz)
                stages = (*(s for s in stages if s.path == "force" and not s.name.startswith("F/T sensor")),
                          Stage("force", "F/T sensor: sampling and transport to the host", float("nan"),
                                "not measured by the app: the fakes' timestamps, a tap test "
                                "(docs/hardware-setup.md)"),
                          robot_stage(a.robot.mode, teleop, rate))
            self._fixed = stages
        return self._fixed

    def latency(self) -> Latency:
        """The breakdown now: the fixed stages and the loop's share over its newest records."""
        ring = self.eng.ring
        rows = ring.latest(LIVE_RECORDS) if ring is not None else None
        live = live_stages(rows) if rows is not None else ()
        return Latency((*live, *self._stages()))
