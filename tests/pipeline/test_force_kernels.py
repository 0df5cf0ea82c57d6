"""Algorithm 1's compiled kernels give the bits of the Python they are compiled from, and are compiled before a loop
ticks.

Each stage's kernel (the moving average, the scaling law, the safety stage, the norm clamp) and the whole tick
(:func:`pipeline.force.framework.step_kernel`) run compiled and as their ``py_func`` from the same state and inputs,
at the extremes (zero of either sign, subnormals, huge values, infinities, NaN): the same outputs and the same state,
bit for bit.  With ``tests/pipeline/test_exact.py`` (the norm and the exact sum are CPython's) and
``tests/pipeline/test_framework.py`` (the tick is the stages composed) this holds the compiled tick to the
interpreted product's arithmetic; ``scripts/same_study.py`` showed a seeded study's tables identical across the
change.
"""

from __future__ import annotations

import copy
import math
import pickle

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from kernel_checks import bits, compiled_on_construction, same

from pipeline.force import bias_refinement, filters, frames, safety, scaling
from pipeline.force.bias_refinement import RlsBias
from pipeline.force.framework import FrameworkConfig, HapticFramework, refine_kernel, step_kernel
from pipeline.force.safety import SafetyConfig, SafetyGovernor

ANY = st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True)
FORCE = st.one_of(st.floats(-50.0, 50.0), ANY)  # mostly forces, the extremes among them
DT = st.one_of(st.just(0.001), st.floats(0.0, 0.2), st.floats(-1.0, 0.0), st.just(math.nan))


@settings(max_examples=300)
@given(window=st.integers(1, 6), fill=st.lists(st.tuples(FORCE, FORCE, FORCE), max_size=14), x=FORCE, y=FORCE,
       z=FORCE)
def test_moving_average(window: int, fill: list[tuple[float, float, float]], x: float, y: float, z: float) -> None:
    ma = filters.MovingAverage3(window)
    for s in fill:  # any state a run can reach: rejected samples, partial and full windows, overflowed sums
        ma.update(*s)
    same(filters.ma3_update, ma.array, x, y, z)
    same(filters.ma3_mean, ma.array)


@settings(max_examples=300)
@given(gain=st.sampled_from([0.0, 0.3, 1.0]), s=st.tuples(*[st.floats(-2.0, 2.0)] * 3), f=st.tuples(ANY, ANY, ANY),
       enabled=st.booleans(), dt=DT, peak=st.sampled_from([3.3, 2.0, 0.5]))
def test_safety_step(gain: float, s: tuple[float, float, float], f: tuple[float, float, float], enabled: bool,
                     dt: float, peak: float) -> None:
    g = SafetyGovernor(SafetyConfig(), peak)
    g.load_state({"gain": gain, "sx": s[0], "sy": s[1], "sz": s[2]})  # (a command the last tick left)
    same(safety.safety_step, g.array, *f, enabled, dt)


@settings(max_examples=500)
@given(f=st.tuples(ANY, ANY, ANY), f_max=st.sampled_from([3.0, 1e-6, 1e6]), f_scale=st.sampled_from([7.0, 1e-6, 1e6]))
def test_scaling_and_clamp(f: tuple[float, float, float], f_max: float, f_scale: float) -> None:
    with np.errstate(all="ignore"):
        assert bits(scaling.scale_kernel(*f, f_max, f_scale)) == bits(scaling.scale_kernel.py_func(*f, f_max, f_scale))
        if all(v - v == 0.0 for v in f):  # (the clamp is asked of finite vectors only)
            assert bits(scaling.clamp3(*f, f_max)) == bits(scaling.clamp3.py_func(*f, f_max))


@settings(max_examples=200, deadline=None)
@given(window=st.integers(1, 12), fill=st.lists(st.tuples(FORCE, FORCE, FORCE, st.booleans(), DT), max_size=30),
       f=st.tuples(FORCE, FORCE, FORCE), enabled=st.booleans(), dt=DT,
       rv=st.tuples(*[st.floats(-3.0, 3.0)] * 3), command=st.one_of(st.none(), FORCE))
def test_the_tick(window: int, fill: list[tuple[float, float, float, bool, float]], f: tuple[float, float, float],
                  enabled: bool, dt: float, rv: tuple[float, float, float], command: float | None) -> None:
    fw = HapticFramework(FrameworkConfig(filter_window=window), device_peak_n=3.3)
    fw.set_pose(frames.rotvec_to_matrix(*rv))
    for fx, fy, fz, on, d in fill:
        fw.step(fx, fy, fz, on, d)
    same(step_kernel, fw.array, *f, 0.0 if command is None else command, command is not None, enabled, dt)


def test_the_kernels_are_compiled_when_a_framework_is_built() -> None:
    """A framework is built with Algorithm 1's kernels compiled or loaded: the loop's first tick waits for no compiler
    (in a fresh process: this one's may have compiled them already)."""
    compiled_on_construction(
        "from pipeline.core import exact\nfrom pipeline.force import filters, frames, safety, scaling\n"
        "from pipeline.force.framework import FrameworkConfig, HapticFramework, step_kernel",
        "(step_kernel, filters.ma3_update, filters.ma3_mean, safety.safety_step, scaling.scale_kernel, scaling.clamp3,"
        " exact.hypot3, exact.fsum)",
        "HapticFramework(FrameworkConfig(), device_peak_n=3.3)")


def test_a_copy_of_a_framework_shares_its_own_state() -> None:
    """A framework's copy (deepcopy, pickle) keeps its filter's and safety stage's states in its own array: its reset
    and its derated clamp reach the state its tick reads."""
    fw = HapticFramework(FrameworkConfig(), device_peak_n=3.3)
    fw.step(5.0, 0.0, 0.0, True, 0.001)
    for c in (copy.deepcopy(fw), pickle.loads(pickle.dumps(fw))):
        assert np.shares_memory(c.array, c.safety.array) and np.shares_memory(c.array, c.filter.array)
        assert not np.shares_memory(c.array, fw.array)
        for _ in range(600):  # fully ramped in
            c.step(5.0, 0.0, 0.0, True, 0.001)
        c.set_device_limit(1.0)
        assert abs(c.step(5.0, 0.0, 0.0, True, 0.001)[-3]) <= 1.0  # the derated clamp reaches the tick
        c.reset()
        assert c.step(5.0, 0.0, 0.0, False, 0.001)[-3:] == (0.0, 0.0, 0.0)


def test_no_kernel_closes_over_another() -> None:
    """numba keys its on-disk cache on a kernel's closure pickled, and a kernel pickles differently in every process:
    a kernel that held another in its closure would be compiled anew by every process (found in review: two kernels
    were, each run adding a cache file).  Each closes over plain values only (its callees' fingerprint)."""
    import pipeline.sim.rig  # noqa: F401  (its kernels too)
    from pipeline.core.compiled import kernels

    ks = kernels()
    assert len(ks) >= 15
    for k in ks:
        cells = [c.cell_contents for c in (k.py_func.__closure__ or ())]
        assert all(isinstance(v, (int, float, str)) for v in cells), (k.py_func.__qualname__, cells)


@settings(max_examples=300)
@given(theta=st.tuples(*[st.floats(-2.0, 2.0)] * 6), p=st.floats(1e-6, 1.0), w=st.tuples(*[ANY] * 6),
       pose=st.tuples(*[st.floats(-3.0, 3.0)] * 3))
def test_the_bias_refinement(theta: tuple[float, ...], p: float, w: tuple[float, ...],
                             pose: tuple[float, float, float]) -> None:
    """The online bias estimator's update and the framework's refinement step around it, compiled and interpreted."""
    rls = RlsBias(theta[:3], theta[3:])
    rls.array[bias_refinement.COVARIANCE] = p
    same(bias_refinement.rls_update, rls.array, *w)
    fw = HapticFramework(FrameworkConfig(), device_peak_n=3.3, rls=rls)
    fw.set_pose(frames.rotvec_to_matrix(*pose))
    a, b = fw.array.copy(), fw.array.copy()
    ra, rb = rls.array.copy(), rls.array.copy()
    with np.errstate(all="ignore"):
        got_c = refine_kernel(a, ra, *w)
        got_i = refine_kernel.py_func(b, rb, *w)
    assert got_c == got_i and bits(a) == bits(b) and bits(ra) == bits(rb)
