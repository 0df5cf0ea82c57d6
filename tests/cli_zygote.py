"""Run many ``haptic-study`` commands as forks of one process that has imported the command line once.

The bad-input corpus (tests/test_bad_inputs.py) runs a couple of hundred commands, each of which used to be a new
interpreter paying Python's start-up and the imports (numpy, the storage layer, the settings) before refusing in a
few milliseconds: about 0.4 s of CPU each, most of the corpus's two minutes.  Here one process (this script, started
once per corpus in the environment the commands get) imports the command line and what its refusals need, then
forks a child per command.  Each child is a process of its own, as a command run from a shell is: its own
standard output and error (files, at the descriptor level), its own working folder and environment, the user it
runs as, an exit status from ``sys.exit(main(argv))`` as the console script has it (an uncaught exception: its
traceback on stderr, status 1), and nothing it changes reaches the next command.  What a fork does not prove --
that the installed script starts and imports on its own -- a few cases of the corpus prove by running the real
script too, and a test compares their outcomes with the forks'.

Protocol: one JSON list on stdin, of ``{"id", "args", "cwd", "env", "user": [uid, gid] | null, "out", "err",
"timeout_s"}``; one JSON line on stdout per finished command, ``{"id", "returncode", "seconds"}`` (a command
killed at its timeout: returncode -9).  At most ``sys.argv[1]`` commands run at once.
"""

from __future__ import annotations

import importlib
import json
import os
import selectors
import sys
import time
import traceback

#: Imported before the first fork: the command line, the modules its refusals import before refusing, and the
#: analysis the commands that fail while writing (a full disk) load first.  Never Qt: the GUI commands import it
#: themselves, and a process holding Qt must not fork.
PRELOAD = (
    "study_app.cli.main",
    "numpy",
    "pandas",
    "protocol.storage",
    "protocol.study.records",
    "protocol.storage.audit",
    "pipeline.settings.hardware",
    "pipeline.assembly.real_rig",
    "pipeline.force.replay",
    "foundation.parallel",
    "foundation.oserrors",
    "foundation.outdir",
    "analysis.reading.inputs",
    "analysis.reading.load",
    "analysis.reading.metrics",
    "analysis.plots.figures",
    "analysis.plots.session_figures",
    "analysis.report.report",
    "analysis.stats.replay_compare",
    "analysis.planning.power_pool",
)


def _exit_status(exc: SystemExit) -> int:
    """The status Python gives ``sys.exit(code)`` (a message: printed on stderr, status 1)."""
    if exc.code is None:
        return 0
    if isinstance(exc.code, int):
        return exc.code & 0xFF
    print(exc.code, file=sys.stderr)
    return 1


def _child(req: dict) -> None:
    """In the fork: become the command (descriptors, folder, environment, user), run it, and never return."""
    status = 1
    try:
        stdin = os.open(os.devnull, os.O_RDONLY)
        out = os.open(req["out"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        err = os.open(req["err"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        for fd, target in ((stdin, 0), (out, 1), (err, 2)):
            os.dup2(fd, target)
            os.close(fd)
        os.chdir(req["cwd"])
        os.environ.clear()
        os.environ.update(req["env"])
        if req["user"] is not None:
            os.setgroups([])
            os.setgid(req["user"][1])
            os.setuid(req["user"][0])
        from study_app.cli.main import main

        sys.argv = ["haptic-study", *req["args"]]
        try:
            sys.exit(main(req["args"]))
        except SystemExit as exc:
            status = _exit_status(exc)
        except BaseException:  # what the interpreter does with an uncaught exception
            traceback.print_exc()
            status = 1
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(status)


def _start(req: dict) -> tuple[int, int]:
    sys.stdout.flush()  # nothing buffered here may be written again by the child
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:
        _child(req)
    return pid, os.pidfd_open(pid)


def serve(requests: list[dict], at_once: int) -> None:
    """Run ``requests``, ``at_once`` at a time, and report each as it ends."""
    pending = list(reversed(requests))
    running: dict[int, tuple[dict, int, float]] = {}  # pidfd -> (request, pid, start)
    sel = selectors.DefaultSelector()
    while pending or running:
        while pending and len(running) < at_once:
            req = pending.pop()
            pid, pidfd = _start(req)
            running[pidfd] = (req, pid, time.monotonic())
            sel.register(pidfd, selectors.EVENT_READ)
        now = time.monotonic()
        wait_s = min(start + req["timeout_s"] - now for req, _, start in running.values())
        ready = {key.fd for key, _ in sel.select(timeout=max(0.0, wait_s))}
        now = time.monotonic()
        for pidfd, (req, pid, start) in list(running.items()):
            if pidfd not in ready and now - start < req["timeout_s"]:
                continue
            if pidfd not in ready:  # it hung (a FIFO read for ever): killed, and reported as such
                os.kill(pid, 9)
            _, wstatus = os.waitpid(pid, 0)
            sel.unregister(pidfd)
            os.close(pidfd)
            del running[pidfd]
            code = os.waitstatus_to_exitcode(wstatus)
            print(json.dumps({"id": req["id"], "returncode": code, "seconds": now - start}), flush=True)


if __name__ == "__main__":
    # run as a script, this folder heads sys.path, and tests/protocol would shadow the product's protocol package
    here = os.path.dirname(os.path.abspath(__file__))
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != here]
    for name in PRELOAD:
        importlib.import_module(name)
    serve(json.load(sys.stdin), int(sys.argv[1]))
