"""The device seam on the real rig: a haptic model registered from this test opens through its own backend.

The Net F/T box and the UR are the real backends against their loopback fakes; the haptic device is a model this
test registers (a 12 N device, the omega.3's force) whose backend is this test's: ``build_hardware_engine`` opens it
through the registry as it opens a Touch, and the framework's clamp is its peak, not the Touch's.  Also here: the
UR e-Series' automatic rate (``frequency_hz = -1``) is its 500 Hz in the servo, as the registry defines it.
"""

from __future__ import annotations

import socket
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, ClassVar

import pytest
from fake_netft import FakeNetFT
from fake_rtde import FakeRtde
from fake_ur_control import FakeControl

from pipeline.assembly.engine import build_hardware_engine
from pipeline.backends.ur import RtdeLink
from pipeline.backends.ur_control import UrRtdeServo
from pipeline.core.clock import Clock, VirtualClock
from pipeline.devices.registry import HapticConnection, HapticModel, register_haptic, robot_model, unregister_haptic
from pipeline.devices.touch_output import HapticLimits
from pipeline.settings.hardware import load_hardware
from pipeline.sim.touch import SimTouch


class LoopbackBackend:
    """The test device's backend: each device opened is recorded (its renderer is the Touch's output contract)."""

    opened: ClassVar[list[tuple[str, float]]] = []
    start_step: str | None = None

    def __init__(self, model: HapticModel, settings: Sequence[HapticConnection]) -> None:
        self.model = model

    def open(self, settings: HapticConnection, clock: Clock) -> SimTouch:
        LoopbackBackend.opened.append((settings.device_name, settings.command_timeout_s))
        return SimTouch(self.model.limits, settings.command_timeout_s)

    def start(self) -> None:
        """Nothing to start."""


OMEGA = HapticModel(
    key="omega3-like", name="omega.3-like test device",
    limits=HapticLimits(peak_force_n=12.0, continuous_force_n=12.0, thermal_budget_n2s=100.0),
    servo_rate_hz=4000.0, backend=LoopbackBackend, twin=SimTouch,
    source="Force Dimension omega.x datasheet (omega.3: 12.0 N)",
)


@pytest.fixture
def omega() -> Iterator[HapticModel]:
    LoopbackBackend.opened = []
    model = register_haptic(OMEGA)
    yield model
    unregister_haptic(model.key)


def _file(tmp_path: Path, netft: FakeNetFT, rtde: FakeRtde, haptic: str, f_max_n: float) -> Path:
    p = tmp_path / "hardware.toml"
    p.write_text(f'[sensor]\nhost = "127.0.0.1"\nport = {netft.udp_port}\nhttp_port = {netft.http_port}\n'
                 f'connect_timeout_s = 1.0\n[robot]\nhost = "{rtde.host}"\nconnect_timeout_s = 1.0\n'
                 f'[haptic]\n{haptic}\n'
                 "[frames]\nrot_tip_sensor = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n"
                 "rot_haptic_base = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]\n"
                 f"[framework]\nf_max_n = {f_max_n}\nf_scale_n = 7.0\n", encoding="utf-8")
    return p


def test_the_real_rig_opens_a_registered_device_through_its_backend(tmp_path: Path, omega: HapticModel) -> None:
    with FakeNetFT() as netft, FakeRtde() as rtde:
        hw = load_hardware(_file(tmp_path, netft, rtde, 'model = "omega3-like"\ndevice_name = "omega"\n'
                                                        "command_timeout_s = 0.001", 10.0))
        opened: list[str] = []
        eng = build_hardware_engine(hw, clock=VirtualClock(), on_open=opened.append)
        try:
            assert opened == ["force sensor", "robot", "haptic device"]
            assert LoopbackBackend.opened == [("omega", 0.001)]
            assert isinstance(eng.rig.haptic, SimTouch) and eng.rig.haptic.peak_force_n == 12.0
            assert eng.framework.safety.static_limit_n == 10.0  # min(f_max 10, the device's 12): not the Touch's 3.3
            eng.loop.run_ticks(3)
            assert eng.loop.last_record is not None
        finally:
            eng.rig.close()


def test_the_e_series_automatic_rate_is_its_500_hz() -> None:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(1)
    try:
        made: list[float] = []

        def factory(host: str, frequency_hz: float) -> Any:
            made.append(frequency_hz)
            return FakeControl()

        link = RtdeLink("127.0.0.1", -1, robot_model("ur3e"), VirtualClock(), port=s.getsockname()[1])
        servo = UrRtdeServo(link, control_factory=factory)
        try:
            # ur_rtde is asked for -1 (it picks the controller's rate); each servoL's time is the e-Series' 2 ms
            assert made == [-1] and servo.period_s == 1.0 / 500.0
        finally:
            servo.close()
    finally:
        s.close()
