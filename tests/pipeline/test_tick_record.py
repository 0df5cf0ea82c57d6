"""The one tick record: its layout, the ring's typed rows, and the loop's records with their integers as ints."""

from __future__ import annotations

import ast
import math
import struct
from pathlib import Path

import numpy as np
import pytest

from pipeline.assembly.engine import EngineConfig, build_sim_engine
from pipeline.core import record_writer
from pipeline.core.tick_record import KEPT_DTYPE, KEPT_FIELDS, TICK_DTYPE, TICK_FIELDS
from pipeline.force.framework import STEP_FIELDS
from pipeline.runtime import arm_channel
from pipeline.runtime.loop_messages import RECORD_FIELDS, Mark
from pipeline.runtime.ring import RingBuffer

#: What is an integer in a record (the rest are measurements: float64).
INTEGERS = {"tick", "t_ns", "period_ns", "sensor_age_ns", "pose_age_ns", "latency_ns", "faults", "haptic_on",
            "trial_index", "phase"}


def test_the_layout_is_defined_once_and_derived_everywhere() -> None:
    assert RECORD_FIELDS == TICK_DTYPE.names == tuple(f.name for f in TICK_FIELDS)
    assert set(STEP_FIELDS) <= set(RECORD_FIELDS) and len(STEP_FIELDS) == 21
    assert {n for n in RECORD_FIELDS if TICK_DTYPE[n] == np.int64} == INTEGERS
    assert all(TICK_DTYPE[n] == np.float64 for n in RECORD_FIELDS if n not in INTEGERS)
    assert TICK_DTYPE.itemsize == 8 * len(RECORD_FIELDS)  # no padding
    # the kept fields lead the record, so a record's kept part is a prefix of its bytes
    assert TICK_FIELDS[: len(KEPT_FIELDS)] == KEPT_FIELDS
    assert KEPT_DTYPE.names == RECORD_FIELDS[: len(KEPT_FIELDS)]
    assert all(KEPT_DTYPE.fields[n][1] == TICK_DTYPE.fields[n][1] for n in KEPT_DTYPE.names)


def test_the_ring_keeps_each_field_with_its_own_type() -> None:
    ring = RingBuffer.create(TICK_DTYPE, 8, shared=False)
    big = 2**62 + 1  # not exact in a float64: an int64 field keeps it
    row = [0.5] * len(RECORD_FIELDS)
    for i, name in enumerate(RECORD_FIELDS):
        if name in INTEGERS:
            row[i] = big if name == "t_ns" else i
    ring.write(row)
    got = ring.read_since(0).rows
    assert got.dtype == TICK_DTYPE and int(got["t_ns"][0]) == big and got["gain"][0] == 0.5
    # an attached reader (another process's view) reads the same types from the header
    shared = RingBuffer.create(TICK_DTYPE, 8)
    try:
        shared.write(row)
        reader = RingBuffer.attach(shared.name or "")
        try:
            assert reader.dtype == TICK_DTYPE and int(reader.latest(1)["t_ns"][0]) == big
        finally:
            reader.close()
    finally:
        shared.close()
    # a float where an integer belongs is refused, never truncated
    bad = list(row)
    bad[RECORD_FIELDS.index("faults")] = 1.5
    with pytest.raises(struct.error):
        ring.write(bad)
    with pytest.raises(ValueError, match="int64 or float64"):
        RingBuffer.create(np.dtype([("a", "<i4"), ("b", "<f8")]), 8, shared=False)


def test_the_loop_writes_its_integers_as_ints() -> None:
    eng = build_sim_engine(EngineConfig(clock="virtual"))
    eng.loop.submit(Mark(3, 2))
    eng.loop.run_ticks(50)
    assert eng.ring is not None and eng.ring.dtype == TICK_DTYPE
    rows = eng.ring.read_since(0).rows
    np.testing.assert_array_equal(rows["tick"], np.arange(50))
    assert rows["trial_index"][-1] == 3 and rows["phase"][-1] == 2
    np.testing.assert_array_equal(rows["t_ns"], rows["tick"] * 1_000_000)  # virtual clock, 1 ms period
    np.testing.assert_array_equal(rows["t_s"], rows["t_ns"] * 1e-9)
    last = eng.loop.last_record
    assert last is not None and all(type(last[n]) is int for n in INTEGERS)
    assert np.array([tuple(last[n] for n in RECORD_FIELDS)], TICK_DTYPE).tobytes() == rows[-1:].tobytes()


def _function(module: object, name: str) -> ast.FunctionDef:
    """The function ``name`` of a module's source, at any depth (a kernel is defined inside its compiling factory)."""
    tree = ast.parse(Path(module.__file__).read_text(encoding="utf-8"))  # type: ignore[attr-defined]
    return next(n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef) and n.name == name)


def _names(node: ast.AST) -> tuple[str, ...] | None:
    """The names of a tuple of plain names (None: anything else)."""
    if isinstance(node, ast.Tuple) and all(isinstance(e, ast.Name) for e in node.elts):
        return tuple(e.id for e in node.elts)  # type: ignore[attr-defined]
    return None


def test_the_writer_stores_each_field_at_its_place_with_its_type() -> None:
    """write_record's parameters are the record's fields in order, each stored at its index through the view of its
    type (int64 or float64): the one definition, read from the code."""
    fn = _function(record_writer, "write_record")
    params = [a.arg for a in fn.args.args]
    assert params[:2] == ["rf", "ri"] and tuple(params[2:]) == RECORD_FIELDS
    stores = [n for n in fn.body if isinstance(n, ast.Assign)]
    assert len(stores) == len(RECORD_FIELDS)
    for i, (node, field) in enumerate(zip(stores, TICK_FIELDS, strict=True)):
        target = node.targets[0]
        assert isinstance(target, ast.Subscript) and isinstance(node.value, ast.Name)
        assert (ast.unparse(target.value), ast.unparse(target.slice), node.value.id) == (
            "ri" if field.integer else "rf", str(i), field.name)


def test_the_tick_builds_its_record_by_name() -> None:
    """Each value of a record is the tick's kernel's local variable (or parameter) named as its field, passed to the
    writer in the one definition's order, and the framework's stages are unpacked into locals named by STEP_FIELDS:
    no value is placed by counting."""
    fn = _function(arm_channel, "record_kernel")
    call = next(n for n in ast.walk(fn) if isinstance(n, ast.Call) and ast.unparse(n.func) == "write_record")
    assert [ast.unparse(a) for a in call.args[:2]] == ["rf", "ri"]
    assert tuple(ast.unparse(a) for a in call.args[2:]) == RECORD_FIELDS
    assigned: set[str] = {a.arg for a in fn.args.args}
    stages = None
    for node in ast.walk(fn):
        if isinstance(node, ast.Assign) and len(node.targets) == 1:
            target = node.targets[0]
            names = _names(target) or ((target.id,) if isinstance(target, ast.Name) else ())
            assigned |= set(names)
            if isinstance(node.value, ast.Call) and ast.unparse(node.value.func) == "algorithm_1.step_kernel":
                stages = names
    assert stages == STEP_FIELDS
    assert set(RECORD_FIELDS) <= assigned  # every field is a value the tick computed under its name


def test_the_tick_passes_each_value_to_the_kernel_under_its_name() -> None:
    """ArmChannel.tick hands record_kernel its values by position: each one that is a plain name is the parameter's
    own name (stylus and tip, or the two ages, cannot change places unseen), and every field the kernel takes as a
    parameter is one of them."""
    params = [a.arg for a in _function(arm_channel, "record_kernel").args.args]
    tick = _function(arm_channel, "tick")
    call = next(n for n in ast.walk(tick) if isinstance(n, ast.Call) and ast.unparse(n.func) == "record_kernel")
    assert len(call.args) == len(params)
    named = {p for p, a in zip(params, call.args, strict=True) if isinstance(a, ast.Name)}
    assert all(a.id == p for p, a in zip(params, call.args, strict=True) if isinstance(a, ast.Name))
    computed = {"fw", "rf", "ri", "command_n", "commanded", "derate_check", "limit_n", "static_limit_n", "tick",
                "t_ns", "haptic_on", "trial_index", "phase"}  # (expressions of the loop's or the channel's state)
    assert set(params) - named == computed


def test_the_kernel_is_compiled_for_the_types_its_fields_have() -> None:
    """numba types a kernel by the values of its first call, not by annotations: the warmed record_kernel takes
    floats for every force, position and time in seconds, bools for the switches and int64 for the counts and
    nanoseconds -- so a converted value is never a force truncated to an integer."""
    build_sim_engine(EngineConfig(clock="virtual"))  # (its channel warms the kernel)
    params = [a.arg for a in _function(arm_channel, "record_kernel").args.args][3:]
    (sig,) = arm_channel.record_kernel.signatures  # type: ignore[attr-defined]  # a numba dispatcher's
    got = [str(t) for t in sig[3:]]
    assert got == list(arm_channel.RECORD_KERNEL_TYPES)
    ints = {p for p, t in zip(params, got, strict=True) if t == "int64"}
    assert ints == {p for p in params if p.endswith("_ns") or p in ("tick", "faults", "haptic_on", "trial_index",
                                                                      "phase")}
    assert {p for p, t in zip(params, got, strict=True) if t == "bool"} == {"commanded", "enabled", "derate_check"}


def test_a_record_written_by_the_tick_reads_back_by_name() -> None:
    """The loop's record, read from the ring by field name, holds what the tick computed under that name."""
    eng = build_sim_engine(EngineConfig(clock="virtual", driver="hold", ring_seconds=1.0))
    eng.loop.run_ticks(300)
    ch = eng.loop.arms[0]
    row = eng.ring.latest(1)[0]  # type: ignore[union-attr]
    rec = dict(zip(RECORD_FIELDS, ch.last_record or (), strict=True))
    assert all(row[name] == rec[name] for name in RECORD_FIELDS if not np.isnan(row[name]))
    assert rec["tick"] == eng.loop.tick_count - 1 and rec["t_s"] == rec["t_ns"] * 1e-9
    assert rec["force_n"] == math.hypot(rec["filt_fx"], rec["filt_fy"], rec["filt_fz"])
    assert rec["haptic_on"] == 1 and isinstance(rec["haptic_on"], int)
