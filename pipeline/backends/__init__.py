"""Real device backends: each implements the same Protocol (:mod:`pipeline.devices.interfaces`) as its simulated twin.

Vendor SDKs (``rtde_receive``, ``pyOpenHaptics``, ``serial``) are imported
lazily inside the backend that needs them, so importing this package -- and
running the simulated rig -- never requires them.
"""
