"""The devices: their interfaces (what the loop sees), the device registry (every haptic device and robot model: its
limits, its backend, its twin), the rig and its arms, the haptic output contract, the jaw and teleoperation. The
simulated twins are in :mod:`pipeline.sim`, the real backends in :mod:`pipeline.backends`."""
