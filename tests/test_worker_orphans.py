"""A command killed with ``kill -9`` leaves no worker process behind (``PR_SET_PDEATHSIG``, by every pool).

``run``'s participant workers always died with it; ``report`` (and every other command with a pool of worker
processes: the analysis's :func:`foundation.parallel.run_tasks`, ``sweep``'s and the calibration bench's pools)
left its workers orphaned, each computing on with ~200 MB, for ever.  Each test starts the command in a
subprocess, waits until it has worker processes, kills it with SIGKILL and polls (within a bound) until every
worker it had is gone.
"""

from __future__ import annotations

import ast
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "analysis"))  # studybuilder

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")

#: How long the workers may take to go once their parent is dead (the kernel signals them at once).
GONE_WITHIN_S = 15.0


def _children(pid: int) -> list[int]:
    """The live (not zombie) processes whose parent is ``pid``."""
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid and fields[0] not in ("Z", "X"):
            out.append(int(d.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state not in ("Z", "X")


def _kill_and_watch(script: str, workers: int, env: dict[str, str] | None = None) -> list[int]:
    """Start ``script``; once it has ``workers`` children, SIGKILL it; the children still alive after the bound."""
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})})
    kids: list[int] = []
    try:
        deadline = time.monotonic() + 120.0
        while len(kids) < workers and time.monotonic() < deadline:
            assert proc.poll() is None, f"the command ended before its workers started: {proc.stderr.read()!r}"
            kids = _children(proc.pid)
            time.sleep(0.05)
        assert len(kids) >= workers, f"no {workers} worker processes within the bound (saw {kids})"
        time.sleep(0.5)  # the workers past their start (a pool's initializer), computing
        kids = _children(proc.pid)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        deadline = time.monotonic() + GONE_WITHIN_S
        while any(_alive(k) for k in kids) and time.monotonic() < deadline:
            time.sleep(0.05)
        return [k for k in kids if _alive(k)]
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for k in kids:  # an orphan this test made is not left to run on (it would be the bug's 200 MB)
            if _alive(k):
                os.kill(k, signal.SIGKILL)
        if proc.stderr is not None:
            proc.stderr.close()


_POOLS = {
    "foundation.parallel.run_tasks (report, bench)": """
        import time
        from foundation.parallel import run_tasks
        run_tasks(time.sleep, [(600,), (600,)], workers=2)
    """,
    "worker_pool, fork (sweep)": """
        import time
        from foundation.platform_support.processes import worker_pool
        with worker_pool(2) as pool:
            pool.map(time.sleep, [600, 600])
    """,
    "worker_pool, spawn (calibration bench)": """
        import multiprocessing as mp, time
        from foundation.platform_support.processes import worker_pool
        if __name__ == "__main__":
            with worker_pool(2, mp.get_context("spawn")) as pool:
                pool.map(time.sleep, [600, 600])
    """,
}


@pytest.mark.parametrize("pool", list(_POOLS))
def test_a_killed_process_leaves_no_pool_worker(pool: str) -> None:
    assert _kill_and_watch(textwrap.dedent(_POOLS[pool]), workers=2) == []


def test_kill_9_of_report_leaves_no_worker(tmp_path: Path) -> None:
    """The defect as found: ``report`` killed while its workers read the samples; they end with it."""
    from studybuilder import SessionDef, build, success_trial, timeout_trial

    db = build(tmp_path / "s.db", [SessionDef(f"P{i:02d}", [success_trial("GENTLE", "on", 100 * i),
                                                            timeout_trial("FIRM", "off", 1.0)], max_trial_s=2.0)
                                   for i in range(1, 5)])
    # the workers' task made slow (they inherit it: fork), so the report is still computing when it is killed
    script = textwrap.dedent(f"""
        import sys, time
        import analysis.reading.metrics as m
        real = m._chunk
        def _chunk(*args):
            time.sleep(600)
            return real(*args)
        _chunk.__module__, _chunk.__qualname__ = real.__module__, real.__qualname__
        m._chunk = _chunk
        from study_app.cli.main import main
        sys.exit(main(["report", "--db", {str(db)!r}, "--out", {str(tmp_path / "rep")!r}]))
    """)
    assert _kill_and_watch(script, workers=2, env={"HAPTIC_STUDY_WORKERS": "2"}) == []


def test_every_pool_of_the_product_makes_its_workers_die_with_it() -> None:
    """A pool made anywhere else than in the two places that pass :func:`die_with` would orphan its workers."""
    allowed = {("foundation/platform_support/processes.py", "Pool"), ("foundation/parallel.py", "ProcessPoolExecutor")}
    found = []
    for folder in ("foundation", "analysis", "bench", "pipeline", "protocol", "study_app"):
        for path in (ROOT / folder).rglob("*.py"):
            rel = path.relative_to(ROOT).as_posix()
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.Call):
                    f = node.func
                    name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
                    if name in ("Pool", "ProcessPoolExecutor"):
                        found.append((rel, name))
                        assert (rel, name) in allowed, f"{rel}: {name}(...) outside worker_pool / run_tasks"
                        assert any(k.arg == "initializer" for k in node.keywords), f"{rel}: {name} without die_with"
    assert sorted(set(found)) == sorted(allowed)
