"""``haptic-study bench pipeline --reference-tree TREE``: our pipeline's figures and another version's, in one run.

Each round runs ``bench pipeline --json`` of our tree and of the reference tree (a git worktree of another
version: :mod:`bench.source_trees`), each in a fresh process, in turn -- ours, theirs, ours, theirs, … -- so a busy
spell of a shared machine falls on both alike.  A figure is the median of its rounds, and the ratio ours /
reference is of those medians; the best (least disturbed) round of each and every round's figures are kept.  The
figures compared are the per-tick costs: Algorithm 1's step (``ours_us_per_tick``) and the loop's whole
tick with one and two arms (devices read, watchdog, Algorithm 1, command, record), and, with ``--loop-seconds``,
the 1 kHz loop's p99 |period - 1 ms|.
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Callable
from typing import Any

from bench.source_trees import check_tree, source_env

__all__ = ["COMPARED", "format_reference", "run_reference"]

#: The figures compared, with what they are.
COMPARED: dict[str, str] = {
    "ours_us_per_tick": "Algorithm 1, one step (µs)",
    "arms_tick_one_us": "the loop's whole tick, one arm (µs)",
    "arms_tick_two_us": "the loop's whole tick, two arms (µs)",
    "loop_abs_dev_p99_us": "1 kHz loop, p99 |period - 1 ms| (µs)",
}


def _figures(source: str | None, cwd: str, loop_seconds: float, ticks: int) -> dict[str, Any]:
    """One ``bench pipeline --json`` of our tree (``source`` None) or of the tree ``source``, in a fresh process."""
    out = subprocess.run([sys.executable, "-m", "study_app.cli", "bench", "pipeline", "--json", "--loop-seconds",
                          repr(loop_seconds), "--ticks", str(ticks)],
                         check=True, capture_output=True, text=True, env=source_env(source), cwd=cwd)
    result: dict[str, Any] = json.loads(out.stdout)
    return result


def run_reference(tree: str, rounds: int = 5, loop_seconds: float = 0.0, ticks: int = 20_000,
                  progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Our figures and the tree's, ``rounds`` times in turn; medians, their ratios and every round's figures."""
    say = progress or (lambda s: None)
    runs: dict[str, list[dict[str, Any]]] = {"ours": [], "reference": []}
    with tempfile.TemporaryDirectory(prefix="bench-pipeline-") as cwd:
        check_tree(tree, cwd, "--reference-tree")
        for k in range(rounds):
            for side, source in (("ours", None), ("reference", tree)):
                say(f"round {k + 1} of {rounds}: {side}")
                runs[side].append(_figures(source, cwd, loop_seconds, ticks))
    figures: dict[str, Any] = {}
    for key in COMPARED:
        ours = [r[key] for r in runs["ours"] if r.get(key) is not None]
        theirs = [r[key] for r in runs["reference"] if r.get(key) is not None]
        if not ours or not theirs:
            continue
        mo, mt = statistics.median(ours), statistics.median(theirs)
        figures[key] = {"ours": mo, "reference": mt, "ratio": round(mo / mt, 3) if mt else None,
                        "ours_best": min(ours), "reference_best": min(theirs),
                        "ours_rounds": ours, "reference_rounds": theirs}
    return {"reference_tree": tree, "rounds": rounds, "loop_seconds": loop_seconds, "ticks": ticks,
            "figures": figures}


def format_reference(r: dict[str, Any]) -> str:
    """Human-readable report of :func:`run_reference`."""
    lines = [f"Ours against {r['reference_tree']}: {r['rounds']} rounds in turn, fresh processes, "
             f"{r['ticks']} recorded ticks each (medians; ratio = ours / reference):"]
    for key, what in COMPARED.items():
        f = r["figures"].get(key)
        if f is None:
            continue
        lines.append(f"  {what:<40} ours {f['ours']:9.3f}   reference {f['reference']:9.3f}   ratio "
                     f"{f['ratio']:.3f}   (best round: ours {f['ours_best']:.3f}, reference {f['reference_best']:.3f})")
        lines.append(f"    rounds: ours {' / '.join(f'{v:.3f}' for v in f['ours_rounds'])}; reference "
                     f"{' / '.join(f'{v:.3f}' for v in f['reference_rounds'])}")
    return "\n".join(lines)
