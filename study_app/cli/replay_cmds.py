"""``replay``, ``plot-session`` and ``export samples``: a recorded session, after the fact.

``replay`` runs a session's recorded inputs through the pipeline again
(:mod:`pipeline.force.replay`): with the recorded settings it must reproduce the
rendered force bit for bit, and says whether it did; with another filter
window, f_scale or f_max it says, trial by trial, what the participant would
have felt instead, and measures the filter's trade on the recording itself.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from foundation.errors import InputRefused
from pipeline.force.config import LIMIT_RANGE_N
from pipeline.settings.tomlfields import SQLITE_INTEGER_MAX
from study_app.cli.argtypes import add_command, arm_name, real_number, whole_number
from study_app.cli.error import CliError
from study_app.cli.export_participant_cmds import add_export_participant_parser

if TYPE_CHECKING:  # numpy is imported where it is used: every haptic-study command imports this module
    import numpy as np

__all__ = ["add_replay_parsers", "cmd_export", "cmd_plot_session", "cmd_replay"]

_FIGURE_SUFFIXES = (".png", ".pdf", ".svg")

#: The marker of a replay output folder (foundation.outdir): the files replay wrote there, with their SHA-256.
REPLAY_MARKER = ".haptic-study-replay"


def add_replay_parsers(sub: argparse._SubParsersAction) -> None:
    """Register ``replay``, ``plot-session`` and ``export``."""
    _add_replay_parser(sub)
    _add_plot_and_export_parsers(sub)


def _add_replay_parser(sub: argparse._SubParsersAction) -> None:
    r = add_command(
        sub, "replay", "run a recorded session through the pipeline again, as recorded or with other settings",
        "haptic-study replay --db study.db --session 2\n"
        "haptic-study replay --db study.db --session 2 --filter-window 20 --out replay-w20\n"
        "haptic-study replay --db study.db --session 2 --filter-window 30 --out replay-w20 --force",
        "Run a recorded session's inputs (raw sensor wrench, robot poses, feedback switch, faults) through the "
        "same pipeline code as the live loop. With the recorded settings it reproduces the rendered force bit for "
        "bit; with another --filter-window, --f-scale or --f-max it writes, per trial, how the rendered force would "
        "have differed, and measures the filter window's noise and delay on the recording",
    )
    r.add_argument("--db", required=True, metavar="PATH", help="study database")
    r.add_argument("--session", type=whole_number("--session", 1, SQLITE_INTEGER_MAX), required=True, metavar="ID",
                   help="session id (haptic-study sessions --db PATH lists them)")
    r.add_argument("--filter-window", type=whole_number("--filter-window", 1, 1000), default=None, metavar="N",
                   help="moving-average window to try, samples")
    # the scaling law's own lower bound (LIMIT_RANGE_N), checked here in the option's name before any work
    r.add_argument("--f-scale", type=real_number("--f-scale", LIMIT_RANGE_N[0], 1000.0), default=None,
                   metavar="N", help="tanh scaling f_scale to try, N")
    r.add_argument("--f-max", type=real_number("--f-max", LIMIT_RANGE_N[0], 100.0), default=None, metavar="N",
                   help="tanh scaling f_max to try, N (the device's own peak still clamps)")
    r.add_argument("--out", default=None, metavar="DIR",
                   help="write replay_trials.csv, filter_trade.csv and replay.png/.pdf/.svg here (a new or empty "
                        "folder, unless --force)")
    r.add_argument("--force", action="store_true",
                   help="replace the files an earlier replay wrote in DIR, if unedited (the marker "
                        f"{REPLAY_MARKER} lists them with their SHA-256); any other file, an edited one or the "
                        "input database in DIR is a refusal")
    r.add_argument("--arm", type=arm_name("--arm"), default=None, metavar="NAME",
                   help="a rig of several arms: the arm whose records to replay, over the task arm's trials "
                        "(default: the task arm's)")
    r.set_defaults(handler=cmd_replay)


def _add_plot_and_export_parsers(sub: argparse._SubParsersAction) -> None:

    p = add_command(
        sub, "plot-session", "a whole recorded session's force through the pipeline (the paper's Fig. 6)",
        "haptic-study plot-session --db study.db --session 2 --out session2.pdf",
        "Draw a whole recorded session: the compensated and rendered force with trials, their target bands and "
        "contact shaded and a zero baseline; aborted trials (with their cause), experimenter pauses, latched "
        "faults and resumes marked; the raw sensor force on an axis of its own (decimated for drawing, never for "
        "numbers)",
    )
    p.add_argument("--db", required=True, metavar="PATH", help="study database")
    p.add_argument("--session", type=whole_number("--session", 1, SQLITE_INTEGER_MAX), required=True, metavar="ID",
                   help="session id")
    p.add_argument("--out", required=True, metavar="FILE", help="figure file: .png (300 dpi), .pdf or .svg")
    p.add_argument("--arm", type=arm_name("--arm"), default=None, metavar="NAME",
                   help="a rig of several arms: the arm whose records to draw (default: the task arm's)")
    p.set_defaults(handler=cmd_plot_session)

    e = add_command(
        sub, "export", "export a study's data in tidy form (samples: every 1 kHz record; participant: all of one "
        "participant's)",
        "haptic-study export samples --db study.db --session 2 --format csv --out session2.csv\n"
        "haptic-study export samples --db study.db --format parquet --out samples.parquet\n"
        "haptic-study export participant --db study.db --participant P02 --out P02-data",
        "Export every recorded 1 kHz record (of one session, or all) as one table, for pandas, R or SQL-free "
        "tools; the Python function is analysis.samples_frame",
    )
    esub = e.add_subparsers(dest="export", metavar="WHAT")
    esub.required = True
    es = add_command(
        esub, "samples", "every recorded record: session time, trial, forces, stylus, ages",
        "haptic-study export samples --db study.db --session 2 --out session2.csv\n"
        "haptic-study export samples --db study.db --format parquet --out samples.parquet\n"
        "haptic-study export samples --db study.db --session 2 --out - | head",
        "Every 1 kHz record of the recorded sessions (one session, or all) as one table, a row per record: the "
        "participant, session time, trial and phase (by name and code), the raw sensor wrench, the task force (the "
        "filtered compensated force the metrics use), the rendered force and gain, the stylus position, the sample "
        "and pose ages, the latency and the faults (bitmask and names); a unit ends every name (_N, _Nm, _s, _ms, "
        "_m) and FILE.codebook.csv beside the file describes every column (analysis.samples_frame returns the same "
        "as a DataFrame)",
    )
    es.add_argument("--db", required=True, metavar="PATH", help="study database")
    es.add_argument("--session", type=whole_number("--session", 1, SQLITE_INTEGER_MAX), default=None, metavar="ID",
                    help="one session (default: all)")
    es.add_argument("--format", choices=("csv", "parquet"), default="csv", help="file format (default csv)")
    es.add_argument("--arm", type=arm_name("--arm"), default=None, metavar="NAME",
                   help="a rig of several arms: the arm whose records to export, named in an arm column "
                        "(default: the task arm's)")
    es.add_argument("--out", required=True, metavar="FILE",
                    help="file to write (must not exist); - writes csv to standard output")
    es.set_defaults(handler=cmd_export)
    add_export_participant_parser(esub)  # everything about one participant (study_app/cli/export_participant_cmds.py)


# -- shared -------------------------------------------------------------------------------------------------
def _session(db_path: str, session_id: int, partial: bool = False, arm: str | None = None,
             ) -> tuple[Any, list[Any], Any]:
    """(open read-only database, its recorded segments -- of ``arm``, default the task arm --, the session's trials
    frame), or a one-line error.

    A damaged recording is that one-line error, or with ``partial`` its damaged blocks are left out and
    named on standard error (a partial result, stated as such).
    """
    from protocol.recording import RecordingDamaged
    from protocol.storage import StorageError, StudyReader
    from protocol.storage.recordings import read_segment, segments_of

    try:
        db = StudyReader(db_path, check=True)
    except StorageError as exc:
        raise CliError(str(exc)) from None
    info = db.session(session_id)
    if info is None:
        ids = db.session_ids()
        db.close()
        raise CliError(f"--session {session_id}: no such session in {db_path} (sessions: "
                         f"{', '.join(map(str, ids)) or 'none'}; haptic-study sessions --db PATH lists them)")
    row = (info.code, info.kind, info.status)
    try:
        key = db.arm_key(session_id, arm)
    except KeyError as exc:
        db.close()
        raise CliError(exc.args[0]) from None
    segs = segments_of(db, session_id, key) if db.schema_version >= 3 else []
    if not segs:
        db.close()
        raise CliError(f"--session {session_id}: was not recorded whole (it was stored by an earlier version, "
                         "which kept its trials' samples only); replay and plot-session need a recorded session")
    try:
        segments = [read_segment(db, session_id, s[0], skip_damaged=partial, arm=key) for s in segs]
    except RecordingDamaged as exc:
        db.close()
        raise CliError(f"--session {session_id} in {db_path}: {exc} (haptic-study check --db {db_path} lists "
                       "every damaged block)") from None
    for d in (d for seg in segments for d in seg.damage):
        print(f"haptic-study: recording damaged: {d.describe()}: left out, the result is partial", file=sys.stderr)
    from analysis.reading.load import frame_of  # pandas: not before the database was found good (a refusal stays cheap)

    trials = frame_of(db.recorded_trial_table(session_id))
    db.close()
    trials.insert(0, "code", row[0])
    trials.insert(1, "session_kind", row[1])
    return row, segments, trials


def _magnitude(cols: dict[str, np.ndarray], prefix: str) -> np.ndarray:
    import numpy as np

    return np.sqrt(cols[f"{prefix}_fx"] ** 2 + cols[f"{prefix}_fy"] ** 2 + cols[f"{prefix}_fz"] ** 2)


def _output_policy(call: Any) -> Any:
    """Run an output-policy call (foundation.outdir); its refusal or failure is one line (exit 2, or 1 mid-write)."""

    try:
        return call()
    except InputRefused as exc:
        raise CliError(str(exc), getattr(exc, "status", 2)) from None


# -- replay ---------------------------------------------------------------------------------------------------
def cmd_replay(args: argparse.Namespace) -> int:
    """``haptic-study replay``."""
    from foundation.outdir import check_output_folder, write_output_folder

    folder: dict[str, Any] = {"command": "replay", "marker": REPLAY_MARKER, "inputs": [args.db], "force": args.force}
    if args.force and not args.out:
        raise CliError("--force applies to --out DIR only (without --out, replay writes no folder)")
    if args.out:  # refused before the work, not after it
        _output_policy(lambda: check_output_folder(args.out, **folder))
    (code, kind, _), segments, trials = _session(args.db, args.session, arm=args.arm)
    outputs, exact = _replay_as_recorded(args.session, code, kind, segments)
    trade = _filter_trade(outputs, segments)
    changes = {k: v for k, v in (("filter_window", args.filter_window), ("f_scale_n", args.f_scale),
                                 ("f_max_n", args.f_max)) if v is not None}
    write_changes = _replay_with_changes(segments, trials, changes) if changes else None
    if args.out:
        def fill(out: Path) -> None:
            trade.round(6).to_csv(out / "filter_trade.csv", index=False)
            if write_changes is not None:
                write_changes(out)

        files = _output_policy(lambda: write_output_folder(args.out, fill, **folder))
        print(f"Files in {args.out}/: {', '.join(files)}")
    return 0 if all(exact) else 1


def _replay_as_recorded(session_id: int, code: str, kind: str, segments: list[Any]) -> tuple[list[Any], list[bool]]:
    """Replay every recorded run with its recorded settings and say whether it matched (outputs, exact per run)."""
    import numpy as np

    from pipeline.force.replay import replay

    n = sum(len(s.columns["tick"]) for s in segments)
    t0 = time.perf_counter()
    try:
        outputs = [replay(s.replay_inputs()) for s in segments]
    except ValueError as exc:  # a log entry this version cannot apply
        raise CliError(f"--session {session_id}: {exc}") from None
    wall = time.perf_counter() - t0
    exact = [all(np.array_equal(o.column(f"render_{a}"), s.columns[f"render_{a}"]) for a in ("fx", "fy", "fz"))
             and np.array_equal(o.force_n, s.columns["force_n"]) for o, s in zip(outputs, segments, strict=True)]
    gaps = [s.segment for s in segments if not s.continuous]
    print(f"Session {session_id} ({code}, {kind}): {len(segments)} recorded run{'s' if len(segments) != 1 else ''}, "
          f"{n:,} records ({n / 1000:.1f} s at 1 kHz), replayed in {wall:.1f} s")
    verdict = ("bit-identical to the recording" if all(exact) else
               f"DIFFERENT from the recording in run(s) "
               f"{[s.segment for s, ok in zip(segments, exact, strict=True) if not ok]}")
    print(f"  recorded settings: rendered force and task force {verdict}")
    if gaps:
        print(f"  note: run(s) {gaps} miss records (a gap the loop logged): replay after a gap is approximate")
    return outputs, exact


def _filter_trade(outputs: list[Any], segments: list[Any]) -> Any:
    """Print (and return) the filter's trade on this recording: noise at rest against delay in contact."""
    import numpy as np

    from analysis.stats.replay_compare import filter_trade
    from protocol.study.trial import PHASE_CODES, TrialPhase
    from protocol.tasks.window import CONTACT_THRESHOLD_N

    # the compensated force replay recomputed, at rest and in contact
    comp = np.concatenate([o.stage_force("comp") for o in outputs])
    phase = np.concatenate([s.columns["phase"] for s in segments])
    in_trial = np.concatenate([s.columns["trial_index"] for s in segments]) >= 0
    mag = np.linalg.norm(comp, axis=1)
    rest = (phase == PHASE_CODES[TrialPhase.PAUSE]) & (mag < 2 * CONTACT_THRESHOLD_N)
    contact = in_trial & (mag > 2 * CONTACT_THRESHOLD_N)
    trade = filter_trade(comp, rest, contact)
    recorded_w = segments[0].snapshot["framework"]["config"]["filter_window"]
    print(f"  the moving-average window on this recording ({int(rest.sum()):,} records at rest, "
          f"{int(contact.sum()):,} in contact; recorded with {recorded_w}):")
    print("    window  noise at rest (N RMS)  delay in contact (ms)  theory (ms)")
    for r in trade.itertuples():
        print(f"    {r.window:6d}  {r.noise_rms_N:21.5f}  {r.delay_ms + 0.0:21.1f}  {r.group_delay_ms:11.1f}")
    return trade


def _replay_with_changes(segments: list[Any], trials: Any, changes: dict[str, Any]) -> Any:
    """Replay with ``changes`` to the recorded settings; the rendered force's difference, trial by trial.

    Prints the table and returns ``write(folder)``, which writes it and the figure (for ``--out``).
    """
    import numpy as np

    from analysis.stats.replay_compare import trial_differences
    from pipeline.force.framework import framework_config_from_dict
    from pipeline.force.replay import replay

    what = ", ".join(f"{k} = {v:g}" for k, v in changes.items())
    other = []
    for s in segments:
        cfg = framework_config_from_dict(s.snapshot["framework"]["config"])
        try:
            cfg = dataclasses.replace(cfg, **changes)
        except ValueError as exc:
            raise CliError(str(exc)) from None
        other.append(replay(s.replay_inputs(), cfg))
    recorded = np.concatenate([_magnitude(s.columns, "render") for s in segments])
    replayed = np.concatenate([np.linalg.norm(o.stage_force("render"), axis=1) for o in other])
    run = 2**40  # ticks restart with each run of the session: make them unique across runs
    ticks = np.concatenate([s.columns["tick"] + s.segment * run for s in segments])
    trials = trials.assign(first_tick=trials["first_tick"] + trials["segment"] * run,
                           last_tick=trials["last_tick"] + trials["segment"] * run)
    diffs = trial_differences(trials, recorded, replayed, ticks)
    print(f"  with {what}: the rendered force, trial by trial (against the recording):")
    print("    trial  mode  outcome   RMS diff (N)  peak diff (N)  delay (ms)")
    for r in diffs.itertuples():
        print(f"    {r.trial_index + 1:5d}  {r.haptic_mode:>4}  {r.outcome:<8}  {r.rms_difference_N:12.4f}  "
              f"{r.peak_difference_N:13.4f}  {r.delay_ms:10.1f}")

    def write(out: Path) -> None:
        # named as the report's trials.csv names them (participant_code, trial_number first, a force's unit _N)
        table = diffs.drop(columns=["first_tick", "last_tick", "trial_index"]).rename(
            columns={"code": "participant_code", "target_force_n": "target_force_N"})
        table.insert(1, "trial_number", diffs["trial_index"].to_numpy() + 1)
        table.round(6).to_csv(out / "replay_trials.csv", index=False)
        from analysis.plots.figures import save
        from analysis.plots.session_figures import replay_figure

        t_s = np.concatenate([s.session_time_s for s in segments])
        worst = None
        if len(diffs) and diffs["rms_difference_N"].notna().any():
            w = diffs.loc[diffs["rms_difference_N"].idxmax()]
            worst = (float(w["started_at_s"]), float(w["ended_at_s"]),
                     f"trial {int(w['trial_index']) + 1} ({w['haptic_mode']}, {w['outcome']}): the largest difference")
        save(replay_figure(t_s, recorded, replayed, what, worst), out, "replay")

    return write


# -- plot-session ---------------------------------------------------------------------------------------------
def cmd_plot_session(args: argparse.Namespace) -> int:
    """``haptic-study plot-session``."""
    import numpy as np

    from foundation.outfile import check_output_file, write_output_file
    from protocol.study.labels import plural

    out = Path(args.out)
    if out.suffix.lower() not in _FIGURE_SUFFIXES:
        raise CliError(f"--out {out}: must end in .png, .pdf or .svg")
    _output_policy(lambda: check_output_file(out, command="plot-session"))  # before the work
    (code, kind, status), segments, trials = _session(args.db, args.session, partial=True, arm=args.arm)
    # matplotlib: once the session is known to be there
    from analysis.plots.figures import save_one
    from analysis.plots.session_figures import session_trace

    comp = np.concatenate([s.columns["force_n"] for s in segments])  # filtered and compensated, as recorded
    t_s = np.concatenate([s.session_time_s for s in segments])
    raw = np.concatenate([_magnitude(s.columns, "raw") for s in segments])
    rendered = np.concatenate([_magnitude(s.columns, "render") for s in segments])
    in_trial = np.concatenate([s.columns["trial_index"] for s in segments]) >= 0
    faults = np.concatenate([s.columns["faults"] for s in segments]).astype(np.int64)
    starts = [(float(r.started_at_s), f"{r.trial_index + 1} {r.target_label} {r.haptic_mode.upper()}")
              for r in trials.itertuples()]
    n_aborted = int((trials["outcome"] == "aborted").sum())
    title = (f"{code}, {kind} session {args.session}: {plural(len(trials), 'trial')} ({n_aborted} aborted), "
             f"{t_s[-1] - t_s[0]:.0f} s (trial number, target, haptics)") if len(t_s) else \
        f"{code}, session {args.session}: no records"
    if status == "running":  # a session a run left unfinished: what is drawn is not the whole designed session
        title += "; INTERRUPTED, not complete (resume it: run --continue or the GUI)"
    if args.arm:
        title += f"; arm {args.arm}"
    gone = [f"{d.t_first_s:.3f}–{d.t_last_s:.3f} s" for s in segments for d in s.damage]
    if gone:
        title += f"; PARTIAL: recording damaged at {', '.join(gone)}, left out"
    marks = _session_marks(args.db, args.session, segments, trials, float(t_s[-1]) if len(t_s) else 0.0)
    fig = session_trace(t_s, raw, comp, rendered, in_trial, title, starts, marks, faults)
    _output_policy(lambda: write_output_file(out, lambda path: save_one(fig, path), command="plot-session"))
    damaged = any(s.damage for s in segments)
    print(f"Wrote {out}{' (partial: the damaged records are left out)' if damaged else ''}")
    return 1 if damaged else 0


#: The step at which plot-session draws a trial's band (it asks the task for the band at each).
_BAND_STEP_S = 0.05


def _session_marks(db_path: str, session_id: int, segments: list[Any], trials: Any, t_end: float) -> Any:
    """What plot-session marks besides the force: target bands, aborted trials, pauses, resumes."""
    import json

    import numpy as np

    from analysis.plots.session_figures import SessionMarks
    from protocol.storage import StorageError, StudyReader
    from protocol.tasks.base import TrialTarget
    from protocol.tasks.registry import stored_task

    try:
        db = StudyReader(db_path, check=False)  # (checked by _session, which read the segments)
    except StorageError as exc:
        raise CliError(str(exc)) from None
    with db:
        stored = db.session(session_id)
        protocol_json = "{}" if stored is None else stored.protocol_json
        events = db.session_events(session_id, "experimenter", ("pause", "resume"))
    try:
        task = stored_task(json.loads(protocol_json), f"session {session_id} protocol")
    except ValueError as exc:
        raise CliError(str(exc)) from None
    bands = []
    for r in trials.itertuples():  # each trial's band asked of its task over the trial (a tracked target's moves)
        t0, t1 = float(r.started_at_s), float(r.ended_at_s)
        times = np.linspace(t0, max(t0, t1), max(2, int((t1 - t0) / _BAND_STEP_S) + 1))
        edges = task.screen(TrialTarget.of(r._asdict())).band_over(times - t0)
        if edges is not None:
            bands.append((times, *edges))
    aborted = [(float(r.started_at_s), float(r.ended_at_s), f"trial {r.trial_index + 1} aborted: {r.abort_reason}")
               for r in trials.itertuples() if r.outcome == "aborted"]
    pauses, since = [], None
    for t, what in events:
        if what == "pause" and since is None:
            since = float(t)
        elif what == "resume" and since is not None:
            pauses.append((since, float(t)))
            since = None
    if since is not None:
        pauses.append((since, t_end))
    resumes = [float(s.session_time_s[0]) for s in segments[1:] if len(s.session_time_s)]
    return SessionMarks(bands=bands, aborted=aborted, pauses=pauses, resumes=resumes)


# -- export ---------------------------------------------------------------------------------------------------
def _codebook_path(out: Path) -> Path:
    """Where an export's codebook goes: ``samples.csv`` → ``samples.csv.codebook.csv`` (one per file written, so a
    csv and a parquet export of one name each keep their own)."""
    return out.with_name(f"{out.name}.codebook.csv")


def cmd_export(args: argparse.Namespace) -> int:
    """``haptic-study export samples``: the labelled records, and their codebook beside the file."""
    from foundation.outfile import check_output_file, write_output_file

    to_stdout = args.out == "-"
    if to_stdout and args.format != "csv":
        raise CliError("--out -: standard output takes --format csv only; give a file for parquet")
    out = Path(args.out)
    book = _codebook_path(out)
    if not to_stdout:
        _output_policy(lambda: check_output_file(out, command="export"))  # before the work
        _output_policy(lambda: check_output_file(book, command="export", option="--out's codebook"))
    if args.format == "parquet":
        try:
            import pyarrow  # noqa: F401
        except ImportError:
            raise CliError("--format parquet needs pyarrow (pip install pyarrow); or use --format csv") from None
    if sys.stderr.isatty():  # a person waits: say what takes the time (a log gets only the result, or one error)
        print("export: reading the records ...", file=sys.stderr, flush=True)
    from analysis.reading.samples import codebook_frame, samples_frame

    try:
        frame = samples_frame(args.db, args.session, args.arm)
    except InputRefused as exc:
        raise CliError(str(exc)) from None
    if to_stdout:
        frame.to_csv(sys.stdout, index=False)
        for line in frame.attrs.get("damage", []):
            print(f"haptic-study: recording damaged: {line}: left out, the output is partial", file=sys.stderr)
        print("export: every column's unit and meaning: export to a file, its codebook is written beside it",
              file=sys.stderr)
        return 1 if frame.attrs.get("damage") else 0

    def fill(path: Path) -> None:
        if args.format == "csv":
            frame.to_csv(path, index=False)  # floats written as repr: they read back exactly
        else:
            frame.to_parquet(path, index=False)

    # at least ~6 bytes a value in CSV and ~2 in parquet (measured: 7.1 and 2.6): what surely cannot fit is
    # refused before writing; a disk that fills anyway is one line too
    need = int(frame.shape[0] * frame.shape[1] * (6 if args.format == "csv" else 2))
    _output_policy(lambda: write_output_file(out, fill, command="export", need_bytes=need))
    try:  # all or nothing: the data without its codebook is not left behind (the data file is this command's own)
        _output_policy(lambda: write_output_file(
            book, lambda p: codebook_frame(out.name, list(frame.columns)).to_csv(p, index=False), command="export",
            option="--out's codebook"))
    except BaseException:
        out.unlink(missing_ok=True)
        raise
    sessions = frame["session_id"].nunique() if len(frame) else 0
    damage = frame.attrs.get("damage", [])
    for line in damage:
        print(f"haptic-study: recording damaged: {line}: left out of {out}", file=sys.stderr)
    print(f"Wrote {out}: {len(frame):,} records of {sessions} session{'s' if sessions != 1 else ''}, "
          f"{len(frame.columns)} columns ({', '.join(frame.columns[:6])}, …); every column's unit and meaning "
          f"in {book}{'; partial: damaged records left out' if damage else ''}")
    return 1 if damage else 0
