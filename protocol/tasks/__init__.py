"""The tasks: each trial's kind, one module each (:mod:`protocol.tasks.force_regulation` is the paper's), asked by
everything that runs, shows or analyses a trial (:mod:`protocol.tasks.base`, the seam).

The floor above the metrics and below the study: a task knows the metric registry (the metrics it produces) and the
pipeline's vocabulary (the aim it gives a simulated participant), not the schedule, the storage or the runner.
"""
