"""The simulated rig: hand → haptic device → robot → tissue → wrist sensor, stepped by the loop.

Only what the force-regulation scene needs (science.md §2, §3, §5): a 1-D
Hunt–Crossley tissue under a horizontal surface, an arm that follows the
stylus through its controller's cycle with a tracking lag, a sensor that sees
the tool's weight at the current orientation plus the contact force, and a
haptic device with real limits.  Everything derives from one seed, so a run is
reproducible bit for bit on the virtual clock.

The haptic device and the robot are their models' simulated twins
(:mod:`pipeline.devices.registry`; by default the paper's Touch and UR3 on a
CB3): the registry gives each twin its limits -- the haptic device's peak,
continuous rating and thermal budget, the robot controller's rate -- so the
simulated rig of another device is a configuration, not another rig.  The
scene is one-dimensional: the hand moves the stylus along the tissue normal
(base +z) as the device's frame sees it (``rot_haptic_base``'s third column;
the Touch's +y with the paper's frames) and feels the rendered force along it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields, is_dataclass
from typing import Any

import numpy as np

from pipeline.core.compiled import State, fingerprint, is_warm, kernel, warm_once
from pipeline.devices.registry import DEFAULT_HAPTIC_MODEL, DEFAULT_ROBOT_MODEL, haptic_model, robot_model
from pipeline.devices.touch_output import DEFAULT_COMMAND_TIMEOUT_S, HapticLimits
from pipeline.force.frames import IDENTITY, Mat3, Vec3, axis_angle, mat_mul, transpose
from pipeline.force.framework import DEFAULT_ROT_HAPTIC_BASE, DEFAULT_ROT_TIP_SENSOR
from pipeline.sim import hand as sim_hand
from pipeline.sim import robot as sim_robot
from pipeline.sim import sensor as sim_sensor
from pipeline.sim import tissue as sim_tissue
from pipeline.sim.faults import DEFAULT_DURATION_S, FaultInjector, SimFault
from pipeline.sim.hand import ArmParams, CompliantArm, HandObservation, HoldStill, StylusDriver
from pipeline.sim.jaw import SimJaw
from pipeline.sim.robot import TOOL_DOWN, RobotParams, SimRobot
from pipeline.sim.sensor import SensorParams, SimForceSensor
from pipeline.sim.tissue import HuntCrossleyTissue, TissueParams
from pipeline.sim.touch import SimTouch

__all__ = ["SimRig", "SimRigConfig", "warm_kernels"]

#: A long tick (a stalled loop) is simulated as at most this much time.
_MAX_DT_S = 0.01
_new_tuple = tuple.__new__

# The rig's state, one float64 array (:func:`step_kernel`'s layout): the tool's home (base frame), the haptic device's
# frame in the base frame (row-major), the hand's axis in the device's frame, the motion scale, the surface's height,
# a push on the tip (base frame); then the arm's, the robot's, the tissue's and the sensor's states, each the slice
# its model works on (``adopt``).
_HOME, _ROT, _AXIS, _SCALE, _SURFACE, _PUSH = 0, 3, 12, 15, 16, 17
_ARM = 20
_ROBOT = _ARM + sim_hand.STATE_SIZE
_TISSUE = _ROBOT + sim_robot.STATE_SIZE
_SENSOR = _TISSUE + sim_tissue.STATE_SIZE
_STATE_SIZE = _SENSOR + sim_sensor.STATE_SIZE
#: Where the rig's state holds the arm's, the robot's and the sensor's slices (a block of ticks reads them).
ARM_AT, ROBOT_AT, SENSOR_AT = _ARM, _ROBOT, _SENSOR
#: A long tick (a stalled loop) is simulated as at most this much time, s.
MAX_DT_S = _MAX_DT_S


@kernel
def target_kernel(st: State, y: float) -> tuple[float, float, float]:
    """The robot's target (base frame, m) for the stylus at ``y`` along the hand's axis (m): home plus the motion
    scale times the displacement, turned from the haptic device's frame into the base frame."""
    ym = y * st[_SCALE]
    ax, ay, az = st[_AXIS], st[_AXIS + 1], st[_AXIS + 2]
    hx = ax * ym if ax != 0.0 else 0.0  # (off-axis components exactly zero)
    hy = ay * ym if ay != 0.0 else 0.0
    hz = az * ym if az != 0.0 else 0.0
    r = _ROT
    return (st[_HOME] + (st[r] * hx + st[r + 1] * hy + st[r + 2] * hz),
            st[_HOME + 1] + (st[r + 3] * hx + st[r + 4] * hy + st[r + 5] * hz),
            st[_HOME + 2] + (st[r + 6] * hx + st[r + 7] * hy + st[r + 8] * hz))


def _compile_step(callees: int) -> Callable[..., tuple[float, float, bool, int, float, float, float, float, float,
                                                        float]]:
    """:func:`step_kernel` closed over ``callees``, the :func:`pipeline.core.compiled.fingerprint` of the models it
    calls: numba keys its cache on the kernel's own file and closure, so a change in a model recompiles it."""

    @kernel
    def step_kernel(st: State, noise: State, ni: int, y_c: float, felt: float, dt_s: float, robot_ns: int,
                    sensor_ns: int) -> tuple[float, float, bool, int, float, float, float, float, float, float]:
        """The tick after the hand's decision, when nothing on the Python side is due (:meth:`SimRig.advance`): the
        arm toward ``y_c`` under the felt force, the robot's target from the stylus, the robot (at ``robot_ns``), the
        tissue, the sensor (at ``sensor_ns``) -- each model's own kernel on its slice of ``st``, in
        :meth:`SimRig._advance_by_models`' order.

        Returns the stylus position along the hand's axis (m), the contact force (N), whether the robot's controller
        cycled, what the sensor did (:func:`pipeline.sim.sensor.sample_kernel`) and its record's six values.
        """
        _ = callees  # (read, so that it is in the closure numba's cache is keyed on)
        y = sim_hand.step_kernel(st[_ARM:_ROBOT], y_c, felt, dt_s)
        rob = st[_ROBOT:_TISSUE]
        tx, ty, tz = target_kernel(st, y)
        sim_robot.command_kernel(rob, tx, ty, tz)
        cycled = sim_robot.advance_kernel(rob, robot_ns, dt_s)
        depth = st[_SURFACE] - rob[2]
        tis = st[_TISSUE:_SENSOR]
        f = sim_tissue.step_kernel(tis, depth, dt_s) if dt_s > 0 else tis[2]
        what = sim_sensor.sample_kernel(st[_SENSOR:_STATE_SIZE], noise, ni, sensor_ns, st[_PUSH], st[_PUSH + 1],
                                        f + st[_PUSH + 2], dt_s)
        o = _SENSOR + sim_sensor.OUT
        return y, f, cycled, what, st[o], st[o + 1], st[o + 2], st[o + 3], st[o + 4], st[o + 5]

    return step_kernel


#: The rig's tick after the hand's decision in one compiled call (:func:`_compile_step`).
step_kernel = _compile_step(fingerprint(sim_hand, sim_robot, sim_tissue, sim_sensor))


@dataclass(frozen=True, slots=True)
class SimRigConfig:
    """Everything that defines a simulated rig.

    Attributes
    ----------
    seed
        Seed of every random process (noise, drift, packet loss).
    surface_z_m
        Height of the tissue surface in the base frame.
    tip_home_m
        Tool-tip start position (base frame); the default is 15 mm above the surface.
    motion_scale
        Robot displacement per stylus displacement.
    rot_tip_sensor
        The sensor mounting the application is told about (nominal).
    mount_error_deg
        The true mounting differs from the nominal by this rotation about an
        oblique axis -- the unmodelled error the affine calibration absorbs.
    sensor_z_mount_deg
        A lab's mounting mistake: the sensor is turned about its own z axis by
        this much, and nobody told the pipeline (``--sim-mount-error-deg``).
        The payload calibration absorbs it for the weight; the frame and sign
        check must catch it for the contact force.
    rot_haptic_base
        Touch frame vs robot base.
    tip_in_flange_m
        Where the instrument tip really is in the flange frame (what the TCP
        calibration must recover; the CAD nominal would be (0, 0, 0.40) m).
    pivot_m
        The divot of the TCP calibration, base frame (within reach, clear of the tissue).
    pivot_noise_m
        Per-axis standard deviation of the robot's reported flange position and
        of the tip's seat in the divot, m (UR3 repeatability ±0.1 mm).
    robot
        The simulated arm's timing; None: its model's control rate, the default tracking lag.
    touch
        The haptic device's limits; None: its model's (a rehearsal gives hotter motors here).
    haptic_model, robot_model
        The devices' models (:mod:`pipeline.devices.registry`), whose twins the rig builds.
    """

    seed: int = 0
    surface_z_m: float = 0.10
    tip_home_m: Vec3 = (0.30, 0.0, 0.115)
    motion_scale: float = 1.0
    rot_tip_sensor: Mat3 = DEFAULT_ROT_TIP_SENSOR
    mount_error_deg: float = 0.5
    sensor_z_mount_deg: float = 0.0
    rot_haptic_base: Mat3 = DEFAULT_ROT_HAPTIC_BASE
    tip_in_flange_m: Vec3 = (0.0011, -0.0007, 0.4023)
    pivot_m: Vec3 = (0.35, 0.12, 0.14)
    pivot_noise_m: float = 3e-5
    tissue: TissueParams = field(default_factory=TissueParams)
    sensor: SensorParams = field(default_factory=SensorParams)
    robot: RobotParams | None = None
    touch: HapticLimits | None = None
    arm: ArmParams = field(default_factory=ArmParams)
    haptic_model: str = DEFAULT_HAPTIC_MODEL
    robot_model: str = DEFAULT_ROBOT_MODEL

    def __post_init__(self) -> None:
        haptic_model(self.haptic_model)  # KeyError naming the models there are
        robot_model(self.robot_model)

    @property
    def robot_params(self) -> RobotParams:
        """The simulated arm's timing: :attr:`robot`, or its model's control rate with the default tracking lag."""
        if self.robot is not None:
            return self.robot
        return RobotParams(controller_rate_hz=robot_model(self.robot_model).control_rate_hz)

    @property
    def haptic_limits(self) -> HapticLimits:
        """The haptic device's limits: :attr:`touch`, or its model's."""
        return self.touch if self.touch is not None else haptic_model(self.haptic_model).limits

    def record(self) -> dict[str, Any]:
        """What a session stores of the rig (``config_json``'s ``"sim"``): every field, the devices' parameters
        resolved; the models named only when they are not the paper's (a session on the paper's rig stores what it
        stored before the models)."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["robot"], out["touch"] = self.robot_params, self.haptic_limits
        for key, default in (("haptic_model", DEFAULT_HAPTIC_MODEL), ("robot_model", DEFAULT_ROBOT_MODEL)):
            if out[key] == default:
                del out[key]
        return {k: asdict(v) if is_dataclass(v) and not isinstance(v, type) else v for k, v in out.items()}


class SimRig:
    """Implements the loop's ``Rig`` interface with simulated devices."""

    def __init__(self, config: SimRigConfig | None = None, driver: StylusDriver | None = None) -> None:
        cfg = config or SimRigConfig()
        self.config = cfg
        seeds = np.random.SeedSequence(cfg.seed).generate_state(4)
        self.sensor = SimForceSensor(cfg.sensor, seed=int(seeds[0]))
        #: The robot's twin (a :class:`pipeline.sim.robot.SimRobot` for a UR).
        self.robot: SimRobot = robot_model(cfg.robot_model).open_twin(cfg.tip_home_m, TOOL_DOWN, cfg.robot_params)
        #: The haptic device's twin (a :class:`pipeline.sim.touch.SimTouch` for a Touch).
        self.haptic: SimTouch = haptic_model(cfg.haptic_model).open_twin(DEFAULT_COMMAND_TIMEOUT_S, cfg.haptic_limits)
        self.tissue = HuntCrossleyTissue(cfg.tissue)
        self.arm = CompliantArm(cfg.arm)
        self.driver: StylusDriver = driver or HoldStill()
        rot_base_haptic = transpose(cfg.rot_haptic_base)
        r = cfg.rot_haptic_base
        #: The tissue normal (base +z) in the haptic device's frame: the axis the hand moves the stylus along.
        self.hand_axis: Vec3 = (r[2], r[5], r[8])
        along = [(i, c) for i, c in enumerate(self.hand_axis) if c != 0.0]
        # one device axis (the paper's frames: +y): the felt force is that component, exactly
        self._hand_one_axis = along[0] if len(along) == 1 else None
        err = axis_angle((1.0, 1.0, 0.3), cfg.mount_error_deg * np.pi / 180.0) if cfg.mount_error_deg else IDENTITY
        if cfg.sensor_z_mount_deg:
            err = mat_mul(err, axis_angle((0.0, 0.0, 1.0), cfg.sensor_z_mount_deg * np.pi / 180.0))
        #: The true sensor mounting (nominal × error) the physics uses.
        self.true_rot_tip_sensor: Mat3 = mat_mul(cfg.rot_tip_sensor, err)
        #: The rig's state (:func:`step_kernel`'s layout); the arm, the robot, the tissue and the sensor keep theirs
        #: in its slices from here on.
        self.state = st = np.zeros(_STATE_SIZE)
        st[_HOME:_HOME + 3], st[_ROT:_ROT + 9] = cfg.tip_home_m, rot_base_haptic
        st[_AXIS:_AXIS + 3] = self.hand_axis
        st[_SCALE], st[_SURFACE] = cfg.motion_scale, cfg.surface_z_m
        self.arm.adopt(st[_ARM:_ROBOT])
        self.robot.adopt(st[_ROBOT:_TISSUE])
        self.tissue.adopt(st[_TISSUE:_SENSOR])
        self.sensor.adopt(st[_SENSOR:_STATE_SIZE])
        self._push_base_n: Vec3 = (0.0, 0.0, 0.0)
        self._orient: Mat3 | None = None
        self._rot_sensor_base: Mat3 = IDENTITY
        self._last_ns: int | None = None
        self.sim_time_s = 0.0
        self._truth: Vec3 = (0.0, 0.0, 0.0)
        self.last_observation = HandObservation(0.0, 0.0, 0.0, 0.0, cfg.tip_home_m[2] - cfg.surface_z_m)
        #: App-side teleoperation (a :class:`pipeline.devices.teleop.TeleopDriver`); None: the robot follows the stylus
        #: directly.
        self.teleop: Any = None
        #: Fault rehearsal: faults scheduled on the rig's clock (:meth:`inject_fault`).
        self.faults = FaultInjector()
        #: The instrument's jaw (the sketch's limits, no serial port).
        self.jaw = SimJaw()
        #: Called with (now_ns, the stylus buttons) every step:
        #: :meth:`pipeline.devices.jaw_control.JawController.buttons`.
        self.on_buttons: Callable[[int, int], None] | None = None
        #: Whether a tick with nothing due on the Python side runs as one compiled call (:func:`step_kernel`); False
        #: runs every tick model by model, the path the one call is tested against (the same bits either way).
        self.one_call = True
        #: Ticks that ran as one compiled call (diagnostics).
        self.one_call_ticks = 0
        self.warm_up()

    @property
    def hand_one_axis(self) -> tuple[int, float] | None:
        """The one device axis the hand moves along and its component (the paper's frames: +y), or None."""
        return self._hand_one_axis

    @property
    def last_ns(self) -> int | None:
        """The clock reading of the last step (None before the first)."""
        return self._last_ns

    @property
    def steps_elsewhere(self) -> bool:
        """Whether the next step may run in a compiled block of ticks (:mod:`pipeline.sim.block`): it has stepped
        once, and nothing on the Python side is due in its step -- a teleoperation driver, a buttons hook, a fault
        being rehearsed, a re-orientation or a servo stop, a frozen robot or a published pose at another orientation
        than the robot's (one published before it turned while frozen), a device error."""
        robot = self.robot
        return (self._last_ns is not None and self.one_call and self.teleop is None and self.on_buttons is None
                and not self.faults.busy and robot.moves_smoothly and not robot.frozen
                and robot.orientation is self._orient and robot.read_pose().rot_base_tip == robot.orientation
                and robot.origin_ns is not None and self.sensor.origin_ns is not None and self.haptic.error_code == 0)

    def ran_block(self, ticks: int, last_ns: int, sim_time_s: float, force_n: float, obs: HandObservation,
                  y_m: float, error_code: int) -> None:
        """``ticks`` steps ran in a compiled block of ticks (:mod:`pipeline.sim.block`), the last at ``last_ns``:
        take what the last left -- the time, the contact force (N), the hand's observation, the stylus along the
        hand's axis (m), the Touch's error code (the models' states are in :attr:`state` already)."""
        self._last_ns = last_ns
        self.sim_time_s = sim_time_s
        px, py, pz = self._push_base_n
        self._truth = (px, py, force_n + pz)
        self.last_observation = obs
        self.haptic.ran_block(last_ns, self._stylus(y_m), error_code)
        self.one_call_ticks += ticks

    def _stylus(self, y: float) -> Vec3:
        """The stylus at ``y`` along the hand's axis, device frame (off-axis components exactly zero)."""
        ax, ay, az = self.hand_axis
        return (ax * y if ax else 0.0, ay * y if ay else 0.0, az * y if az else 0.0)

    @property
    def push_base_n(self) -> Vec3:
        """A force someone applies to the tip by hand, base frame, N (the frame and sign check's pushes)."""
        return self._push_base_n

    @push_base_n.setter
    def push_base_n(self, value: Vec3) -> None:
        self._push_base_n = value
        self.state[_PUSH:_PUSH + 3] = value

    def warm_up(self) -> None:
        """Compile the models' kernels (or load them from numba's cache) now, so that no tick of a running loop waits
        for it (:func:`warm_kernels`)."""
        warm_kernels(self.state, self.sensor.noise)

    def __setstate__(self, state: dict[str, Any]) -> None:
        """A copy (``copy.deepcopy``, pickle) shares its state array with its own models, as the original does."""
        self.__dict__.update(state)
        st = self.state
        self.arm.array, self.robot.array = st[_ARM:_ROBOT], st[_ROBOT:_TISSUE]
        self.tissue.array, self.sensor.array = st[_TISSUE:_SENSOR], st[_SENSOR:_STATE_SIZE]

    # -- Rig interface ------------------------------------------------------------------------
    def advance(self, now_ns: int) -> None:
        """Step the physics to ``now_ns``: Touch output, hand, robot, tissue, then the sensor.

        The hand's decision and the Touch's output are Python's; the rest is :func:`step_kernel` (one compiled call)
        unless something on the Python side is due in it this tick -- an attached teleoperation driver, a
        re-orientation or a servo stop at the robot's next cycle -- when :meth:`_advance_by_models` runs it model by
        model with the same kernels in the same order (and always with :attr:`one_call` False).
        """
        last = self._last_ns
        dt = 0.0 if last is None else (now_ns - last) * 1e-9
        if dt < 0.0:
            dt = 0.0
        elif dt > _MAX_DT_S:
            dt = _MAX_DT_S
        self._last_ns = now_ns
        self.sim_time_s += dt
        if self.faults.busy:
            self.faults.apply(self, now_ns)
        cfg = self.config
        touch = self.haptic
        touch.advance(now_ns, dt)
        # the hand's axis written out here, not called: this runs every tick of every simulated study
        ax, ay, az = self.hand_axis
        one = self._hand_one_axis
        applied = touch.applied_force_n
        felt = (applied[one[0]] * one[1] if one is not None  # one device axis: that component, exactly
                else applied[0] * ax + applied[1] * ay + applied[2] * az)

        robot = self.robot
        st = self.state
        depth = cfg.surface_z_m - st.item(_ROBOT + 2)  # (the tool's z: item() gives a Python float)
        # (tuple.__new__: the named tuple without its __new__'s Python frame, ~0.14 µs a tick)
        obs = _new_tuple(HandObservation, (self.sim_time_s, st.item(_ARM), felt, depth if depth > 0 else 0.0,
                                           -depth if depth < 0 else 0.0))
        self.last_observation = obs
        # (float(): a kernel is compiled for its arguments' types; a driver's int or a command's would compile another)
        y_c, felt = float(self.driver.equilibrium_y(obs)), float(felt)
        if self.teleop is not None or not robot.moves_smoothly or not self.one_call:
            self._advance_by_models(now_ns, dt, y_c, felt)
        else:
            sensor = self.sensor
            ni = sensor.next_noise_row()
            if robot.orientation is not self._orient:  # (no cycle re-orients the robot this tick: moves_smoothly)
                self._reorient()
            y, f, cycled, what, v0, v1, v2, v3, v4, v5 = step_kernel(
                st, sensor.noise, ni, y_c, felt, dt, robot.since_first_ns(now_ns), sensor.since_first_ns(now_ns))
            touch.stylus_m = self._stylus(y)
            if cycled:
                robot.cycled(now_ns)
            px, py, pz = self._push_base_n
            self._truth = (px, py, f + pz)
            sensor.took(what, now_ns, v0, v1, v2, v3, v4, v5)
            self.one_call_ticks += 1
        hook = self.on_buttons
        if hook is not None:  # (it reads the buttons only, which no model of the tick changes: its turn is last)
            hook(now_ns, touch.buttons)

    def _advance_by_models(self, now_ns: int, dt: float, y_c: float, felt: float) -> None:
        """:meth:`advance` after the hand's decision, model by model (the teleoperation driver, the robot's
        re-orientation or servo stop have their turns in it)."""
        cfg = self.config
        touch = self.haptic
        y = self.arm.step(y_c, felt, dt)
        touch.stylus_m = self._stylus(y)
        robot = self.robot
        if self.teleop is None:
            robot.command(target_kernel(self.state, y))
        else:
            # the app owns the robot: targets come from the teleoperation controller through servo_tcp
            self.teleop.update(now_ns)
        robot.advance(now_ns, dt)
        depth = cfg.surface_z_m - self.state.item(_ROBOT + 2)
        f = self.tissue.step(depth, dt) if dt > 0 else self.tissue.force_n
        px, py, pz = self._push_base_n
        self._truth = (px, py, f + pz)
        if robot.orientation is not self._orient:
            self._reorient()
        self.sensor.sample(now_ns, self._rot_sensor_base, self._truth, dt)

    def _reorient(self) -> None:
        """The robot's orientation changed: the sensor's true orientation in the base frame, told to the sensor."""
        orient = self.robot.orientation
        self._orient = orient
        self._rot_sensor_base = transpose(mat_mul(orient, self.true_rot_tip_sensor))
        self.sensor.set_rotation(self._rot_sensor_base)

    def true_contact_force(self) -> Vec3:
        """Contact force on the tool tip in the base frame, N (ground truth)."""
        return self._truth

    def on_faults(self, faults: int) -> None:
        """The loop's latched faults changed: an attached teleoperation driver stops the arm (see
        ``pipeline.devices.rig.Rig``)."""
        if self.teleop is not None:
            self.teleop.on_faults(faults)

    def stop_motion(self, reason: str) -> None:
        """The loop is stopping: an attached teleoperation driver stops the arm."""
        if self.teleop is not None:
            self.teleop.stop_motion(reason)

    def close(self) -> None:
        """Stop a teleoperated arm, zero the haptic device."""
        if self.teleop is not None:
            self.teleop.close()
        self.haptic.close()

    # -- scenario control ---------------------------------------------------------------------
    def attach_teleop(self, driver: Any) -> None:
        """Let a :class:`pipeline.devices.teleop.TeleopDriver` (servoing :attr:`robot`) move the arm; None detaches."""
        self.teleop = driver

    def inject_fault(self, kind: str, at_ns: int, duration_s: float | None = None) -> None:
        """Rehearse a fault (:mod:`pipeline.sim.faults`): ``kind`` from loop-clock time ``at_ns``.

        ``duration_s`` defaults to the kind's own (:data:`pipeline.sim.faults.DEFAULT_DURATION_S`).
        """
        duration = DEFAULT_DURATION_S.get(kind, 0.0) if duration_s is None else duration_s
        self.faults.schedule(SimFault(kind, int(at_ns), duration))

    def cancel_fault(self, kind: str, at_ns: int) -> bool:
        """Withdraw a rehearsed fault (its trial ended first), or end it if it has begun; True if there was one."""
        return self.faults.cancel(kind, int(at_ns), self)

    def set_driver(self, driver: StylusDriver) -> None:
        """Hand the stylus to another driver (scripted, simulated participant, mouse)."""
        self.driver = driver

    @property
    def indentation_m(self) -> float:
        """Current true tissue indentation, m."""
        d = self.config.surface_z_m - self.state.item(_ROBOT + 2)
        return d if d > 0 else 0.0


def warm_kernels(state: State | None = None, noise: State | None = None) -> None:
    """Compile the simulated rig's kernels (or load them from numba's cache), once a process, on copies of a rig's
    ``state`` and sensor ``noise`` (None: a default rig's, built for it).

    A rig's construction calls it; so does a parent that forks a process per participant, before forking
    (:func:`study_app.headless.pool.run_parallel`): its children then inherit the machine code instead of each
    loading it from the cache (~0.2 s of a core a participant).
    """
    if state is None or noise is None:
        if not is_warm(__name__):
            SimRig()  # (its construction comes back here with its own state: a zero state would divide by zero)
        return

    def compile_them() -> None:
        st, scratch = state.copy(), np.zeros_like(noise)
        step_kernel(st, scratch, 0, 0.0, 0.0, 0.001, 1, 1)
        # and each on its own, as the models' methods call them (a tick with Python's turns in it)
        sim_hand.step_kernel(st[_ARM:_ROBOT], 0.0, 0.0, 0.001)
        sim_robot.command_kernel(st[_ROBOT:_TISSUE], 0.0, 0.0, 0.0)
        target_kernel(st, 0.0)
        sim_robot.advance_kernel(st[_ROBOT:_TISSUE], 2, 0.001)
        sim_tissue.step_kernel(st[_TISSUE:_SENSOR], 0.0, 0.001)
        sim_sensor.sample_kernel(st[_SENSOR:_STATE_SIZE], scratch, 0, 2, 0.0, 0.0, 0.0, 0.001)

    warm_once(__name__, compile_them)
