"""The device registry (pipeline/devices/registry.py): devices composed, not special-cased.

A haptic device model registered from this test -- not from a product file -- with a 12 N peak (the limits of a
Force Dimension omega.3, whose datasheet gives 12.0 N of continuous force) is run on the simulated rig through the
one builder every command uses: its twin is built from its model, f_max is capped by its peak and not by the Touch's
3.3 N, and a hardware file asking for more than its peak is refused in one line naming the field.  The robot
model's control rate is the one meaning of an automatic RTDE rate (``frequency_hz = -1``).
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pipeline.assembly.engine import EngineConfig, build_sim_engine
from pipeline.assembly.sim_config import sim_rig_config
from pipeline.backends.ur import RtdeLink
from pipeline.devices.registry import (
    DEFAULT_HAPTIC_MODEL,
    DEFAULT_ROBOT_MODEL,
    HapticModel,
    haptic_model,
    haptic_models,
    register_haptic,
    robot_model,
    robot_models,
    unregister_haptic,
)
from pipeline.devices.touch_output import HapticLimits
from pipeline.force.config import FrameworkConfig
from pipeline.force.frames import IDENTITY
from pipeline.settings.hardware import HardwareError, hardware_from_dict
from pipeline.sim.rig import SimRig, SimRigConfig
from pipeline.sim.touch import SimTouch

ROOT = Path(__file__).resolve().parents[2]

#: A 12 N device: the omega.3's force (Force Dimension, omega.x datasheet: 12.0 N continuous), a 4 kHz servo loop.
OMEGA = HapticModel(
    key="omega3-like",
    name="omega.3-like test device",
    limits=HapticLimits(peak_force_n=12.0, continuous_force_n=12.0, thermal_budget_n2s=100.0),
    servo_rate_hz=4000.0,
    backend="tests-only: not opened here",
    twin=SimTouch,  # an impedance-type device with the Touch's output contract, given its own limits
    source="Force Dimension omega.x datasheet (omega.3: 12.0 N)",
)


@pytest.fixture
def omega() -> Iterator[HapticModel]:
    model = register_haptic(OMEGA)
    yield model
    unregister_haptic(model.key)


def _max_rendered_n(haptic: str, framework: FrameworkConfig, ticks: int = 6000) -> tuple[float, Any]:
    """The largest force the loop commanded over ``ticks`` of scripted presses on the simulated rig of ``haptic``."""
    eng = build_sim_engine(EngineConfig(sim=sim_rig_config(0, haptic=haptic), clock="virtual", framework=framework,
                                        ring_seconds=10.0))
    eng.loop.run_ticks(ticks)
    rows = eng.ring.latest(ticks)  # type: ignore[union-attr]
    render = np.hypot(np.hypot(rows["render_fx"], rows["render_fy"]), rows["render_fz"])
    return float(render.max()), eng


def test_a_registered_device_runs_on_the_simulated_rig_capped_by_its_own_peak(omega: HapticModel) -> None:
    # f_max 10 N and a steep scaling: the scripted presses ask for far more than a Touch can render
    cfg = FrameworkConfig(f_max_n=10.0, f_scale_n=1.0)
    peak, eng = _max_rendered_n(omega.key, cfg)
    assert isinstance(eng.rig.haptic, SimTouch) and eng.rig.haptic.peak_force_n == 12.0  # its twin, its limits
    assert eng.framework.safety.static_limit_n == 10.0  # min(f_max, 12 N): f_max is what caps it
    assert 3.3 < peak <= 10.0 * (1 + 1e-12)  # above the Touch's peak; the clamp's rounding is within 1e-12
    touch_peak, touch_eng = _max_rendered_n(DEFAULT_HAPTIC_MODEL, cfg)
    assert touch_eng.framework.safety.static_limit_n == 3.3 and touch_peak <= 3.3 * (1 + 1e-12)


def test_a_hardware_file_over_the_devices_peak_is_refused_in_one_line(omega: HapticModel) -> None:
    d: dict[str, Any] = {
        "sensor": {"host": "10.0.0.1"}, "robot": {"host": "10.0.0.2"}, "haptic": {"model": omega.key},
        "frames": {"rot_tip_sensor": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
                   "rot_haptic_base": [[1, 0, 0], [0, 0, 1], [0, -1, 0]]},
        "framework": {"f_max_n": 10.0, "f_scale_n": 7.0},
    }
    hw = hardware_from_dict(d, "hw.toml")
    assert hw.haptic.model == omega.key and hw.framework.f_max_n == 10.0  # over the Touch's peak, under the omega's
    d["framework"]["f_max_n"] = 13.0
    with pytest.raises(HardwareError) as err:
        hardware_from_dict(d, "hw.toml")
    assert str(err.value) == ("hw.toml: framework.f_max_n = 13.0: must be a number from 1e-06 to 12 (N; the "
                              "omega.3-like test device's peak force)")
    d["haptic"] = {}  # the default device: the Touch
    d["framework"]["f_max_n"] = 10.0
    with pytest.raises(HardwareError, match=r"^hw\.toml: framework\.f_max_n = 10\.0: must be a number from 1e-06 to "
                                            r"3\.3 \(N; the 3D Systems Touch's peak force\)$"):
        hardware_from_dict(d, "hw.toml")
    # the command timeout's floor is two of the device's servo periods: 0.5 ms at 4 kHz, 2 ms on a Touch
    d["framework"]["f_max_n"] = 3.0
    d["haptic"] = {"model": omega.key, "command_timeout_s": 0.001}
    assert hardware_from_dict(d, "hw.toml").haptic.command_timeout_s == 0.001
    d["haptic"] = {"command_timeout_s": 0.001}
    with pytest.raises(HardwareError, match=r"^hw\.toml: haptic\.command_timeout_s = 0\.001: must be a number from "
                                            r"0\.002 to 0\.05"):
        hardware_from_dict(d, "hw.toml")


def test_an_unknown_model_is_refused_naming_the_models_there_are() -> None:
    d: dict[str, Any] = {"sensor": {"host": "10.0.0.1"}, "robot": {"host": "10.0.0.2", "model": "ur99"},
                         "haptic": {}}
    with pytest.raises(HardwareError) as err:
        hardware_from_dict(d, "hw.toml")
    assert str(err.value) == ("hw.toml: robot.model = 'ur99': allowed values: 'ur3' (UR3 (CB3)), "
                              "'ur3e' (UR3e (e-Series))")
    d["robot"] = {"host": "10.0.0.2"}
    d["haptic"] = {"model": "omega"}
    with pytest.raises(HardwareError, match=r"^hw\.toml: haptic\.model = 'omega': allowed values: 'touch' \(3D Systems "
                                            r"Touch\)$"):
        hardware_from_dict(d, "hw.toml")
    with pytest.raises(ValueError, match=r"^simulated robot = 'ur99': allowed values: 'ur3' \(UR3 \(CB3\)\), 'ur3e'"):
        sim_rig_config(0, robot="ur99")


def test_the_defaults_are_the_papers_devices() -> None:
    assert (DEFAULT_HAPTIC_MODEL, DEFAULT_ROBOT_MODEL) == ("touch", "ur3")
    assert haptic_models()[0] == "touch" and robot_models()[:2] == ("ur3", "ur3e")
    touch = haptic_model("touch")
    assert (touch.peak_force_n, touch.limits.continuous_force_n, touch.servo_rate_hz) == (3.3, 0.88, 1000.0)
    assert sim_rig_config(7) == SimRigConfig(seed=7)
    # a session on the paper's rig stores the rig as it always did: no model keys, the Touch's and UR3's numbers
    rec = SimRigConfig(seed=7).record()
    assert "haptic_model" not in rec and "robot_model" not in rec
    assert rec["touch"] == {"peak_force_n": 3.3, "continuous_force_n": 0.88, "thermal_budget_n2s": 60.0,
                            "derate_from_fraction": 0.5}
    assert rec["robot"] == {"controller_rate_hz": 125.0, "tracking_lag_s": 0.03}
    assert SimRigConfig(robot_model="ur3e").record()["robot_model"] == "ur3e"


def test_minus_one_is_the_robot_models_control_rate_once() -> None:
    ur3, ur3e = robot_model("ur3"), robot_model("ur3e")
    assert (ur3.rate_hz(-1), ur3e.rate_hz(-1), ur3e.rate_hz(250.0)) == (125.0, 500.0, 250.0)
    assert RtdeLink("10.0.0.2", -1, ur3e).rate_hz == 500.0 and RtdeLink("10.0.0.2", -1).rate_hz == 125.0
    from pipeline.assembly.real_rig import teleop_config

    def teleop_file(model: str) -> Any:
        return hardware_from_dict({
            "sensor": {"host": "10.0.0.1"}, "robot": {"host": "10.0.0.2", "frequency_hz": -1, "mode": "teleop",
                                                      "model": model},
            "haptic": {}, "frames": {"rot_tip_sensor": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
                                     "rot_haptic_base": [[1, 0, 0], [0, 0, 1], [0, -1, 0]]},
            "framework": {"f_max_n": 3.0, "f_scale_n": 7.0},
            "teleop": {"workspace_min_m": [0.2, -0.1, 0.05], "workspace_max_m": [0.4, 0.1, 0.25]}}, "hw.toml")

    # the period is 1 / the rate, the same division as here: exactly equal
    assert teleop_config(teleop_file("ur3")).period_s == 1.0 / 125.0
    assert teleop_config(teleop_file("ur3e")).period_s == 1.0 / 500.0


def test_the_simulated_robot_runs_at_its_models_control_rate() -> None:
    for model, cycle_ms in (("ur3", 8), ("ur3e", 2)):
        eng = build_sim_engine(EngineConfig(sim=sim_rig_config(0, robot=model), clock="virtual", ring_seconds=1.0))
        eng.loop.run_ticks(200)
        t = eng.ring.latest(100)["pose_age_ns"]  # type: ignore[index]
        assert int(t.max()) == (cycle_ms - 1) * 1_000_000  # a pose is at most one cycle (less a tick) old


def test_the_hand_moves_along_the_tissue_normal_in_the_devices_frame() -> None:
    """With the device's frame aligned to the base (the normal along its z, not the Touch's y), the hand presses
    and feels the force along z; the paper's frames keep it on the Touch's +y."""
    for rot, axis in ((IDENTITY, 2), (SimRigConfig().rot_haptic_base, 1)):
        cfg = dataclasses.replace(sim_rig_config(0), rot_haptic_base=rot)
        eng = build_sim_engine(EngineConfig(sim=cfg, clock="virtual", framework=FrameworkConfig(rot_haptic_base=rot),
                                            ring_seconds=10.0))
        eng.loop.run_ticks(3000)  # into the first scripted press
        rig: SimRig = eng.rig
        stylus = rig.haptic.stylus_m
        assert stylus[axis] < -0.01 and all(stylus[i] == 0.0 for i in range(3) if i != axis)
        assert rig.indentation_m > 0.0
        rendered = rig.haptic.applied_force_n
        # off the axis only what the sensor's unmodelled 0.5° mounting error leaves: a few per cent
        assert rendered[axis] > 0.1 and all(abs(rendered[i]) < 0.05 * rendered[axis] for i in range(3) if i != axis)


def test_no_backend_is_imported_until_a_rig_opens_one() -> None:
    """The registry names backends and twins as strings: the simulated rig's process imports no haptic or robot
    backend and no vendor SDK, and reading a hardware file imports none either."""
    code = ("import sys\n"
            "import pipeline.devices.registry, pipeline.settings.hardware, pipeline.assembly.real_rig\n"
            "from pipeline.assembly.engine import EngineConfig, build_sim_engine\n"
            "from pipeline.assembly.sim_config import sim_rig_config\n"
            "build_sim_engine(EngineConfig(sim=sim_rig_config(0), clock='virtual')).loop.run_ticks(50)\n"
            "bad = ('pipeline.backends.touch', 'pipeline.backends.hdapi', 'pipeline.backends.ur',\n"
            "       'pipeline.backends.ur_control', 'pipeline.backends.ur_backend', 'pyOpenHaptics', 'rtde_receive',\n"
            "       'rtde_control', 'serial')\n"
            "print(sorted(m for m in sys.modules if m in bad or m.split('.')[0] in bad))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_every_product_registration_names_a_backend_and_a_twin_where_they_live() -> None:
    """A backend is in pipeline.backends and a twin in pipeline.sim, each loadable by its name."""
    from pipeline.devices.registry import load

    models: list[Any] = [haptic_model(k) for k in haptic_models()] + [robot_model(k) for k in robot_models()]
    for m in models:
        assert isinstance(m.backend, str) and m.backend.startswith("pipeline.backends."), m.key
        assert isinstance(m.twin, str) and m.twin.startswith("pipeline.sim."), m.key
        assert callable(load(m.backend)) and callable(load(m.twin)), m.key
        assert m.source.strip(), m.key
