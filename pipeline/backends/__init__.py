"""Real device backends: each implements the same Protocol (:mod:`pipeline.devices.interfaces`) as its simulated twin.

The device registry (:mod:`pipeline.devices.registry`) names the haptic and robot backends by module and imports
one only when a rig opens a device of its model.  Vendor SDKs (``rtde_receive``, ``pyOpenHaptics``, ``serial``) are
imported lazily inside the backend that needs them, so importing this package -- and running the simulated rig --
never requires them.
"""
