"""The simulated rig's physical models and the end-to-end run on the virtual clock."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from pipeline.assembly.engine import EngineConfig, build_sim_engine
from pipeline.commissioning.payload_identification import recommended_pose_set
from pipeline.core.clock import VirtualClock
from pipeline.devices.touch_output import HD_WARM_MOTORS, HapticLimits
from pipeline.force.frames import IDENTITY, mat_mul, transpose
from pipeline.sim.calibration import auto_calibrate
from pipeline.sim.hand import CompliantArm
from pipeline.sim.rig import SimRig, SimRigConfig
from pipeline.sim.robot import TOOL_DOWN, SimRobot
from pipeline.sim.sensor import _ROUND, GAMMA_RANGE, SATURATION_STATUS, SensorParams, SimForceSensor
from pipeline.sim.tissue import HuntCrossleyTissue, TissueParams
from pipeline.sim.touch import SimTouch

QUIET = SensorParams(
    noise_force_n=(0.0, 0.0, 0.0), noise_torque_nm=(0.0, 0.0, 0.0), random_walk_n_per_sqrt_s=0.0,
    drift_force_n=(0.0, 0.0, 0.0),
)


# -- tissue ---------------------------------------------------------------------------------------
def test_hunt_crossley_task_forces_and_continuity() -> None:
    p = TissueParams()
    # science.md §3: 0.6 N at ~1.4 mm and 1.2 N at ~2.3 mm
    assert p.static_force(0.0014) == pytest.approx(0.576, abs=0.01)
    assert p.static_force(0.0023) == pytest.approx(1.213, abs=0.01)
    assert p.depth_for_force(0.6) == pytest.approx(0.00144, abs=2e-5)
    t = HuntCrossleyTissue(p)
    assert t.step(-0.001, 0.001) == 0.0
    # first contact: continuous (no damping jump at δ = 0)
    assert t.step(1e-7, 0.001) < 1e-5
    # retracting fast never pulls (F ≥ 0)
    t.step(0.002, 0.001)
    assert t.step(0.0001, 0.0001) == 0.0  # 19 m/s retraction: 1 + αδ̇ < 0


def test_hunt_crossley_damping_and_relaxation() -> None:
    t = HuntCrossleyTissue(TissueParams(damping_s_per_m=0.5))
    t.step(0.002, 0.001)
    f = t.step(0.00201, 0.001)  # 10 mm/s
    elastic = 1.1e4 * 0.00201**1.5
    assert f == pytest.approx(elastic * (1 + 0.5 * 0.01), rel=1e-12)
    r = HuntCrossleyTissue(TissueParams(relax_stiffness_n_per_m=200.0, relax_time_s=1.0, damping_s_per_m=0.0))
    r.step(0.0, 0.001)
    peak = r.step(0.002, 0.001)
    for _ in range(20000):  # 20 τ
        held = r.step(0.002, 0.001)
    assert peak > held and held == pytest.approx(1.1e4 * 0.002**1.5, rel=1e-6)  # relaxes to the elastic part
    with pytest.raises(ValueError, match=r"tissue.exponent"):
        TissueParams(exponent=0.0)


# -- robot ----------------------------------------------------------------------------------------
def test_robot_publishes_at_125_hz_and_lags() -> None:
    r = SimRobot((0.0, 0.0, 0.1))
    r.command((0.0, 0.0, 0.09))
    stamps = []
    for k in range(40):
        r.advance(k * 1_000_000, 0.001)
        stamps.append(r.read_pose().t_ns)
    assert sorted(set(stamps)) == [0, 8_000_000, 16_000_000, 24_000_000, 32_000_000]
    # first-order lag τ = 30 ms: after 40 ms of tracking ≈ 1 − e^{−40/30} of the 10 mm step
    moved = 0.1 - r.position_m[2]
    assert moved == pytest.approx(0.01 * (1 - math.exp(-0.040 / 0.03)), rel=1e-9)
    r.frozen = True
    r.advance(48_000_000, 0.001)
    assert r.read_pose().t_ns == 32_000_000


# -- sensor ---------------------------------------------------------------------------------------
def test_sensor_reports_weight_contact_and_bias_in_its_frame() -> None:
    s = SimForceSensor(QUIET)
    rsb = transpose(TOOL_DOWN)  # sensor axes = tool axes, tool pointing down
    s.sample(0, rsb, (0.0, 0.0, 1.0), 0.001)  # 1 N upward contact
    w = s.read_wrench()
    m, g = QUIET.mass_kg, 9.80665
    # tool down: base −z (gravity) is sensor +z; the upward contact is sensor −z
    assert w.fz == pytest.approx(m * g - 1.0 + QUIET.bias_force_n[2], abs=1e-6)
    assert w.fx == pytest.approx(QUIET.bias_force_n[0], abs=1e-6)
    # lever arm: contact at the tip (0, 0, 0.35) along z produces no torque; weight at c does
    c = QUIET.com_m
    assert w.tx == pytest.approx(c[1] * m * g + QUIET.bias_torque_nm[0], abs=1e-6)
    # quantised to counts (cpf = 1e6)
    assert w.fz * 1e6 == pytest.approx(round(w.fz * 1e6), abs=1e-6)
    assert (w.status, w.rdt_sequence, w.ft_sequence) == (0, 1, 1)


def test_sensor_saturation_sets_status_and_clips() -> None:
    s = SimForceSensor(QUIET)
    s.sample(0, IDENTITY, (500.0, 0.0, 0.0), 0.001)
    w = s.read_wrench()
    assert w.fx == GAMMA_RANGE[0] and w.status == SATURATION_STATUS


def test_sensor_packet_loss_and_stall_keep_the_old_sample() -> None:
    s = SimForceSensor(SensorParams(packet_loss=0.3), seed=3)
    stamps = []
    for k in range(2000):
        s.sample(k * 1_000_000, IDENTITY, (0.0, 0.0, 0.0), 0.001)
        stamps.append(s.read_wrench().t_ns)
    fresh = sum(1 for k, t in enumerate(stamps) if t == k * 1_000_000)
    assert 1250 < fresh < 1550  # ≈ 70 % delivered
    assert s.lost_packets == 2000 - fresh
    last = s.read_wrench()  # the box numbered every packet, lost or not
    assert last.rdt_sequence == last.ft_sequence == last.t_ns // 1_000_000 + 1
    s.stalled = True
    before = s.read_wrench()
    s.sample(5_000_000_000, IDENTITY, (0.0, 0.0, 0.0), 0.001)
    assert s.read_wrench() == before


# -- Touch ----------------------------------------------------------------------------------------
def test_touch_clamps_to_its_peak_and_renders_only_fresh_commands() -> None:
    t = SimTouch(HapticLimits(peak_force_n=3.3, continuous_force_n=0.88, thermal_budget_n2s=60.0))
    t.advance(0, 0.001)
    t.command_force(10.0, 0.0, 0.0)  # commanded at t = 0 ms
    t.advance(1_000_000, 0.001)
    assert t.applied_force_n == pytest.approx((3.3, 0.0, 0.0))
    # nobody commands any more: rendered while younger than 10 ms, exactly zero once 10 ms old
    t.advance(9_999_999, 0.001)
    assert t.applied_force_n == pytest.approx((3.3, 0.0, 0.0))
    t.advance(10_000_000, 1e-9)
    assert t.applied_force_n == (0.0, 0.0, 0.0) and t.output.stale
    t.command_force(math.nan, 0.0, 0.0)
    t.advance(10_500_000, 0.0005)
    assert t.applied_force_n == (0.0, 0.0, 0.0)


def test_touch_derates_toward_its_continuous_rating_and_stays_under_budget() -> None:
    spec = HapticLimits(peak_force_n=3.3, continuous_force_n=0.88, thermal_budget_n2s=1.0)
    t = SimTouch(spec)
    limits, heat = [], []
    for k in range(3000):  # the loop commands 10 N every tick for 3 s
        limit = t.read_state().force_limit_n  # the limit in force when this tick renders
        t.advance(k * 1_000_000, 0.001)
        t.command_force(10.0, 0.0, 0.0)
        limits.append(t.read_state().force_limit_n)
        heat.append(t.heat_n2s)
        assert math.hypot(*t.applied_force_n) <= limit * (1 + 1e-12)
    assert t.error_code == 0  # derating kept it under the budget: no WARM_MOTORS
    assert max(heat) < spec.thermal_budget_n2s
    # full peak until half the budget, then falling monotonically toward the continuous rating
    half = next(i for i, h in enumerate(heat) if h > 0.5)
    assert all(x == 3.3 for x in limits[:half])
    assert all(b <= a for a, b in itertools.pairwise(limits[half:]))
    assert 0.88 < limits[-1] < 1.0 and t.read_state().heat_fraction > 0.95
    # resting cools it: the full peak comes back
    for k in range(3000, 6000):
        t.advance(k * 1_000_000, 0.001)
        t.command_force(0.0, 0.0, 0.0)
    assert t.read_state().force_limit_n == 3.3


def test_touch_past_its_budget_raises_warm_motors_until_cooled_and_rearmed() -> None:
    t = SimTouch(HapticLimits(peak_force_n=3.3, continuous_force_n=0.88, thermal_budget_n2s=1.0))
    t.advance(0, 0.001)
    t.command_force(1.0, 0.0, 0.0)
    t.output.heat.heat_n2s = 1.01  # past the budget (e.g. after a servo stall): the backstop
    t.advance(1_000_000, 0.001)
    assert t.error_code == HD_WARM_MOTORS and t.applied_force_n == (0.0, 0.0, 0.0)
    assert not t.rearm()  # still hot
    k = 2
    while t.heat_n2s > 0.5:
        t.command_force(0.0, 0.0, 0.0)
        t.advance(k * 1_000_000, 0.001)
        k += 1
    assert t.rearm() and t.error_code == 0


# -- calibration on the simulated rig ------------------------------------------------------------------
def test_sim_calibration_recovers_payload_and_rest_residual_is_small() -> None:
    """24-pose set on the noisy, drifting sensor: m, c, biases within noise; compensated force at rest ≤ 0.02 N RMS."""
    rig = SimRig(SimRigConfig(seed=4))
    clock = VirtualClock()
    cal, poses = auto_calibrate(rig, clock, recommended_pose_set(24))
    p = rig.config.sensor
    assert len(poses) == 24 and cal.model == "affine"
    assert cal.mass_kg == pytest.approx(p.mass_kg, abs=2e-3)
    assert cal.com_m == pytest.approx(p.com_m, abs=1e-3)
    true_bias = rig.sensor.current_bias(rig.sim_time_s)
    # bias within noise + the random walk during the 12 s of calibration
    assert cal.force_bias_n == pytest.approx(true_bias[:3], abs=0.02)
    assert cal.torque_bias_nm == pytest.approx(true_bias[3:], abs=2e-3)
    assert cal.mount_angle_deg == pytest.approx(0.5, abs=0.2)
    assert cal.condition_number < 50

    # at rest, tool down, the compensated force is noise only
    errs = []
    for _ in range(2000):
        clock.advance(1_000_000)
        rig.advance(clock.now_ns())
        w = rig.sensor.read_wrench()
        rsb = transpose(mat_mul(rig.robot.read_pose().rot_base_tip, rig.config.rot_tip_sensor))
        comp = cal.compensate(w[1:7], rsb)
        errs.append(comp[:3])
    e = np.array(errs)
    # systematic part (what a filter cannot remove)
    assert np.linalg.norm(e.mean(axis=0)) < 0.02
    # the task's signal: magnitude of the 10-sample moving average
    kernel = np.ones(10) / 10
    filt = np.stack([np.convolve(e[:, i], kernel, mode="valid") for i in range(3)], axis=1)
    assert math.sqrt(np.mean(np.sum(filt**2, axis=1))) <= 0.02


# -- end to end -----------------------------------------------------------------------------------
def _run(seed: int, ticks: int, haptics: bool = True) -> np.ndarray:
    eng = build_sim_engine(EngineConfig(sim=SimRigConfig(seed=seed), clock="virtual", haptics_on=haptics))
    eng.loop.run_ticks(ticks)
    assert eng.ring is not None
    rows = eng.ring.latest(ticks)
    eng.ring.close()
    return rows


def test_end_to_end_run_is_deterministic_and_tracks_the_true_force() -> None:
    rows = _run(seed=1, ticks=9000)
    again = _run(seed=1, ticks=9000)
    assert rows.tobytes() == again.tobytes()
    other = _run(seed=2, ticks=2000)
    assert other.tobytes() != rows[:2000].tobytes()

    true_f = np.abs(rows["true_fz"])
    assert true_f.max() > 1.0  # the scripted presses reach FIRM-like forces
    contact = true_f > 0.05
    err = rows["force_n"][contact] - true_f[contact]
    # filter delay (4.5 ms) and noise only
    assert math.sqrt(np.mean(err**2)) < 0.05
    render = np.sqrt(rows["render_fx"] ** 2 + rows["render_fy"] ** 2 + rows["render_fz"] ** 2)
    assert render.max() <= 3.0
    # rendered ≈ 3·tanh(F/7) of the filtered force once ramped in and steady
    steady = contact & (rows["gain"] == 1.0)
    expect = 3.0 * np.tanh(rows["force_n"][steady] / 7.0)
    assert np.max(np.abs(render[steady] - expect)) < 0.02
    # rendered force pushes the hand up (+y of the Touch) while pressing
    assert np.all(rows["render_fy"][steady] > 0)
    assert rows["faults"].max() == 0
    assert np.all(np.diff(rows["t_s"]) == pytest.approx(0.001, abs=1e-12))


def test_haptics_off_renders_nothing_and_presses_deeper() -> None:
    on = _run(seed=5, ticks=6000, haptics=True)
    off = _run(seed=5, ticks=6000, haptics=False)
    assert np.all(off["render_fx"] == 0) and np.all(off["render_fy"] == 0) and np.all(off["render_fz"] == 0)
    # Wagner–Howe: without the push-back the same hand motion indents further
    assert np.abs(off["true_fz"]).max() > np.abs(on["true_fz"]).max()


def test_arm_one_substep_shortcut_is_the_integrator_bit_for_bit() -> None:
    # step() writes the 1 kHz case out (issue 47: a cheaper tick); it must stay the general integrator's arithmetic
    # in its order -- a stored study's bytes depend on it -- so the two are compared exactly, not within a tolerance
    rng = np.random.default_rng(47)
    fast, ref = CompliantArm(), CompliantArm()
    for dt in [0.001, 0.0009999999999999998, 0.0005, 0.0, *rng.uniform(0.0, 0.001, 300)]:
        y_c, felt = float(rng.uniform(-0.03, 0.005)), float(rng.uniform(-1.0, 3.0))
        assert fast.step(y_c, felt, float(dt)) == ref.substeps(y_c, felt, float(dt), 1)
        assert (fast.y_m, fast.v_m_s) == (ref.y_m, ref.v_m_s)
    # a long tick (a stalled loop) still takes sub-steps of at most 1 ms
    fast.step(0.0, 0.0, 0.0025)
    ref.substeps(0.0, 0.0, 0.0025, 3)
    assert (fast.y_m, fast.v_m_s) == (ref.y_m, ref.v_m_s)


def test_the_sensors_counts_round_as_round_does() -> None:
    """The sample's quantisation (x + 1.5·2⁵² − 1.5·2⁵²) is round(x) -- halves to even, signs, zero -- below 2⁵¹ counts,
    and a sensor whose full scale could reach 2⁵¹ counts is refused."""
    rng = np.random.default_rng(4)
    values = [*rng.uniform(-4e8, 4e8, 20_000), *(k + 0.5 for k in range(-50, 50)), -0.5, -0.0, 0.49999999999999994,
              2.0**51 - 1.5, -(2.0**51) + 0.5, 130.0 * 1e6 + 0.5]
    # exact, not approximate: the claim is bit-identity with round() (the stored counts), and two IEEE-754 double
    # additions are correctly rounded on every CPU -- no BLAS kernel or fused operation is involved
    assert all(x + _ROUND - _ROUND == round(x) for x in values)
    assert all(math.copysign(1.0, (x + _ROUND - _ROUND) / 1e6) == math.copysign(1.0, round(x) / 1e6) for x in values)
    with pytest.raises(ValueError, match="counts_per_force"):
        SimForceSensor(SensorParams(counts_per_force=1e14))
