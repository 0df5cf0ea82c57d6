"""Qt windows of the experimenter app: layout and wiring only (behaviour is in :mod:`study_app.models`)."""
