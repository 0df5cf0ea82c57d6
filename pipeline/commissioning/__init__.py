"""The commissioning maths and the commissioning service: payload identification and its pose advice, the
tool-centre-point calibration, the frame check, the calibration file that stores their results, and
:mod:`pipeline.commissioning.steps`, which judges each step (limits, verdicts, refusals, what goes on record) for
both front ends. No device I/O: the front ends that gather the data are :mod:`study_app.engine.commissioning` (the
GUI's wizard, from the ring) and :mod:`study_app.cli.calibrate_cmds` (``haptic-study calibrate``, from the
devices)."""
