"""The shared-memory ring of loop records, where the runtime's modules and their readers have always found it.

The ring itself is :mod:`pipeline.core.ring`, on the lowest floor, because the device back-ends use it too (the UR
pose stream's own process writes its poses into one, :mod:`pipeline.backends.ur_process`) and a back-end may not
import up to the runtime.
"""

from pipeline.core.ring import RingBuffer, RingReadResult

__all__ = ["RingBuffer", "RingReadResult"]
