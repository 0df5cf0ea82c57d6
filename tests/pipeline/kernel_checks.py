"""Holding a compiled kernel to its ``py_func`` (the same function run by the interpreter), bit for bit."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

_NAN_BITS = np.float64(math.nan).view(np.uint64).item()


def bits(x: Any) -> Any:
    """A value or array as its bits (0.0 differs from -0.0), every NaN as one: IEEE 754 leaves to the machine which
    operand's NaN an operation of two NaNs passes on, and LLVM may swap the operands of ``+`` and ``*`` (the sign and
    payload of a NaN from NaN inputs are no result of ours to keep)."""
    if isinstance(x, np.ndarray):
        a = x.astype(np.float64)
        return np.where(np.isnan(a), _NAN_BITS, a.view(np.uint64)).tolist()
    if isinstance(x, tuple):
        return tuple(bits(v) for v in x)
    if x is None or isinstance(x, (bool, np.bool_)):
        return x if x is None else bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    return _NAN_BITS if math.isnan(x) else np.float64(x).view(np.uint64).item()


def same(kernel: Any, state: np.ndarray, *args: Any) -> None:
    """``kernel`` compiled and interpreted from the same state and arguments: the same result and state, bit for
    bit; a Python exception raised by both alike."""
    a, b = state.copy(), state.copy()
    try:
        got_c = kernel(a, *args)
    except ZeroDivisionError:
        got_c = ZeroDivisionError
    with np.errstate(all="ignore"):
        try:
            got_i = kernel.py_func(b, *args)
        except ZeroDivisionError:
            got_i = ZeroDivisionError
    if got_c is ZeroDivisionError or got_i is ZeroDivisionError:
        assert got_c is got_i
        return
    assert bits(got_c) == bits(got_i)
    assert bits(a) == bits(b)


def compiled_on_construction(imports: str, kernels: str, build: str) -> None:
    """In a fresh process (this one's may have compiled them already): none of ``kernels`` (an expression, after
    ``imports``) is compiled before ``build`` runs, and every one is after it -- so the first tick of a loop that
    ``build`` makes waits for no compiler."""
    code = (f"{imports}\nks = {kernels}\nassert not any(k.signatures for k in ks)\n{build}\n"
            "print(all(k.signatures for k in ks))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=Path(__file__).parents[2])
    assert out.stdout.strip() == "True", out.stderr
