"""Simulated ATI Gamma SI-130-10 on a Net F/T box (science.md §1.5, §2).

It reports, in its own frame S, what the real one would: the tool's weight at
the current orientation, the contact force transmitted from the tip (with its
lever-arm torque), a bias that drifts (warm-up exponential + random walk),
white noise, quantisation to counts, saturation at the calibrated ranges and,
optionally, lost UDP packets.  Records carry the RDT fields (``rdt_sequence``,
``ft_sequence``, ``status``) so the same health checks run on the simulation
and on hardware.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from pipeline.core.compiled import KernelState, State, kernel
from pipeline.devices.interfaces import WrenchSample
from pipeline.force.frames import Mat3, Vec3, cross, mat_vec

__all__ = ["GAMMA_RANGE", "SATURATION_STATUS", "SensorParams", "SimForceSensor"]

#: 1.5·2⁵²: added to and taken from a double under 2⁵¹ in magnitude, rounds it to an integer, halves to even.
_ROUND = 6755399441055744.0
#: SI-130-10 full scale: Fx, Fy ±130 N; Fz ±400 N; Tx, Ty, Tz ±10 N·m.
GAMMA_RANGE: tuple[float, float, float, float, float, float] = (130.0, 130.0, 400.0, 10.0, 10.0, 10.0)
#: Status word the simulated box reports while a gauge is saturated (non-zero = serious).
SATURATION_STATUS = 0x80020000
_G = 9.80665
#: A named tuple made from its values without its ``__new__``'s Python frame (~0.14 µs a record).
_new_tuple = tuple.__new__


@dataclass(frozen=True, slots=True)
class SensorParams:
    """Physical truth of the simulated sensor and payload (what calibration must recover).

    Attributes
    ----------
    mass_kg, com_m
        Instrument mass distal to the sensor and its centre of mass in S.
    tip_in_sensor_m
        Position of the instrument tip in S (lever arm of the contact force).
    bias_force_n, bias_torque_nm
        Initial offsets.
    drift_force_n, drift_tau_s
        Warm-up drift amplitude per force axis and its time constant (torque
        drift is scaled by 0.01 m).
    random_walk_n_per_sqrt_s
        Random-walk intensity of the bias, N/√s (0.01 N/√min ≈ 1.3e-3 N/√s,
        the low end of science.md §1.5).
    noise_force_n, noise_torque_nm
        White-noise standard deviation per channel.
    counts_per_force, counts_per_torque
        Quantisation (Net F/T cpf/cpt).
    packet_loss
        Probability a 1 kHz sample is lost (the previous one stays newest).
    """

    mass_kg: float = 0.65
    com_m: Vec3 = (0.003, -0.002, 0.110)
    tip_in_sensor_m: Vec3 = (0.0, 0.0, 0.35)
    bias_force_n: Vec3 = (0.8, -0.5, 1.2)
    bias_torque_nm: Vec3 = (0.03, -0.02, 0.01)
    drift_force_n: Vec3 = (0.12, -0.08, 0.15)
    drift_tau_s: float = 900.0
    random_walk_n_per_sqrt_s: float = 1.3e-3
    noise_force_n: Vec3 = (0.02, 0.02, 0.035)
    noise_torque_nm: Vec3 = (0.0008, 0.0008, 0.0008)
    counts_per_force: float = 1_000_000.0
    counts_per_torque: float = 1_000_000.0
    range_n: tuple[float, float, float, float, float, float] = GAMMA_RANGE
    packet_loss: float = 0.0


# The sensor's state, a float64 array (its kernel's layout): the random walk, the payload's weight in S at the current
# orientation, that orientation (row-major), the constants, the first sample's time (ns since the first sample: 0;
# NaN before it), the fault switches, the newest record's six values, the box's RDT and F/T sequence counters, the
# packets lost, the status word a fault rehearsal sets, and the newest record's status word and counters.
_RW, _GRAV, _ROT, _BIAS0, _DRIFT, _RANGE, _LEVER = 0, 6, 12, 21, 27, 33, 39
_CPF, _CPT, _TAU, _RW_SCALE, _LOSS, _T0, _STALLED, _NAN = 42, 43, 44, 45, 46, 47, 48, 49
_OUT = 50
_RDT, _FT, _LOST, _OVERRIDE, _STATUS, _PUB_RDT, _PUB_FT = 56, 57, 58, 59, 60, 61, 62
STATE_SIZE = 63
#: Where the state holds the newest record's status word.
STATUS_AT = _STATUS
#: Where the newest record's six values are in the state.
OUT = _OUT
#: What :func:`sample_kernel` did: no record (a stalled box), a lost packet, a record, a saturated record.
STALLED, LOST, RECORD, SATURATED = 0, 1, 2, 3


@kernel
def sample_kernel(st: State, noise: State, ni: int, t_ns: int, c0: float, c1: float, c2: float,
                  dt_s: float) -> int:
    """This tick's record at ``t_ns`` (ns since the first sample: :meth:`SimForceSensor.since_first_ns`) from the
    contact force ``(c0, c1, c2)`` (base frame, N) and noise row ``ni``, into ``st``.

    The orientation and the weight in ``st`` are the current ones (:meth:`SimForceSensor.set_rotation`).  Returns
    :data:`STALLED`, :data:`LOST`, :data:`RECORD` or :data:`SATURATED`; the record's six values are ``st[_OUT:]``,
    its status word and the box's counters then ``st[_STATUS:]`` (what :meth:`SimForceSensor.took` publishes).
    """
    if st[_T0] != st[_T0]:  # (NaN: the first sample)
        st[_T0] = t_ns
    scale = st[_RW_SCALE]
    if dt_s > 0.0 and scale > 0.0:
        s = scale * math.sqrt(dt_s)
        s_t = 0.01 * s
        st[0] = st[0] + s * noise[ni, 6]
        st[1] = st[1] + s * noise[ni, 7]
        st[2] = st[2] + s * noise[ni, 8]
        st[3] = st[3] + s_t * noise[ni, 9]
        st[4] = st[4] + s_t * noise[ni, 10]
        st[5] = st[5] + s_t * noise[ni, 11]
    if st[_STALLED] != 0.0:
        return STALLED
    st[_RDT] += 1.0
    st[_FT] += 1.0
    if noise[ni, 12] < st[_LOSS]:
        st[_LOST] += 1.0
        return LOST  # the box sampled and sent it; the network ate it
    r = _ROT
    f0 = st[r] * c0 + st[r + 1] * c1 + st[r + 2] * c2
    f1 = st[r + 3] * c0 + st[r + 4] * c1 + st[r + 5] * c2
    f2 = st[r + 6] * c0 + st[r + 7] * c1 + st[r + 8] * c2
    lx, ly, lz = st[_LEVER], st[_LEVER + 1], st[_LEVER + 2]
    w = 1.0 - math.exp((st[_T0] - t_ns) * 1e-9 / st[_TAU])
    b, d = _BIAS0, _DRIFT
    v0 = st[_GRAV] + f0 + (st[b] + st[d] * w + st[0]) + noise[ni, 0]
    v1 = st[_GRAV + 1] + f1 + (st[b + 1] + st[d + 1] * w + st[1]) + noise[ni, 1]
    v2 = st[_GRAV + 2] + f2 + (st[b + 2] + st[d + 2] * w + st[2]) + noise[ni, 2]
    v3 = st[_GRAV + 3] + (ly * f2 - lz * f1) + (st[b + 3] + st[d + 3] * w + st[3]) + noise[ni, 3]
    v4 = st[_GRAV + 4] + (lz * f0 - lx * f2) + (st[b + 4] + st[d + 4] * w + st[4]) + noise[ni, 4]
    v5 = st[_GRAV + 5] + (lx * f1 - ly * f0) + (st[b + 5] + st[d + 5] * w + st[5]) + noise[ni, 5]
    out = RECORD
    st[_OUT] = v0
    st[_OUT + 1] = v1
    st[_OUT + 2] = v2
    st[_OUT + 3] = v3
    st[_OUT + 4] = v4
    st[_OUT + 5] = v5
    for i in range(6):
        v, ri = st[_OUT + i], st[_RANGE + i]
        if not (-ri <= v <= ri):
            # saturated gauges read full scale and the box flags it (max(-ri, min(ri, v)) as Python's min and max
            # pick: a NaN reads +ri)
            out = SATURATED
            m = v if v < ri else ri
            st[_OUT + i] = m if m > -ri else -ri
    # integer counts on the wire: x + 1.5·2⁵² − 1.5·2⁵² is round(x) (halves to even) for |x| < 2⁵¹, which the clamp
    # to the range above and the counts' check in __init__ guarantee; an integral double's quotient is the count's
    for i in range(6):
        per = st[_CPF] if i < 3 else st[_CPT]
        st[_OUT + i] = (st[_OUT + i] * per + _ROUND - _ROUND) / per
    if st[_NAN] != 0.0:
        st[_OUT] = math.nan
    st[_STATUS] = int(st[_OVERRIDE]) | (SATURATION_STATUS if out == SATURATED else 0)
    st[_PUB_RDT] = st[_RDT]
    st[_PUB_FT] = st[_FT]
    return out


class SimForceSensor(KernelState):
    """A ``ForceSensor`` whose readings come from the simulated world.

    The rig calls :meth:`sample` once per tick with the true sensor
    orientation and the contact force; the loop reads the newest record with
    :meth:`read_wrench`.  ``stalled``, ``status_override`` and
    ``inject_nan`` are fault-injection switches for watchdog tests.

    The arithmetic of a sample is :func:`sample_kernel`'s, compiled, over the state array :attr:`array` (the rig's
    compiled step runs the same kernel on the same array).
    """

    #: Noise rows drawn per NumPy call.  The stream is the same for any block
    #: size (consecutive draws of one generator); 64 rows cost ~11 µs at once
    #: (the draws; the rows stay an array the kernel reads), a short pause in one
    #: tick of a real-time run, and a larger block costs the same per row.
    _BLOCK = 64

    def __init__(self, params: SensorParams | None = None, seed: int = 0) -> None:
        self._params = params or SensorParams()
        r, cpf, cpt = self._params.range_n, self._params.counts_per_force, self._params.counts_per_torque
        if not (max(r[:3]) * cpf < 2.0**51 and max(r[3:]) * cpt < 2.0**51):  # (sample's rounding holds below it)
            raise ValueError(f"counts_per_force = {cpf!r}, counts_per_torque = {cpt!r} with range_n = {r!r}: a "
                             "full-scale reading must be under 2**51 counts")
        self._rng = np.random.default_rng(seed)
        #: The clock reading of the first sample: the state counts time from it (None before it).
        self.origin_ns: int | None = None
        p = self._params
        self._sig = np.array([*p.noise_force_n, *p.noise_torque_nm, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0])
        #: The current block of noise rows (6 white-noise channels, 6 random-walk steps, 1 packet-loss draw).
        self.noise = np.zeros((self._BLOCK, 13))
        self._ni = self._BLOCK
        #: Rows drawn at the next refill (:attr:`_BLOCK`; a simulated study's compiled blocks of ticks draw more at
        #: once, :mod:`pipeline.sim.block`: the same stream).
        self.rows_per_draw = self._BLOCK
        self._latest = WrenchSample(0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 0, 0)
        self._bias0 = (*p.bias_force_n, *p.bias_torque_nm)
        self._drift = (*p.drift_force_n, *(0.01 * d for d in p.drift_force_n))
        #: The state :func:`sample_kernel` works on (the rig may move it into
        #: its own array: :meth:`~pipeline.core.compiled.KernelState.adopt`).
        self.array = st = np.zeros(STATE_SIZE)
        st[_BIAS0:_BIAS0 + 6], st[_DRIFT:_DRIFT + 6], st[_RANGE:_RANGE + 6] = self._bias0, self._drift, p.range_n
        st[_LEVER:_LEVER + 3] = p.tip_in_sensor_m
        st[_CPF], st[_CPT], st[_TAU], st[_RW_SCALE] = cpf, cpt, p.drift_tau_s, p.random_walk_n_per_sqrt_s
        st[_LOSS], st[_T0] = _normal_quantile(p.packet_loss), math.nan
        self._grav_rot: Mat3 | None = None

    @property
    def params(self) -> SensorParams:
        """The sensor's physical truth (read-only: it is in :attr:`array`)."""
        return self._params

    @property
    def lost_packets(self) -> int:
        """Samples the network lost (the previous one stayed newest)."""
        return int(self.array[_LOST])

    @property
    def status_override(self) -> int:
        """Fault switch: the status word the box reports (0: none; non-zero is serious)."""
        return int(self.array[_OVERRIDE])

    @status_override.setter
    def status_override(self, word: int) -> None:
        self.array[_OVERRIDE] = int(word)

    @property
    def stalled(self) -> bool:
        """Fault switch: the box stops sending (the random walk goes on)."""
        return bool(self.array[_STALLED])

    @stalled.setter
    def stalled(self, on: bool) -> None:
        self.array[_STALLED] = 1.0 if on else 0.0

    @property
    def inject_nan(self) -> bool:
        """Fault switch: Fx reads NaN."""
        return bool(self.array[_NAN])

    @inject_nan.setter
    def inject_nan(self, on: bool) -> None:
        self.array[_NAN] = 1.0 if on else 0.0

    @property
    def range_n(self) -> tuple[float, float, float, float, float, float]:
        """Full-scale range per channel."""
        return self.params.range_n

    @property
    def counts_per_unit(self) -> tuple[float, float]:
        """Counts per N and per N·m: every reading is an integer count divided by these, as on the wire."""
        return (self.params.counts_per_force, self.params.counts_per_torque)

    def next_noise_row(self) -> int:
        """The row of :attr:`noise` this tick's sample takes (a new block of :attr:`rows_per_draw` rows drawn when one
        is used up)."""
        ni = self._ni
        if ni >= len(self.noise):
            self.refill_noise()
            ni = 0
        self._ni = ni + 1
        return ni

    def refill_noise(self) -> None:
        """Draw the next block of :attr:`noise` rows (the next sample takes its first)."""
        n = self.rows_per_draw
        if len(self.noise) != n:
            self.noise = np.zeros((n, 13))
        np.multiply(self._rng.standard_normal((n, 13)), self._sig, out=self.noise)
        self._ni = 0

    @property
    def noise_row(self) -> int:
        """The row of :attr:`noise` the next sample takes (its length: a new block is due)."""
        return self._ni

    def ran_block(self, noise_row: int, published_ns: int | None) -> None:
        """Samples were taken in a compiled block of ticks (:mod:`pipeline.sim.block`) over its state: the next noise
        row, and the newest record published at ``published_ns`` (None: none in the block)."""
        self._ni = noise_row
        if published_ns is not None:
            v = self.array[_OUT:_OUT + 6].tolist()
            self.took(RECORD, published_ns, v[0], v[1], v[2], v[3], v[4], v[5])

    def bias_at(self, t_s: float) -> tuple[float, ...]:
        """Deterministic part of the bias at ``t_s`` (without the random walk), N and N·m.

        ``b(t) = b0 + b_w (1 − e^{−t/τ_w})``; the torque drift is the force
        drift scaled by 0.01 m (science.md §1.5).
        """
        w = 1.0 - math.exp(-t_s / self.params.drift_tau_s)
        return tuple(b + d * w for b, d in zip(self._bias0, self._drift, strict=True))

    def current_bias(self, t_s: float) -> tuple[float, ...]:
        """Full bias at ``t_s`` including the random walk so far (ground truth for tests)."""
        b = self.bias_at(t_s)
        rw = self.array[_RW:_RW + 6].tolist()
        return tuple(b[i] + rw[i] for i in range(6))

    def set_rotation(self, rot_sensor_base: Mat3) -> None:
        """The sensor's orientation in the base frame changed: the rotation and the payload's weight in S."""
        if rot_sensor_base is self._grav_rot:
            return
        # the payload's weight only changes with the orientation
        g_s = mat_vec(rot_sensor_base, (0.0, 0.0, -_G * self.params.mass_kg))
        st = self.array
        st[_GRAV:_GRAV + 6] = (*g_s, *cross(self.params.com_m, g_s))
        st[_ROT:_ROT + 9] = rot_sensor_base
        self._grav_rot = rot_sensor_base

    def since_first_ns(self, t_ns: int) -> int:
        """``t_ns`` as the state counts it: ns since the first sample (the first call's reading)."""
        if self.origin_ns is None:
            self.origin_ns = t_ns
        return t_ns - self.origin_ns

    def sample(self, t_ns: int, rot_sensor_base: Mat3, contact_force_base: Vec3, dt_s: float) -> None:
        """Produce this tick's record from the true orientation and contact force (:func:`sample_kernel`)."""
        ni = self.next_noise_row()
        self.set_rotation(rot_sensor_base)
        c0, c1, c2 = contact_force_base
        t_ns = int(t_ns)
        what = sample_kernel(self.array, self.noise, ni, self.since_first_ns(t_ns), float(c0), float(c1), float(c2),
                             float(dt_s))
        self.took(what, t_ns, *self.array[_OUT:_OUT + 6].tolist())

    def took(self, what: int, t_ns: int, v0: float, v1: float, v2: float, v3: float, v4: float, v5: float) -> None:
        """Publish what :func:`sample_kernel` did at ``t_ns`` (the record's values ``v0`` ... ``v5``; its status and
        the box's counters are in the state): a record is the newest sample from now on."""
        if what < RECORD:  # (STALLED, LOST: nothing new to read)
            return
        st = self.array
        self._latest = _new_tuple(WrenchSample, (t_ns, v0, v1, v2, v3, v4, v5, int(st.item(_STATUS)),
                                                 int(st.item(_PUB_RDT)), int(st.item(_PUB_FT))))

    def read_wrench(self) -> WrenchSample:
        """Newest record (never blocks)."""
        return self._latest

    def close(self) -> None:
        """Nothing to release."""


def _normal_quantile(p: float) -> float:
    """Φ⁻¹(p): lose a packet when a standard-normal draw falls below it (probability p)."""
    return NormalDist().inv_cdf(p) if 0.0 < p < 1.0 else (-math.inf if p <= 0 else math.inf)

