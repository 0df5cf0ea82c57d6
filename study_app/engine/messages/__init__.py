"""Commands to and events from the study engine process (small typed records, no strings as topics).

The GUI sends a command over the engine's pipe; the engine publishes events
on its queue.  Both sides import this package, so every message is a frozen
dataclass that pickles across the process boundary.  Times called ``t_s``
are sample times of the loop records (the ``t_s`` column of the ring), so a
display can relate an event to the plotted samples whatever the clock speed.

The messages are kept by subsystem, each module with its commands and its events: a session's
(:mod:`~study_app.engine.messages.session`), the commissioning chain's
(:mod:`~study_app.engine.messages.commissioning`) and the engine's own
(:mod:`~study_app.engine.messages.engine`: its lifetime, health and faults, the stylus's driver, the jaw).  Both
sides read them from here: ``from study_app.engine import messages as m``, then ``m.StartSession``.
"""

from __future__ import annotations

from study_app.engine.messages import commissioning, engine, session
from study_app.engine.messages.commissioning import *  # noqa: F403  (its __all__: the names below)
from study_app.engine.messages.engine import *  # noqa: F403
from study_app.engine.messages.session import *  # noqa: F403

__all__: list[str] = []
__all__ += commissioning.__all__
__all__ += engine.__all__
__all__ += session.__all__
