"""The small plan of several parts the tests of ``[[parts]]`` share (tests/protocol/test_parts.py,
tests/test_parts_study.py)."""

#: The plan's study tables and its practice part (tests/test_visits_study.py builds a schedule on them).
STUDY = """name = "tiny plan"
[[targets]]
label = "GENTLE"
force_n = 0.6
[design]
modes = ["on", "off"]
trials_per_cell = 1
[trial]
max_trial_s = 2.0
hold_s = 0.3
pause_s = 0.3
[training]
enabled = true
seconds_per_target_per_mode = 1.0
[[parts]]
name = "practice"
session = "training"
"""
#: A small plan: practice, then three test parts counterbalanced (the tests of the headless run use it too).
PLAN = STUDY + """[[parts]]
name = "regulation"
[[parts]]
name = "tracking"
[parts.task]
kind = "force_tracking"
profile = "sine"
offset_n = 0.8
amplitude_n = 0.3
frequency_hz = 0.5
duration_s = 2.0
lead_in_s = 0.5
band_n = 0.1
[parts.trial]
max_trial_s = 3.0
[parts.training]
enabled = false
[[parts]]
name = "firm"
[[parts.targets]]
label = "FIRM"
force_n = 1.2
[counterbalance]
parts = ["regulation", "tracking", "firm"]
"""
