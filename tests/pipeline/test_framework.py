"""HapticFramework: the fused hot path equals the stage modules composed, bit for bit."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.force.filters import MovingAverage3
from pipeline.force.frames import axis_angle, mat_mul, mat_vec, rotvec_to_matrix, transpose
from pipeline.force.framework import STEP_FIELDS, FrameworkConfig, HapticFramework
from pipeline.force.payload_compensator import NO_PAYLOAD, PayloadCalibration
from pipeline.force.safety import SafetyConfig, SafetyGovernor
from pipeline.force.scaling import scale_components, scale_force


def _calibration() -> PayloadCalibration:
    """A plausible affine calibration with a 1° mount rotation."""
    a = tuple(0.65 * v for v in axis_angle((1.0, 0.4, 0.2), math.radians(1.0)))
    base = NO_PAYLOAD.to_dict()
    base.update(
        mass_kg=0.65, com_m=[0.003, -0.002, 0.11], force_bias_n=[0.8, -0.5, 1.2],
        torque_bias_nm=[0.03, -0.02, 0.01], gravity_matrix=list(a), model="affine",
    )
    return PayloadCalibration.from_dict(base)


class Reference:
    """Algorithm 1 written as the plain composition of the stage modules."""

    def __init__(self, cfg: FrameworkConfig, cal: PayloadCalibration, peak: float) -> None:
        self.cfg, self.cal = cfg, cal
        self.mounted = cal.for_mount(cfg.rot_tip_sensor)
        self.ma = MovingAverage3(cfg.filter_window)
        self.safety = SafetyGovernor(cfg.safety, peak)
        self.rbt = transpose(transpose(cfg.rot_tip_sensor))  # placeholder, set by set_pose

    def set_pose(self, rbt: tuple[float, ...]) -> None:
        self.rbt = rbt

    def step(self, w: tuple[float, ...], enabled: bool, dt: float) -> tuple[float, ...]:
        comp = self.mounted.compensate(w, self.rbt)
        m = self.ma.update(comp[0], comp[1], comp[2])
        tip = mat_vec(self.cfg.rot_tip_sensor, m)
        base = mat_vec(self.rbt, tip)
        hap = mat_vec(self.cfg.rot_haptic_base, base)
        scaled = scale_components(*hap, self.cfg.f_max_n, self.cfg.f_scale_n)
        out = self.safety.step(*scaled, enabled, dt)
        return (*comp[:3], *m, *tip, *base, *hap, *scaled, *out)


def _same(a: float, b: float) -> bool:
    return a == b or (math.isnan(a) and math.isnan(b))


finite = st.floats(min_value=-50.0, max_value=50.0, allow_nan=False)
extreme = st.one_of(
    finite,
    st.sampled_from([0.0, -0.0, 5e-324, -5e-324, 1e-300, 1e300, -1e300, 1e308, math.inf, -math.inf, math.nan]),
)


@settings(max_examples=150, deadline=None)
@given(
    window=st.integers(1, 12),
    samples=st.lists(
        st.tuples(st.tuples(*[extreme] * 6), st.booleans(), st.sampled_from([0.001, 0.001, 0.001, 0.0005, 0.004, 0.2])),
        min_size=1, max_size=60,
    ),
    rv=st.tuples(*[st.floats(-3.0, 3.0)] * 3),
    mount=st.one_of(st.none(), st.tuples(*[st.floats(-0.3, 0.3)] * 3)),
    peak=st.sampled_from([3.3, 2.0, 0.5]),
    reset_at=st.integers(0, 60),
)
def test_fused_step_equals_composed_stages(window, samples, rv, mount, peak, reset_at) -> None:
    """Every output of every tick is identical to the stage modules composed (including extremes).

    A device peak below f_max makes the safety clamp act inside the fused
    path's normal range; a tilted sensor mount exercises all three rotations;
    a reset midway checks the fused path follows the emptied filter.
    """
    rts = FrameworkConfig().rot_tip_sensor if mount is None else rotvec_to_matrix(*mount)
    cfg = FrameworkConfig(filter_window=window, rot_tip_sensor=rts, safety=SafetyConfig(ramp_in_s=0.01))
    cal = _calibration()
    fw = HapticFramework(cfg, cal, device_peak_n=peak)
    ref = Reference(cfg, cal, peak)
    rbt = rotvec_to_matrix(*rv)
    fw.set_pose(rbt)
    ref.set_pose(rbt)
    for k, (w, enabled, dt) in enumerate(samples):
        if k == reset_at:
            fw.reset()
            ref.ma.reset()
            ref.safety.force_zero()
        got = fw.step(w[0], w[1], w[2], enabled, dt)
        assert fw.compensated_torque(*w[3:]) == tuple(ref.mounted.compensate(w, rbt)[3:]) or any(
            math.isnan(v) for v in w[3:]
        )
        want = ref.step(w, enabled, dt)
        # compensation is evaluated from precomputed offsets in the fused path:
        # identical arithmetic order (f − (A g + b)) makes it exact too
        assert len(got) == len(STEP_FIELDS)
        assert all(_same(g, x) for g, x in zip(got, want, strict=True)), (w, enabled, dt, got, want)


@pytest.mark.parametrize("peak", [3.3, 2.0, 0.5])
def test_fused_step_equals_composed_stages_at_the_clamp(peak) -> None:
    """Sustained forces that ramp the output up to the clamp and hold it there, bit for bit.

    Random samples rarely hold a force long enough for the slew-limited output
    to reach the clamp radius, which is where the fused path's clamp-free
    bound decides; this sweeps the force magnitude slowly across it.
    """
    cfg = FrameworkConfig(safety=SafetyConfig(ramp_in_s=0.01))
    cal = _calibration()
    fw = HapticFramework(cfg, cal, device_peak_n=peak)
    ref = Reference(cfg, cal, peak)
    rbt = rotvec_to_matrix(0.3, -0.2, 0.1)
    fw.set_pose(rbt)
    ref.set_pose(rbt)
    rendered = []
    for k in range(3000):
        fz = 0.05 * k if k < 1500 else 0.05 * (3000 - k)  # 0 → 75 N → 0 N, slowly
        w = (0.3, -0.2, fz, 0.0, 0.0, 0.0)
        got = fw.step(w[0], w[1], w[2], True, 0.001)
        assert got == ref.step(w, True, 0.001), k
        rendered.append(math.hypot(*got[18:21]))
    assert max(rendered) <= fw.safety.limit_n
    assert max(rendered) > fw.safety.limit_n * (1 - 1e-9)  # the clamp was reached


def test_steady_state_matches_paper_mapping() -> None:
    """A constant 1.2 N contact force along the tool axis renders 3·tanh(1.2/7) N along the haptic +y."""
    cfg = FrameworkConfig(safety=SafetyConfig(ramp_in_s=0.01))
    fw = HapticFramework(cfg, device_peak_n=3.3)
    tool_down = (1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0)
    fw.set_pose(tool_down)
    # tissue pushes the tool up (+z base) = −z in the tool-down sensor frame
    for _ in range(200):
        out = fw.step(0.0, 0.0, -1.2, True, 0.001)
    rec = dict(zip(STEP_FIELDS, out, strict=True))
    assert rec["base_fz"] == pytest.approx(1.2, abs=1e-15)
    assert rec["haptic_fy"] == pytest.approx(1.2, abs=1e-15)
    expected = 3.0 * math.tanh(1.2 / 7.0)
    assert rec["render_fy"] == pytest.approx(expected, rel=1e-14)
    assert rec["render_fx"] == 0.0 and rec["render_fz"] == 0.0
    assert scale_force((0.0, 1.2, 0.0))[1] == pytest.approx(expected, rel=1e-15)


def test_disabled_output_ramps_to_zero_but_path_runs() -> None:
    cfg = FrameworkConfig(safety=SafetyConfig(ramp_in_s=0.01))
    fw = HapticFramework(cfg, device_peak_n=3.3)
    for _ in range(100):
        fw.step(0.5, 0.0, 0.0, True, 0.001)
    outs = [fw.step(0.5, 0.0, 0.0, False, 0.001) for _ in range(60)]
    zero_at = next(i for i, o in enumerate(outs) if o[18:21] == (0.0, 0.0, 0.0))
    assert zero_at + 1 <= 40  # fault_ramp_s = 0.04 at 1 ms ticks
    assert all(o[18:21] == (0.0, 0.0, 0.0) for o in outs[zero_at:])
    assert outs[-1][3] == pytest.approx(0.5)  # filtered force still computed


def test_rls_refinement_tracks_bias_and_updates_offsets() -> None:
    from pipeline.force.bias_refinement import RlsBias

    cal = _calibration()
    rls = RlsBias(cal.force_bias_n, cal.torque_bias_nm, forgetting=0.99, gate_force_n=0.15)
    fw = HapticFramework(FrameworkConfig(), cal, device_peak_n=3.3, rls=rls)
    pose = (1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0)
    fw.set_pose(pose)
    rsb = transpose(mat_mul(pose, FrameworkConfig().rot_tip_sensor))
    g = cal.payload_wrench(rsb)
    drifted = (0.85, -0.5, 1.25, 0.03, -0.02, 0.01)  # the bias moved by 50 mN on x and z
    raw = tuple(g[i] + drifted[i] for i in range(6))
    for _ in range(2000):
        assert fw.refine_bias(*raw)
    out = fw.step(raw[0], raw[1], raw[2], False, 0.001)
    assert out[0] == pytest.approx(0.0, abs=1e-9) and out[2] == pytest.approx(0.0, abs=1e-9)
    assert fw.calibration.force_bias_n == pytest.approx(drifted[:3], abs=1e-9)
    # a contact-sized innovation is refused by the gate
    assert not fw.refine_bias(raw[0], raw[1], raw[2] + 0.5, *raw[3:])


def test_config_validation_names_the_field() -> None:
    with pytest.raises(ValueError, match="filter_window = 0"):
        FrameworkConfig(filter_window=0)
    with pytest.raises(ValueError, match="f_scale_n = -7"):
        FrameworkConfig(f_scale_n=-7)
    with pytest.raises(ValueError, match="rot_haptic_base"):
        FrameworkConfig(rot_haptic_base=(1, 0, 0, 0, 1, 0, 0, 0, 2))
    with pytest.raises(ValueError, match="f_max_n = nan"):
        FrameworkConfig(f_max_n=math.nan)
    # the safety clamp follows f_max
    assert FrameworkConfig(f_max_n=2.0).safety.f_max_n == 2.0


def _pushing(fw: HapticFramework, ticks: int) -> list[tuple[float, ...]]:
    """Steps with a force that grows past the clamp (the slew state ends at the limit)."""
    return [fw.step(0.8 + 0.004 * k, -0.5 + 0.01 * k, 1.2 + 0.02 * k, True, 0.001) for k in range(ticks)]


def test_a_snapshot_carries_the_device_limit_and_restores_bit_for_bit() -> None:
    fw = HapticFramework(FrameworkConfig(), _calibration(), device_peak_n=3.3)
    _pushing(fw, 600)
    fw.set_device_limit(1.7)  # the Touch derates mid-contact
    _pushing(fw, 50)
    snap = fw.snapshot()
    assert snap["device_limit_n"] == 1.7
    twin = HapticFramework.restore(snap)
    assert twin.safety.limit_n == fw.safety.limit_n == 1.7
    ours, theirs = _pushing(fw, 300), _pushing(twin, 300)
    assert math.hypot(*ours[-1][18:21]) == pytest.approx(1.7)  # the limit is what clamps
    for a, b in zip(ours, theirs, strict=True):
        assert all(_same(x, y) for x, y in zip(a, b, strict=True))
    # replay with another f_max: the device's own limit still clamps (the raw limit is kept, not the clamp)
    higher = HapticFramework.restore(snap, FrameworkConfig(f_max_n=3.2))
    assert higher.safety.static_limit_n == 3.2 and higher.safety.limit_n == fw.safety.limit_n
    # a device that does not derate (no limit given, or cooled to its peak) and a snapshot from before derating
    fw2 = HapticFramework(FrameworkConfig(), _calibration(), device_peak_n=3.3)
    assert fw2.snapshot()["device_limit_n"] is None
    old = dict(snap)
    del old["device_limit_n"]
    assert HapticFramework.restore(old).safety.limit_n == fw.safety.static_limit_n
