"""Tests of the protocol file: the paper's defaults, every field's validation, the dict round trip."""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from tomlvalues import TOML_VALUES, replaced

from protocol.runner.session_setup import training_protocol as _training_protocol
from protocol.study.config import (
    ABORT_POLICIES,
    MODES,
    ORDERINGS,
    ProtocolConfig,
    ProtocolError,
    Target,
    TrainingConfig,
    TrialTiming,
    default_protocol,
    load_protocol,
    protocol_from_dict,
)
from protocol.tasks.force_regulation import ForceRegulation

DEFAULT_TEXT = resources.files("protocol.study").joinpath("default.toml").read_text(encoding="utf-8")


def _write_variant(tmp_path: Path, old: str, new: str, name: str = "study.toml") -> Path:
    """The default protocol file with exactly one occurrence of ``old`` replaced by ``new``."""
    assert DEFAULT_TEXT.count(old) == 1, f"{old!r} must occur exactly once in default.toml"
    p = tmp_path / name
    p.write_text(DEFAULT_TEXT.replace(old, new), encoding="utf-8")
    return p


def _error_of(path: Path) -> str:
    with pytest.raises(ProtocolError) as info:
        load_protocol(path)
    msg = str(info.value)
    assert "\n" not in msg, f"message must be a single line: {msg!r}"
    assert path.name in msg
    return msg


# -- the paper's protocol -------------------------------------------------------------------------
def test_default_protocol_has_the_papers_values():
    p = default_protocol()
    assert p.targets == (Target("GENTLE", 0.6), Target("FIRM", 1.2))
    assert p.modes == ("on", "off")
    assert p.trials_per_cell == 5
    assert p.trials_per_participant == 20
    assert p.ordering == "random"
    assert p.abort_policy == "append"
    assert p.trial == TrialTiming(max_trial_s=12.0, pause_s=2.0, cue_s=1.0)
    assert p.task == ForceRegulation(tolerance_fraction=0.10, hold_s=1.0)  # no [task] table: the paper's task
    assert p.training == TrainingConfig(enabled=True, seconds_per_target_per_mode=20.0, live_force_aid=True)
    assert p.version == 1
    assert p.name == "Shaker & Erden force regulation"


def test_default_protocol_fields_have_exact_types():
    p = default_protocol()
    assert type(p.trials_per_cell) is int
    assert all(type(t.force_n) is float for t in p.targets)
    assert isinstance(p.task, ForceRegulation)
    assert type(p.task.hold_s) is float and type(p.trial.max_trial_s) is float
    assert type(p.training.enabled) is bool


def test_target_lookup_by_label():
    p = default_protocol()
    assert p.target("FIRM") == Target("FIRM", 1.2)
    with pytest.raises(KeyError):
        p.target("gentle")


def test_loading_a_copy_of_the_default_file_gives_the_default(tmp_path):
    path = tmp_path / "copy.toml"
    path.write_text(DEFAULT_TEXT, encoding="utf-8")
    assert load_protocol(path) == default_protocol()
    assert load_protocol(str(path)) == default_protocol()


def test_omitted_optional_tables_take_the_papers_defaults(tmp_path):
    path = tmp_path / "minimal.toml"
    path.write_text('[[targets]]\nlabel = "GENTLE"\nforce_n = 0.6\n', encoding="utf-8")
    p = load_protocol(path)
    assert p.name == "unnamed protocol"
    assert p.targets == (Target("GENTLE", 0.6),)
    assert p.modes == ("on", "off")
    assert p.trials_per_cell == 5
    assert p.trials_per_participant == 10
    assert (p.ordering, p.abort_policy) == ("random", "append")
    assert p.trial == TrialTiming()
    assert p.training == TrainingConfig()


# -- validation: one bad field per file -----------------------------------------------------------
# (id, text in default.toml, replacement, the message after "<file>: ")
BAD_FIELDS = [
    ("negative hold", "hold_s = 1.0 ", "hold_s = -1.0 ",
     "trial.hold_s = -1.0: must be a number > 0 and ≤ 60"),
    ("zero hold", "hold_s = 1.0 ", "hold_s = 0.0 ",
     "trial.hold_s = 0.0: must be a number > 0 and ≤ 60"),
    ("hold equal to the cap", "hold_s = 1.0 ", "hold_s = 12.0 ",
     "trial.hold_s = 12.0: must be shorter than trial.max_trial_s = 12"),
    ("hold longer than the cap", "max_trial_s = 12.0 ", "max_trial_s = 0.5 ",
     "trial.hold_s = 1.0: must be shorter than trial.max_trial_s = 0.5"),
    # values valid alone but not together (issue 22): the ON trial must hold the feedback's ramp-in, the pause its
    # ramp-out (both the safety stage's, pipeline/force/safety.py)
    ("a trial shorter than ramp-in + hold", "max_trial_s = 12.0 ", "max_trial_s = 1.2 ",
     "trial.max_trial_s = 1.2: must be at least trial.hold_s = 1 + the feedback's 0.5 s ramp-in "
     "(safety.ramp_in_s) = 1.5 s when design.modes has 'on': a shorter haptics-ON trial would be judged at a "
     "feedback gain below 1"),
    ("a training trial shorter than ramp-in + hold", "seconds_per_target_per_mode = 20.0",
     "seconds_per_target_per_mode = 1.25", "training.seconds_per_target_per_mode = 1.25: must be at least "
     "trial.hold_s = 1 + the feedback's 0.5 s ramp-in (safety.ramp_in_s) = 1.5 s when design.modes has 'on': a "
     "shorter haptics-ON trial would be judged at a feedback gain below 1"),
    ("a pause shorter than the ramp-out", "pause_s = 2.0 ", "pause_s = 0.03 ",
     "trial.pause_s = 0.03: must be at least the feedback's 0.04 s ramp-out (safety.fault_ramp_s) when design.modes "
     "has 'on': otherwise a trial is cued while the last one's force still fades out"),
    ("tolerance 0.7", "tolerance_fraction = 0.10 ", "tolerance_fraction = 0.7 ",
     "trial.tolerance_fraction = 0.7: must be a number > 0 and ≤ 0.5"),
    ("tolerance as text", "tolerance_fraction = 0.10 ", 'tolerance_fraction = "10%" ',
     "trial.tolerance_fraction = '10%': must be a number > 0 and ≤ 0.5"),
    ("negative pause", "pause_s = 2.0 ", "pause_s = -2.0 ",
     "trial.pause_s = -2.0: must be a number from 0 to 600"),
    ("infinite cap", "max_trial_s = 12.0 ", "max_trial_s = inf ",
     "trial.max_trial_s = inf: must be a number > 0 and ≤ 600"),
    ("unknown ordering", 'ordering = "random"', 'ordering = "latin_square"',
     "design.ordering = 'latin_square': allowed values: random, blocked_by_mode, counterbalanced"),
    ("unknown abort policy", 'abort_policy = "append"', 'abort_policy = "drop"',
     "design.abort_policy = 'drop': allowed values: append, reinsert"),
    ("duplicate labels", 'label = "FIRM"', 'label = "GENTLE"',
     "targets = ['GENTLE', 'GENTLE']: labels must be unique"),
    ("lower-case label", 'label = "GENTLE"', 'label = "gentle"',
     "targets[0].label = 'gentle': must be an upper-case word of 1–16 letters/digits/_ (e.g. GENTLE)"),
    ("label with a trailing newline", 'label = "FIRM"', 'label = "FIRM\\n"',
     "targets[1].label = 'FIRM\\n': must be an upper-case word of 1–16 letters/digits/_ (e.g. GENTLE)"),
    ("label of 17 characters", 'label = "FIRM"', 'label = "ABCDEFGHIJKLMNOPQ"',
     "targets[1].label = 'ABCDEFGHIJKLMNOPQ': must be an upper-case word of 1–16 letters/digits/_ (e.g. GENTLE)"),
    ("zero force", "force_n = 1.2", "force_n = 0.0",
     "targets[1].force_n = 0.0: must be a number > 0 and ≤ 20"),
    ("modes on twice", 'modes = ["on", "off"]', 'modes = ["on", "on"]',
     "design.modes = ['on', 'on']: must be a non-empty list of distinct values from 'on', 'off'"),
    ("unknown mode", 'modes = ["on", "off"]', 'modes = ["on", "vibro"]',
     "design.modes = ['on', 'vibro']: must be a non-empty list of distinct values from 'on', 'off'"),
    ("no modes", 'modes = ["on", "off"]', "modes = []",
     "design.modes = []: must be a non-empty list of distinct values from 'on', 'off'"),
    ("trials_per_cell 0", "trials_per_cell = 5 ", "trials_per_cell = 0 ",
     "design.trials_per_cell = 0: must be a whole number from 1 to 100"),
    ("trials_per_cell 2.5", "trials_per_cell = 5 ", "trials_per_cell = 2.5 ",
     "design.trials_per_cell = 2.5: must be a whole number from 1 to 100"),
    ("trials_per_cell true", "trials_per_cell = 5 ", "trials_per_cell = true ",
     "design.trials_per_cell = true: must be a whole number from 1 to 100"),
    ("unknown top-level key", 'name = "Shaker & Erden force regulation"',
     'name = "Shaker & Erden force regulation"\ncolour = "red"',
     "colour = 'red': unknown field; allowed: counterbalance, covariates, design, feedback, groups, lsl, name, part, "
     "parts, questionnaires, targets, task, training, trial, version, visits"),
    ("typo inside [trial]", "hold_s = 1.0 ", "hold_sec = 1.0 ",
     "trial.hold_sec = 1.0: unknown field; allowed: cue_s, hold_s, max_trial_s, pause_s, tolerance_fraction"),
    ("typo inside [design]", "trials_per_cell = 5 ", "trials_per_cel = 5 ",
     "design.trials_per_cel = 5: unknown field; "
     "allowed: abort_policy, modes, ordering, task_arm, trials_per_cell"),
    ("unknown key in a target", 'label = "FIRM"', 'label = "FIRM"\nforce = 1.2',
     "targets[1].force = 1.2: unknown field; allowed: force_n, label"),
    ("training enabled as text", "enabled = true", 'enabled = "yes"',
     "training.enabled = 'yes': must be true or false"),
    ("version 2", "version = 1", "version = 2",
     "version = 2: this software reads protocol version 1"),
    ("empty name", 'name = "Shaker & Erden force regulation"', 'name = "  "',
     "name = '  ': must be a non-empty string"),
    # types: in Python True is an int (True == 1) and 1.0 == 1, so both must be refused explicitly
    ("version true", "version = 1", "version = true",
     "version = true: this software reads protocol version 1"),
    ("version 1.0", "version = 1", "version = 1.0",
     "version = 1.0: this software reads protocol version 1"),
    ("name as a number", 'name = "Shaker & Erden force regulation"', "name = 3",
     "name = 3: must be a non-empty string"),
    ("label as a number", 'label = "FIRM"', "label = 7",
     "targets[1].label = 7: must be an upper-case word of 1–16 letters/digits/_ (e.g. GENTLE)"),
    ("force as a boolean", "force_n = 1.2", "force_n = true",
     "targets[1].force_n = true: must be a number > 0 and ≤ 20"),
    ("force a 30-digit integer", "force_n = 1.2", "force_n = 123456789012345678901234567890",
     "targets[1].force_n = 123456789012345678901234567890: must be a number > 0 and ≤ 20"),
    ("hold as a date", "hold_s = 1.0 ", "hold_s = 1979-05-27 ",
     "trial.hold_s = datetime.date(1979, 5, 27): must be a number > 0 and ≤ 60"),
    ("modes nested in a list", 'modes = ["on", "off"]', 'modes = [["on"]]',
     "design.modes = [['on']]: must be a non-empty list of distinct values from 'on', 'off'"),
    ("a mode as a number", 'modes = ["on", "off"]', 'modes = ["on", 1]',
     "design.modes = ['on', 1]: must be a non-empty list of distinct values from 'on', 'off'"),
    ("modes as a string", 'modes = ["on", "off"]', 'modes = "on"',
     "design.modes = 'on': must be a non-empty list of distinct values from 'on', 'off'"),
    ("ordering in a list", 'ordering = "random"', 'ordering = ["random"]',
     "design.ordering = ['random']: allowed values: random, blocked_by_mode, counterbalanced"),
    ("trials_per_cell beyond 64 bits", "trials_per_cell = 5 ", "trials_per_cell = 99999999999999999999 ",
     "design.trials_per_cell = 99999999999999999999: must be a whole number from 1 to 100"),
    ("live aid as 1", "live_force_aid = true", "live_force_aid = 1",
     "training.live_force_aid = 1: must be true or false"),
    # the training session runs trials capped at seconds_per_target_per_mode: it must be a valid cap
    ("training trials shorter than the hold", "seconds_per_target_per_mode = 20.0", "seconds_per_target_per_mode = 0.5",
     "training.seconds_per_target_per_mode = 0.5: must be longer than trial.hold_s = 1 "
     "(each training trial lasts this long and must leave time to complete a hold)"),
    ("training trials as long as the hold", "seconds_per_target_per_mode = 20.0", "seconds_per_target_per_mode = 1",
     "training.seconds_per_target_per_mode = 1.0: must be longer than trial.hold_s = 1 "
     "(each training trial lasts this long and must leave time to complete a hold)"),
    ("training trials over 600 s", "seconds_per_target_per_mode = 20.0", "seconds_per_target_per_mode = 601",
     "training.seconds_per_target_per_mode = 601: must be a number > 0 and ≤ 600"),
]


@pytest.mark.parametrize(("old", "new", "expected"), [b[1:] for b in BAD_FIELDS], ids=[b[0] for b in BAD_FIELDS])
def test_bad_field_is_refused_naming_file_field_value_and_what_is_allowed(tmp_path, old, new, expected):
    path = _write_variant(tmp_path, old, new)
    assert _error_of(path) == f"{path}: {expected}"


def test_the_issue_s_2_ms_trial_is_refused_and_an_off_only_design_needs_no_ramp(tmp_path):
    text = DEFAULT_TEXT.replace("max_trial_s = 12.0 ", "max_trial_s = 0.002 ").replace("hold_s = 1.0 ",
                                                                                       "hold_s = 0.001 ")
    path = tmp_path / "short.toml"
    path.write_text(text, encoding="utf-8")
    assert _error_of(path).startswith(f"{path}: trial.max_trial_s = 0.002: must be at least trial.hold_s = 0.001 + "
                                      "the feedback's 0.5 s ramp-in (safety.ramp_in_s) = 0.501 s")
    off_only = text.replace('modes = ["on", "off"]', 'modes = ["off"]').replace("cue_s = 1.0 ", "cue_s = 0.001 ")
    path.write_text(off_only, encoding="utf-8")  # (a cue shorter than the 2 ms cap, as every cue must be)
    assert load_protocol(path).trial.max_trial_s == 0.002  # no feedback, no ramp: only the hold must fit


def test_the_ramps_have_one_definition():
    from pipeline.force.safety import SafetyConfig
    from protocol.study.delivery import DeliveryLimits

    limits, safety = DeliveryLimits(), SafetyConfig()
    assert (limits.feedback_ramp_in_s, limits.feedback_ramp_out_s) == (safety.ramp_in_s, safety.fault_ramp_s)


def test_non_toml_text_is_refused(tmp_path):
    path = tmp_path / "notes.toml"
    path.write_text("this is not toml\n", encoding="utf-8")
    assert _error_of(path) == (
        f"{path}: not valid TOML (Expected '=' after a key in a key/value pair (at line 1, column 6))"
    )


def test_an_integer_too_long_for_python_is_refused_as_toml(tmp_path):
    path = tmp_path / "long.toml"
    path.write_text(DEFAULT_TEXT.replace("trials_per_cell = 5 ", "trials_per_cell = " + "9" * 5000 + " "),
                    encoding="utf-8")
    assert _error_of(path).startswith(f"{path}: not valid TOML (Exceeds the limit (4300 digits) for integer string")


def test_missing_file_is_refused(tmp_path):
    path = tmp_path / "absent.toml"
    assert _error_of(path) == f"{path}: no such protocol file"
    assert not path.exists()


def test_a_folder_instead_of_a_file_is_refused(tmp_path):
    path = tmp_path / "folder.toml"
    path.mkdir()
    assert _error_of(path).startswith(f"{path}: cannot read the protocol file (")


def test_non_utf8_file_is_refused(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes('name = "Studie für Kraft"\n'.encode("latin-1"))
    assert _error_of(path).startswith(f"{path}: cannot read the protocol file (")


def test_no_targets_is_refused(tmp_path):
    path = tmp_path / "empty.toml"
    path.write_text('name = "x"\n', encoding="utf-8")
    assert _error_of(path) == f"{path}: targets = None: must be a list of 1 to 8 [[targets]] tables"


def test_trial_as_a_value_instead_of_a_table_is_refused():
    d = default_protocol().to_dict()
    d["trial"] = 3
    with pytest.raises(ProtocolError) as info:
        protocol_from_dict(d, "inline")
    assert str(info.value) == "inline: trial = 3: must be a table"


@pytest.mark.parametrize("per_cell", [1, 100])
def test_trials_per_cell_bounds_are_inclusive(tmp_path, per_cell):
    path = _write_variant(tmp_path, "trials_per_cell = 5 ", f"trials_per_cell = {per_cell} ")
    assert load_protocol(path).trials_per_cell == per_cell


def test_tolerance_half_is_allowed_and_pause_zero_is_allowed_without_feedback(tmp_path):
    text = DEFAULT_TEXT.replace("tolerance_fraction = 0.10 ", "tolerance_fraction = 0.5 ").replace(
        "pause_s = 2.0 ", "pause_s = 0 "
    ).replace('modes = ["on", "off"]', 'modes = ["off"]')
    path = tmp_path / "edges.toml"
    path.write_text(text, encoding="utf-8")
    p = load_protocol(path)
    assert isinstance(p.task, ForceRegulation)
    assert (p.task.tolerance_fraction, p.trial.pause_s) == (0.5, 0.0)
    assert type(p.trial.pause_s) is float


# -- round trip -----------------------------------------------------------------------------------
def test_to_dict_round_trips_the_default():
    p = default_protocol()
    assert protocol_from_dict(p.to_dict()) == p


def test_to_dict_round_trips_a_non_default_protocol():
    p = ProtocolConfig(
        name="pilot",
        targets=(Target("LIGHT", 0.3), Target("MEDIUM", 0.9), Target("HARD_2", 2.5)),
        modes=("off",),
        trials_per_cell=3,
        ordering="counterbalanced",
        abort_policy="reinsert",
        trial=TrialTiming(max_trial_s=8.0, pause_s=0.0, cue_s=0.0),
        training=TrainingConfig(enabled=False, seconds_per_target_per_mode=5.0, live_force_aid=False),
        task=ForceRegulation(tolerance_fraction=0.2, hold_s=0.5),
    )
    d = p.to_dict()
    assert d == {
        "name": "pilot",
        "version": 1,
        "targets": [
            {"label": "LIGHT", "force_n": 0.3},
            {"label": "MEDIUM", "force_n": 0.9},
            {"label": "HARD_2", "force_n": 2.5},
        ],
        "design": {"modes": ["off"], "trials_per_cell": 3, "ordering": "counterbalanced", "abort_policy": "reinsert"},
        "trial": {"tolerance_fraction": 0.2, "hold_s": 0.5, "max_trial_s": 8.0, "pause_s": 0.0, "cue_s": 0.0},
        "training": {"enabled": False, "seconds_per_target_per_mode": 5.0, "live_force_aid": False, "required": False},
    }
    assert protocol_from_dict(d) == p
    assert p.trials_per_participant == 9


def test_to_json_is_canonical():
    p = default_protocol()
    assert p.to_json() == protocol_from_dict(p.to_dict()).to_json()
    assert p.to_json().startswith('{"design": {"abort_policy": "append", "modes": ["on", "off"]')


# -- any value of any type in any field -----------------------------------------------------------
_DEFAULT_DICT = default_protocol().to_dict()
FIELDS: list[tuple[str | int, ...]] = [
    ("name",), ("version",), ("targets",), ("targets", 0), ("targets", 0, "label"), ("targets", 0, "force_n"),
    ("design",), ("design", "modes"), ("design", "modes", 0),
    *(("design", k) for k in ("trials_per_cell", "ordering", "abort_policy")),
    ("trial",), *(("trial", k) for k in _DEFAULT_DICT["trial"]),
    ("training",), *(("training", k) for k in _DEFAULT_DICT["training"]),
]


def _assert_well_typed(p: ProtocolConfig) -> None:
    assert type(p.name) is str and p.name and type(p.version) is int
    assert all(type(t.label) is str and type(t.force_n) is float for t in p.targets)
    assert type(p.modes) is tuple and all(m in MODES for m in p.modes)
    assert type(p.trials_per_cell) is int and p.ordering in ORDERINGS and p.abort_policy in ABORT_POLICIES
    own = set(p.task.trial_fields)  # the task's fields of [trial] are its own (the paper's band and hold)
    assert all(type(getattr(p.task if k in own else p.trial, k)) is float for k in _DEFAULT_DICT["trial"])
    assert type(p.training.enabled) is bool and type(p.training.live_force_aid) is bool
    assert type(p.training.seconds_per_target_per_mode) is float


@pytest.mark.parametrize("path", FIELDS, ids=[".".join(map(str, f)) for f in FIELDS])
@settings(max_examples=80)
@given(value=TOML_VALUES)
def test_any_toml_value_in_any_field_is_a_one_line_error_or_a_well_typed_protocol(path, value):
    d = replaced(_DEFAULT_DICT, path, value)
    try:
        p = protocol_from_dict(d, "any.toml")
    except ProtocolError as exc:  # never another exception
        msg = str(exc)
        assert msg.startswith("any.toml: ") and "\n" not in msg and str(path[0]) in msg
        return
    _assert_well_typed(p)
    assert protocol_from_dict(json.loads(p.to_json())) == p  # what a session stores reads back


@given(
    hold_s=st.floats(0.0, 61.0), trial_beyond_hold_s=st.floats(0.0, 601.0),
    training_beyond_hold_s=st.floats(0.0, 601.0),
    enabled=st.booleans(),
)
def test_every_accepted_protocol_has_a_training_protocol_that_is_valid_and_resumable(
        hold_s, trial_beyond_hold_s, training_beyond_hold_s, enabled):
    """The protocol a training session runs and stores (the headless study runner) reads back: a resume can always load
    it.

    The caps are drawn as the hold plus a margin, and training is required exactly when
    it is enabled: drawn on their own, most protocols would be refused by a cross-field
    rule and the test would mostly discard.
    """
    max_trial_s, seconds = hold_s + trial_beyond_hold_s, hold_s + training_beyond_hold_s
    d = replaced(replaced(_DEFAULT_DICT, ("trial", "hold_s"), hold_s), ("trial", "max_trial_s"), max_trial_s)
    d = replaced(replaced(d, ("training", "seconds_per_target_per_mode"), seconds), ("training", "enabled"), enabled)
    d = replaced(d, ("training", "required"), enabled)  # required without training is refused on its own
    try:
        p = protocol_from_dict(d)
    except ProtocolError:
        assume(False)
    training = _training_protocol(p)
    assert protocol_from_dict(json.loads(training.to_json()), "stored training protocol") == training


def test_the_ramps_of_the_pipeline_a_study_runs_with_must_fit_its_trials() -> None:
    """run --set ramp_in_s=20 with 12 s trials would judge every ON trial at a gain below 1: refused in one line."""
    from pipeline.force.safety import SafetyConfig

    p = default_protocol()
    p.check_ramps(SafetyConfig())  # the paper's pipeline: the file's own check
    p.check_ramps(SafetyConfig(ramp_in_s=10.0))  # 10 s + the 1 s hold fit a 12 s trial (and the 20 s training)
    with pytest.raises(ProtocolError, match=r"^protocol: trial\.max_trial_s = 12\.0: must be at least trial\.hold_s "
                                            r"= 1 \+ the feedback's 11.5 s ramp-in"):
        p.check_ramps(SafetyConfig(ramp_in_s=11.5))
