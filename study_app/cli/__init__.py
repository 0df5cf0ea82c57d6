"""The ``haptic-study`` command line: :mod:`study_app.cli.main` builds the parser; each command group registers its
parser beside its handler (``*_cmds.py``)."""
