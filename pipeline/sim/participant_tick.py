"""The simulated participant's tick between its events, compiled: its per-tick state and the kernels over it.

:class:`pipeline.sim.participant.SimulatedParticipant` keeps the state a tick reads and changes in one float64 array
(the layout below; its attributes are backed by it), its observation history in another (one row per quantity) and
the normals its postural drift draws in a third; between its events (a decision, a look, the start of an approach:
Python's) a tick is two compiled calls -- :func:`remember_kernel` (the observation into the history) and
:func:`plan_kernel` (the equilibrium: the plan, its drift, its clamp) -- which a caller running ticks in a block
(:mod:`pipeline.sim.block`) calls too.
"""

from __future__ import annotations

import math
from typing import Any, cast

import numpy as np

from pipeline.core.compiled import State, fingerprint, kernel, warm_once
from pipeline.sim import hand
from pipeline.sim.hand import min_jerk
from pipeline.sim.percepts import HISTORY_TICKS, newest_at

__all__ = ["DRIFT_KNOT_S", "NEXT_AT", "STATE_SIZE", "T_AT", "TickState", "normals_short", "plan_kernel",
           "remember_kernel", "warm_kernels"]

#: Postural drift: a random walk sampled every 20 ms, linearly interpolated.
DRIFT_KNOT_S = 0.02
_DRIFT_KNOT_S = DRIFT_KNOT_S
_HIST = HISTORY_TICKS  # observation history (ticks); covers the longest percept delay
_MASK = _HIST - 1

# The participant's per-tick state, a float64 array (its kernels' layout): the newest observation's time (NaN before
# the first) and its place in the history, the commanded minimum-jerk segment (y0 → y1 over [t0, t0 + dur], its end),
# the postural drift (on, its knots' times and values, its step), the last output, the next event's time, the normals
# drawn (the next one's index, how many), the cue's time.
_T, _HI, _P_T0, _P_DUR, _P_Y0, _P_Y1, _P_END, _DRIFT_ON, _D_T0, _D_T1, _D0, _D1, _D_STEP, _OUT, _NEXT = range(15)
_ZI, _NZ, _CUE_T = 15, 16, 17
STATE_SIZE = 18
#: Where the state holds the next event's time and the newest observation's time (what a caller running ticks in a
#: block checks before each).
NEXT_AT, T_AT = _NEXT, _T
#: The history's rows: times, stylus positions, felt forces, indentations, gaps.
_HT, _HY, _HF, _HD, _HG = range(5)


@kernel
def remember_kernel(ps: State, hist: State, t: float, y_st: float, felt: float, ind: float, gap: float) -> None:
    """Keep this tick's observation (at the participant's time ``t``) in the history's next slot."""
    i = (int(ps[_HI]) + 1) & _MASK
    ps[_HI] = i
    hist[_HT, i] = t
    hist[_HY, i] = y_st
    hist[_HF, i] = felt
    hist[_HD, i] = ind
    hist[_HG, i] = gap


@kernel
def normals_short(ps: State, t: float) -> bool:
    """Whether the drift's knots due at ``t`` need more normals than are drawn (:func:`plan_kernel` would ask for
    more): a caller running ticks in a block checks it before a tick."""
    if ps[_DRIFT_ON] == 0.0 or t < ps[_D_T1]:
        return False
    tk = ps[_D_T1]
    if t - tk > 1.0:  # (plan_kernel's re-anchoring)
        tk = t
    knots = 0
    while t >= tk:
        knots += 1
        tk = tk + _DRIFT_KNOT_S
    return bool(ps[_ZI] + knots > ps[_NZ])


def _compile_plan(callees: int) -> Any:
    """:func:`plan_kernel` closed over the :func:`pipeline.core.compiled.fingerprint` of the module it calls."""

    @kernel
    def plan_kernel(ps: State, z: State, t: float) -> float:
        """The equilibrium at ``t``: the current plan plus the postural drift (its knots drawn from ``z`` as due),
        clamped to :data:`SAFE_Y_RANGE_M`; NaN, and nothing changed, when the knots due need more normals than
        ``z`` has left (the caller draws more and asks again)."""
        _ = callees  # (read, so that it is in the closure numba's cache is keyed on)
        y = ps[_P_Y1] if t >= ps[_P_END] else hand.min_jerk(t, ps[_P_T0], ps[_P_DUR], ps[_P_Y0], ps[_P_Y1])
        if ps[_DRIFT_ON] != 0.0:
            if t >= ps[_D_T1]:
                if normals_short(ps, t):
                    return math.nan
                d_t1 = ps[_D_T1]
                if t - d_t1 > 1.0:  # cannot happen at 1 kHz; re-anchor instead of looping
                    d_t1 = t
                zi = int(ps[_ZI])
                ps[_D_T1] = d_t1
                while t >= ps[_D_T1]:
                    ps[_D_T0] = ps[_D_T1]
                    ps[_D0] = ps[_D1]
                    ps[_D1] = ps[_D0] + ps[_D_STEP] * z[zi]
                    zi += 1
                    ps[_D_T1] = ps[_D_T0] + _DRIFT_KNOT_S
                ps[_ZI] = zi
            y += ps[_D0] + (ps[_D1] - ps[_D0]) * (t - ps[_D_T0]) * (1.0 / _DRIFT_KNOT_S)
        if y < -0.030:
            y = -0.030
        elif y > 0.005:
            y = 0.005
        elif y != y:  # pragma: no cover - the plan is built from finite values only
            y = ps[_OUT]
        ps[_OUT] = y
        return y

    return plan_kernel


#: The participant's equilibrium between its events (:meth:`SimulatedParticipant.equilibrium_y`), compiled.
plan_kernel = _compile_plan(fingerprint(hand))


class _Slot:
    """An attribute of :class:`TickState` kept in its state array (:data:`STATE_SIZE`'s layout), a float."""

    __slots__ = ("index",)

    def __init__(self, index: int) -> None:
        self.index = index

    def __get__(self, obj: Any, owner: Any = None) -> float:
        return obj.array.item(self.index)  # type: ignore[no-any-return]  # (a float64 array's item: a float)

    def __set__(self, obj: Any, value: float) -> None:
        obj.array[self.index] = value


class _IntSlot(_Slot):
    """An attribute kept in the state array, an int."""

    def __get__(self, obj: Any, owner: Any = None) -> int:
        return int(obj.array.item(self.index))


class _BoolSlot(_Slot):
    """An attribute kept in the state array, a bool."""

    def __get__(self, obj: Any, owner: Any = None) -> bool:
        return obj.array.item(self.index) != 0.0  # type: ignore[no-any-return]  # (a float's comparison)


class TickState:
    """The participant's per-tick state (the module's layout) as attributes: its array, its history, its normals.

    The base of :class:`pipeline.sim.participant.SimulatedParticipant`, whose Python (its events) reads and changes
    these attributes while its kernels read and change the arrays behind them.
    """

    array: State
    history: State
    _z: State

    _t = _Slot(_T)  # the newest observation's time (NaN before the first)
    _hi = _IntSlot(_HI)
    _p_t0 = _Slot(_P_T0)  # the commanded minimum-jerk segment: y0 -> y1 over [t0, t0 + dur], its end
    _p_dur = _Slot(_P_DUR)
    _p_y0 = _Slot(_P_Y0)
    _p_y1 = _Slot(_P_Y1)
    _p_end = _Slot(_P_END)
    _drift_on = _BoolSlot(_DRIFT_ON)  # the postural drift: on, its knots' times and values, its step
    _d_t0 = _Slot(_D_T0)
    _d_t1 = _Slot(_D_T1)
    _d0 = _Slot(_D0)
    _d1 = _Slot(_D1)
    _d_step = _Slot(_D_STEP)
    _out = _Slot(_OUT)  # the last equilibrium returned
    _next = _Slot(_NEXT)  # the next event's time
    _zi = _IntSlot(_ZI)  # the next normal's index, and how many are drawn
    _nz = _IntSlot(_NZ)
    _cue_t = _Slot(_CUE_T)

    def init_tick_state(self) -> None:
        """Empty state: no observation, no history (times -inf), no normals drawn."""
        self.array = np.zeros(STATE_SIZE)
        self.history = np.zeros((5, _HIST))
        self.history[_HT] = -math.inf
        self._z = np.zeros(0)

    @property
    def normals(self) -> State:
        """The normals drawn for the current trial's stream (:func:`plan_kernel` reads them)."""
        return self._z

    # -- the history's rows (what a decision looks back at) ------------------------------------
    @property
    def _ht(self) -> State:
        return cast(State, self.history[_HT])

    @property
    def _hy(self) -> State:
        return cast(State, self.history[_HY])

    @property
    def _hf(self) -> State:
        return cast(State, self.history[_HF])

    @property
    def _hd(self) -> State:
        return cast(State, self.history[_HD])

    @property
    def _hg(self) -> State:
        return cast(State, self.history[_HG])


def warm_kernels() -> None:
    """Compile the participant's tick kernels (or load them from numba's cache) on a scratch state, as its methods call
    them, once a process: when the first participant is built or unpickled, or a simulated engine is built (the
    loop's own process, where a participant arrives by pickle while the loop runs), so that no tick waits for a
    compiler."""
    warm_once(__name__, _compile_them)


def _compile_them() -> None:
    ps, hist = np.zeros(STATE_SIZE), np.zeros((5, _HIST))
    remember_kernel(ps, hist, 0.0, 0.0, 0.0, 0.0, 0.0)
    plan_kernel(ps, np.zeros(1), 0.0)
    normals_short(ps, 0.0)
    newest_at(hist[_HT], 0, 0.0, 0.0)
    min_jerk(0.5, 0.0, 1.0, 0.0, 1.0)
