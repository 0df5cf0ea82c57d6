"""``python -m study_app.cli``: the ``haptic-study`` command without its installed script (the module name every
version of this product answers to, so a benchmark can run an older source tree the same way)."""

import sys

from study_app.cli.main import main

sys.exit(main())
