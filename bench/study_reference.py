"""``haptic-study bench study --reference-tree TREE``: a seeded study's wall time, ours and another version's in turn.

Each round runs the same seeded study (the default protocol, training included, participants in parallel as
``run`` does) once with our code and once with the tree's, each in a fresh process
(:mod:`bench.source_trees`), alternating which goes first so a slow spell of the machine falls on both sides.
The figure compared is the median wall time per side, and the load average is printed beside it: a ratio
measured on a busy machine says so.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Callable
from typing import Any

from bench.source_trees import check_tree, source_env
from foundation.platform_support.machine import load_average

__all__ = ["format_study_reference", "run_study_reference"]

# One study in a fresh process.  A tree from before the protocol package was split keeps its protocol file code
# in protocol/config.py; the check is by file, not by trying the import (a failed import of a module the tree does
# not have could find an installed version's instead).
_ONE_STUDY = """
import json, os, sys, tempfile, time
import protocol
if os.path.exists(os.path.join(os.path.dirname(protocol.__file__), "config.py")):
    from protocol.config import default_protocol
else:
    from protocol.study.config import default_protocol
from study_app.headless import run_study
participants, seed = int(sys.argv[1]), int(sys.argv[2])
with tempfile.TemporaryDirectory() as tmp:
    t0 = time.perf_counter()
    p = run_study(os.path.join(tmp, "s.db"), participants=participants, seed=seed, protocol=default_protocol())
    wall = time.perf_counter() - t0
print(json.dumps({"wall_s": wall, "study_time_s": p.study_time_s}))
"""


def _load() -> float:
    """The 1-minute load average (NaN where the OS has none: Windows)."""
    la = load_average()
    return la[0] if la is not None else float("nan")


def _one(tree: str | None, participants: int, seed: int, cwd: str) -> dict[str, float]:
    out = subprocess.run([sys.executable, "-c", _ONE_STUDY, str(participants), str(seed)], check=True,
                         capture_output=True, text=True, env=source_env(tree), cwd=cwd)
    return dict(json.loads(out.stdout.strip().splitlines()[-1]))


def run_study_reference(tree: str, *, participants: int = 10, seed: int = 0, rounds: int = 3,
                        log: Callable[[str], None] | None = None) -> dict[str, Any]:
    """``rounds`` × (ours, the tree's) of the same seeded study, alternating the order; wall times and ratio."""
    say = log or (lambda _: None)
    ours_root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    with tempfile.TemporaryDirectory() as cwd:
        check_tree(tree, cwd, "--reference-tree")
        check_tree(ours_root, cwd, "(ours)")
        load0 = _load()
        ours: list[float] = []
        theirs: list[float] = []
        study_s: dict[str, float] = {}
        for r in range(rounds):
            order = [("ours", ours_root, ours), ("reference", tree, theirs)]
            for name, root, into in (order if r % 2 == 0 else order[::-1]):
                say(f"round {r + 1}/{rounds}: {name} ...")
                got = _one(root, participants, seed, cwd)
                into.append(got["wall_s"])
                study_s[name] = got["study_time_s"]
        load1 = _load()
    mo, mr = statistics.median(ours), statistics.median(theirs)
    return {"participants": participants, "seed": seed, "rounds": rounds, "reference_tree": os.path.abspath(tree),
            "ours_wall_s": [round(x, 2) for x in ours], "reference_wall_s": [round(x, 2) for x in theirs],
            "ours_median_s": round(mo, 2), "reference_median_s": round(mr, 2), "ratio": round(mo / mr, 3),
            "study_time_s": {k: round(v, 1) for k, v in study_s.items()},
            "load_average": [round(load0, 2), round(load1, 2)]}


def format_study_reference(r: dict[str, Any]) -> str:
    """Human-readable summary."""
    same = len(set(r["study_time_s"].values())) == 1
    return (
        f"a seeded {r['participants']}-participant study (seed {r['seed']}, training + experiment, participants in "
        f"parallel as `run` does), {r['rounds']} round(s) of ours and the reference in turn, fresh processes:\n"
        f"  ours        median {r['ours_median_s']:7.1f} s wall   rounds {r['ours_wall_s']}\n"
        f"  reference   median {r['reference_median_s']:7.1f} s wall   rounds {r['reference_wall_s']}\n"
        f"  ratio ours/reference {r['ratio']:.3f}  ({1 / r['ratio']:.2f}x)   "
        f"study time {'the same' if same else 'DIFFERENT'}: {r['study_time_s']}\n"
        f"  load average {r['load_average'][0]} at the start, {r['load_average'][1]} at the end "
        f"(reference: {r['reference_tree']})"
    )
