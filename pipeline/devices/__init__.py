"""The devices: their interfaces (what the loop sees), the rig, the real rig opened from the hardware settings, the
Touch's output, the jaw and teleoperation. The simulated twins are in :mod:`pipeline.sim`, the real backends in
:mod:`pipeline.backends`."""
