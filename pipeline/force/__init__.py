"""The force path of Algorithm 1: compensation, moving average, rotations, tanh scaling and safety, one tick at a time
(:class:`~pipeline.force.framework.HapticFramework`), and its offline replay."""
