"""How a simulated participant answers a questionnaire: a documented rule, the same answers from the same seed.

So a simulated study has questionnaires to analyse, the simulated participant answers them by this rule
(docs/study-design.md, *Questionnaires*), not by chance alone:

* **NASA-TLX ratings.** Each subscale has a typical rating for this force task (:data:`TLX_TYPICAL`: a task of
  little physical effort, demanding attention); each participant rates the whole task higher or lower than
  another (their own offset, normal, s.d. :data:`PERSON_SD`, the same in every block); **with haptic feedback ON
  every rating is :data:`HAPTICS_ON_RELIEF` lower** -- the force is felt, so less of it must be read off the screen
  and held in mind, the relief haptic feedback is meant to bring -- and each rating has its own noise (normal,
  s.d. :data:`ITEM_SD`).  The sum is rounded to the scale's step (5) and kept within 0–100.  A questionnaire
  asked after the session (both modes) gets half the relief.
* **NASA-TLX weights.** Each participant has a fixed importance per subscale (normal, drawn once from their
  seed) and, in each of the 15 pairs, chooses the subscale of greater importance: consistent weights, a
  permutation of 0–5.
* **Likert items.** The middle of the item's scale, plus noise (normal, s.d. a sixth of the scale's range),
  rounded and kept on the scale; no effect of the mode (the rule does not know which end of a lab's own item
  is better).

The draws come from streams of their own (the participant's seed, 44, the block), so nothing else the simulated
participant does changes.
"""

from __future__ import annotations

import numpy as np

from protocol.study import tlx
from protocol.study.questionnaires import SESSION, Prompt

__all__ = ["HAPTICS_ON_RELIEF", "ITEM_SD", "PERSON_SD", "TLX_TYPICAL", "simulated_answers"]

#: A typical rating of each NASA-TLX subscale for the force-regulation task with haptics OFF.
TLX_TYPICAL = {"mental": 55.0, "physical": 35.0, "temporal": 40.0, "performance": 45.0, "effort": 55.0,
               "frustration": 40.0}
#: How much lower every rating is with haptic feedback ON (rating points).
HAPTICS_ON_RELIEF = 12.0
#: The spread of participants' overall level, and of one rating around it (rating points).
PERSON_SD = 10.0
ITEM_SD = 7.5
_BLOCK_CODES = {"on": 1, "off": 2, SESSION: 3}


def simulated_answers(prompt: Prompt, participant_seed: int) -> dict[str, float | str]:
    """The answers of the simulated participant with ``participant_seed`` to ``prompt`` (see the module's rule)."""
    q = prompt.questionnaire
    rng = np.random.default_rng([participant_seed, 44, _BLOCK_CODES.get(prompt.block, 0)])
    if q.kind == "likert":
        out: dict[str, float | str] = {}
        for item in q.items:
            assert item.scale is not None  # (every Likert item has one: refused at the file otherwise)
            lo, hi = item.scale.lo, item.scale.hi
            v = (lo + hi) / 2 + rng.normal(0.0, (hi - lo) / 6)
            out[item.id] = float(min(max(round(v), lo), hi))
        return out
    person = np.random.default_rng([participant_seed, 44])
    offset = float(person.normal(0.0, PERSON_SD))
    importance = {s.id: float(person.normal()) for s in tlx.SUBSCALES}
    relief = {"on": HAPTICS_ON_RELIEF, "off": 0.0}.get(prompt.block, HAPTICS_ON_RELIEF / 2)
    answers: dict[str, float | str] = {}
    for s in tlx.SUBSCALES:
        v = TLX_TYPICAL[s.id] + offset - relief + rng.normal(0.0, ITEM_SD)
        answers[s.id] = float(min(max(tlx.RATING_STEP * round(v / tlx.RATING_STEP), 0), tlx.RATING_MAX))
    if q.weighted:
        for a, b in tlx.pairs():
            answers[tlx.pair_id(a, b)] = a if importance[a] >= importance[b] else b
    return answers
