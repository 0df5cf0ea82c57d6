"""A pure-Python stand-in for pyOpenHaptics 1.0.1 with one Touch, for engine-process tests on machines without libHD.

It offers exactly the names ``pipeline.backends.hdapi.PyOpenHapticsApi`` uses (``hdMakeCurrentDevice``
and a handle per ``hdInitDevice`` too, for several devices) and runs the scheduled servo callback at ~1 kHz
in a thread, as OpenHaptics' scheduler would.
"""
