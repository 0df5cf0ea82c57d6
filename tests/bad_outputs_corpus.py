"""The bad-input corpus of tests/test_bad_inputs.py, part 2: where the commands that write files are sent.

Outputs that exist already, links inside an output folder or in place of an output file, folders the command
may not write, FIFOs and devices, read-only and full file systems (small tmpfs mounts, see tests/mounts.py):
each case ends with one line and its exit status (2: refused before the work; 1: the file system failed while
writing), every file that was there unchanged (bytes, mode, link target), and nothing new left behind.
"""

from __future__ import annotations

from bad_inputs_corpus import (
    EXAMPLE_HARDWARE,
    GOOD,
    TINY_PROTOCOL,
    Case,
    Mount,
    _text,
    fifo,
    good_db,
    link,
    marked_folder,
    user_folder,
)

REPORT = ".haptic-study-report"
POWER = ".haptic-study-power"
READ_ONLY = "the file system is read-only; write to a folder on a writable disk (nothing was written)"
NO_SPACE = "no space left on the device"
DENIED = "permission denied"


def _plot_trial(out: str, db: str = "{d}/good.db") -> tuple[str, ...]:
    return ("plot-trial", "--db", db, "--session", "1", "--trial", "1", "--out", out)


def _plot_session(out: str) -> tuple[str, ...]:
    return ("plot-session", "--db", "{d}/good.db", "--session", "1", "--out", out)


def _export(out: str, *more: str) -> tuple[str, ...]:
    return ("export", "samples", "--db", "{d}/good.db", "--out", out, *more)


def _replay(out: str) -> tuple[str, ...]:
    return ("replay", "--db", "{d}/good.db", "--session", "1", "--filter-window", "20", "--out", out)


def _report(out: str, *more: str) -> tuple[str, ...]:
    return ("report", "--db", "{d}/good.db", "--out", out, *more)


def _power(out: str, *more: str) -> tuple[str, ...]:
    return ("power", "--db", "{d}/good.db", "--out", out, *more)


def _shots(out: str) -> tuple[str, ...]:
    return ("gui", "--screenshot", out)


_OLD_REPORT = {"report.html": "<html>an earlier report</html>", "trials.csv": "a,b\n1,2\n"}
#: A full disk: a tmpfs with no block left (the check before the work refuses it).
FULL = Mount(size_kib=256, free_kib=0)
#: A small empty disk: the check before the work passes, the outputs do not fit (ENOSPC while writing).
SMALL = Mount(size_kib=64)
RO = Mount(size_kib=64, read_only=True)

CASES: list[Case] = [
    # -- an existing output is never replaced, and never written through a link --------------------------------
    Case("plot-trial --out an existing file", _plot_trial("{d}/t.png"),
         "t.png: exists; plot-trial writes a new file only and never replaces one", {**GOOD, "t.png": _text("mine")}),
    Case("plot-trial --out a link to the study database", _plot_trial("{d}/t.png"),
         "t.png: exists (it is a symbolic link); plot-trial writes a new file only",
         {**GOOD, "t.png": link("good.db")}),
    Case("plot-trial --out a dangling link", _plot_trial("{d}/t.png"),
         "t.png: exists (it is a symbolic link)", {**GOOD, "t.png": link("nowhere.png")}),
    Case("plot-trial --out a FIFO", _plot_trial("{d}/t.png"), "t.png: exists (it is a FIFO (named pipe))",
         {**GOOD, "t.png": fifo}),
    Case("plot-trial --out in a missing folder", _plot_trial("{d}/no/t.png"), "the folder {d}/no does not exist", GOOD),
    Case("plot-session --out an existing file", _plot_session("{d}/s.pdf"),
         "s.pdf: exists; plot-session writes a new file only", {**GOOD, "s.pdf": _text("mine")}),
    Case("plot-session --out a link to the study database", _plot_session("{d}/s.png"),
         "s.png: exists (it is a symbolic link)", {**GOOD, "s.png": link("good.db")}),
    Case("export --out a link to a file", _export("{d}/x.csv"), "x.csv: exists (it is a symbolic link)",
         {**GOOD, "x.csv": link("good.db")}),
    Case("export --out a FIFO", _export("{d}/x.csv"), "x.csv: exists (it is a FIFO (named pipe))",
         {**GOOD, "x.csv": fifo}),
    Case("export --out a device", _export("/dev/null"), "--out /dev/null: exists (it is a device)", GOOD),
    Case("export --out in a missing folder", _export("{d}/no/x.csv"), "the folder {d}/no does not exist", GOOD),
    Case("replay --out a non-empty folder", _replay("{d}/r"), "r: the folder exists and holds figure.png and 1 more",
         {**GOOD, "r": user_folder}),
    Case("replay --out a file", _replay("{d}/r"), "r: exists and is not a folder (it is a file)",
         {**GOOD, "r": _text("mine")}),
    Case("replay --out a dangling link", _replay("{d}/r"), "r: is a symbolic link to nothing",
         {**GOOD, "r": link("nowhere")}),
    Case("report --out a folder with someone's files", _report("{d}/r"), "r: the folder exists and holds figure.png",
         {**GOOD, "r": user_folder}),
    Case("report --force, a folder without a marker", _report("{d}/r", "--force"),
         "r: not a folder report wrote (no readable .haptic-study-report in it)", {**GOOD, "r": user_folder}),
    Case("report --force, figures/ a link to someone's folder", _report("{d}/r", "--force"),
         "r: holds figures (a symbolic link), which report did not write",
         {**GOOD, "mine": user_folder, "r": marked_folder(REPORT, _OLD_REPORT, {"figures": "mine"})}),
    Case("report --force, a listed file now a link", _report("{d}/r", "--force"),
         "r: holds trials.csv (a symbolic link), which report did not write",
         {**GOOD, "mine": user_folder,
          "r": marked_folder(REPORT, {"report.html": "<html/>"}, {"trials.csv": "mine/notes.txt"})}),
    Case("report --force, an edited file", _report("{d}/r", "--force"),
         "r: trials.csv was changed since report wrote it", {**GOOD, "r": marked_folder(REPORT, _OLD_REPORT,
                                                                                         edited="trials.csv")}),
    Case("report --force, the marker a link", _report("{d}/r", "--force"), "r: not a folder report wrote",
         {**GOOD, "mine": marked_folder(REPORT, {"trials.csv": "x"}),
          "r": marked_folder("unused", {"trials.csv": "x"}, {REPORT: f"mine/{REPORT}"})}),
    Case("report --force, a FIFO in the folder", _report("{d}/r", "--force"),
         "r: holds pipe (a FIFO (named pipe)), which report did not write",
         {**GOOD, "r": marked_folder(REPORT, _OLD_REPORT), "r/pipe": fifo}),
    Case("report --out an existing file", _report("{d}/r"), "r: exists and is not a folder (it is a file)",
         {**GOOD, "r": _text("mine")}),
    Case("report --out a FIFO", _report("{d}/r"), "r: exists and is not a folder (it is a FIFO (named pipe))",
         {**GOOD, "r": fifo}),
    Case("report --out under a file", _report("{d}/f/r"), "--out {d}/f/r: ", {**GOOD, "f": _text("a file")}),
    Case("report --out the folder of its database", ("report", "--db", "{d}/r/good.db", "--out", "{d}/r", "--force"),
         "r: holds the input database", {"r": marked_folder(REPORT, _OLD_REPORT), "r/good.db": good_db}),
    Case("power --out a folder with someone's files", _power("{d}/p"), "p: the folder exists and holds figure.png",
         {**GOOD, "p": user_folder}),
    Case("power --force, a power folder with a link in it", _power("{d}/p", "--force"),
         "p: holds power.png (a symbolic link), which power did not write",
         {**GOOD, "mine": user_folder,
          "p": marked_folder(POWER, {"power.csv": "x"}, {"power.png": "mine/figure.png"})}),
    Case("gui --screenshot into a folder with someone's files", _shots("{d}/s"),
         "--screenshot {d}/s: the folder exists and holds figure.png", {"s": user_folder}),
    # -- folders the command may not write (run as an unprivileged user) -----------------------------------------
    Case("report --out a folder it may not write", _report("{d}/r"), f"--out {{d}}/r: {DENIED}", GOOD, as_nobody=True),
    Case("plot-trial --out a folder it may not write", _plot_trial("{d}/t.png"), f"--out {{d}}/t.png: {DENIED}", GOOD,
         as_nobody=True),
    Case("plot-session --out a folder it may not write", _plot_session("{d}/s.png"), DENIED, GOOD, as_nobody=True),
    Case("export --out a folder it may not write", _export("{d}/x.csv"), DENIED, GOOD, as_nobody=True),
    Case("replay --out a folder it may not write", _replay("{d}/r"), DENIED, GOOD, as_nobody=True),
    Case("power --out a folder it may not write", _power("{d}/p"), DENIED, GOOD, as_nobody=True),
    Case("gui --screenshot into a folder it may not write", _shots("{d}/s"), DENIED, as_nobody=True),
    Case("run --db in a folder it may not write", ("run", "--participants", "1", "--db", "{d}/new.db"),
         "new.db: cannot create the database here", as_nobody=True),
    # -- a read-only file system ------------------------------------------------------------------------------------
    Case("read-only: report", _report("{d}/ro/r"), READ_ONLY, GOOD, mounts={"ro": RO}),
    Case("read-only: report on the mount point", _report("{d}/ro"), READ_ONLY, GOOD, mounts={"ro": RO}),
    Case("read-only: plot-trial", _plot_trial("{d}/ro/t.png"), READ_ONLY, GOOD, mounts={"ro": RO}),
    Case("read-only: plot-session", _plot_session("{d}/ro/s.svg"), READ_ONLY, GOOD, mounts={"ro": RO}),
    Case("read-only: export", _export("{d}/ro/x.csv"), READ_ONLY, GOOD, mounts={"ro": RO}),
    Case("read-only: export parquet", _export("{d}/ro/x.parquet", "--format", "parquet"), READ_ONLY, GOOD,
         mounts={"ro": RO}),
    Case("read-only: replay --out", _replay("{d}/ro/r"), READ_ONLY, GOOD, mounts={"ro": RO}),
    Case("read-only: power", _power("{d}/ro/p"), READ_ONLY, GOOD, mounts={"ro": RO}),
    Case("read-only: gui --screenshot", _shots("{d}/ro/s"), READ_ONLY, mounts={"ro": RO}),
    Case("read-only: run into a new database", ("run", "--participants", "1", "--db", "{d}/ro/new.db"),
         "new.db: cannot create the database here", mounts={"ro": RO}),
    Case("read-only: run --continue", ("run", "--participants", "2", "--seed", "0", "--protocol", "{d}/tiny.toml",
                                       "--continue", "--db", "{d}/ro/good.db"), "good.db: the database is not writable",
         {"tiny.toml": _text(TINY_PROTOCOL)},
         mounts={"ro": Mount(size_kib=512, read_only=True, files={"good.db": good_db})}),
    # -- a full file system: refused before the work, or one line when it fills while writing ----------------------
    Case("full: plot-trial", _plot_trial("{d}/full/t.png"), NO_SPACE, GOOD, mounts={"full": FULL}),
    Case("full: plot-session", _plot_session("{d}/full/s.png"), NO_SPACE, GOOD, mounts={"full": FULL}),
    Case("full: export", _export("{d}/full/x.csv"), NO_SPACE, GOOD, mounts={"full": FULL}),
    Case("full: export, larger than the space left", _export("{d}/full/x.csv"),
         "x.csv: no space left on the device (", GOOD, mounts={"full": Mount(size_kib=256, free_kib=64)},
         after_work=True),
    Case("full: export parquet", _export("{d}/full/x.parquet", "--format", "parquet"), NO_SPACE, GOOD,
         mounts={"full": FULL}),
    Case("full: report", _report("{d}/full/r"), NO_SPACE, GOOD, mounts={"full": FULL}),
    Case("full: replay --out", _replay("{d}/full/r"), NO_SPACE, GOOD, mounts={"full": FULL}),
    Case("full: power", _power("{d}/full/p"), NO_SPACE, GOOD, mounts={"full": FULL}),
    Case("full: gui --screenshot", _shots("{d}/full/s"), NO_SPACE, mounts={"full": FULL}),
    Case("full: run", ("run", "--participants", "1", "--db", "{d}/full/new.db"), f"new.db: {NO_SPACE}",
         mounts={"full": FULL}),
    Case("full: run --continue", ("run", "--participants", "2", "--seed", "0", "--protocol", "{d}/tiny.toml",
                                  "--continue", "--db", "{d}/full/good.db"), f"good.db: {NO_SPACE}",
         {"tiny.toml": _text(TINY_PROTOCOL)},
         mounts={"full": Mount(size_kib=512, free_kib=0, files={"good.db": good_db})}),
    Case("full while writing: report on the mount point", _report("{d}/full"),
         "--out {d}/full: cannot write report's outputs: no space left on the device; free some space or write to "
         "another disk (nothing was written)", GOOD, exit=1,
         mounts={"full": SMALL}),
    Case("full while writing: plot-trial", _plot_trial("{d}/full/t.png"),
         "--out {d}/full/t.png: cannot write it: no space left on the device", GOOD, exit=1, mounts={"full": SMALL}),
    Case("full while writing: plot-session", _plot_session("{d}/full/s.png"),
         "--out {d}/full/s.png: cannot write it: no space left on the device", GOOD, exit=1, mounts={"full": SMALL}),
    Case("full while writing: replay --out", _replay("{d}/full/r"),
         "cannot write replay's outputs: no space left on the device", GOOD, exit=1, mounts={"full": SMALL}),
    Case("hardware file beside a full disk still checks", ("check-hardware", "--hardware", "{d}/full/hw.toml"),
         "hw.toml: frames.rot_tip_sensor = None", mounts={"full": Mount(size_kib=64, free_kib=0, files={
             "hw.toml": _text(EXAMPLE_HARDWARE.replace("rot_tip_sensor = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]", ""))})}),
]
