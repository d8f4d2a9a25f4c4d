"""Names of explicit constraint equations, from their descriptions (issue 17)."""
from __future__ import annotations

import re

_WORD = re.compile(r"[^0-9A-Za-z_]+")


def constraint_name(doc: str, loop_values, item: int | None, taken) -> str | None:
    """A constraint's name from its description ("rod" -> rod; words joined by _, loop indices
    and vector items appended: "rod" in `for i` -> rod_1, rod_2), or None (then c<k>) when the
    description is empty, not a word, or the name is taken by a constraint in ``taken``."""
    base = _WORD.sub("_", (doc or "").strip()).strip("_")
    if not base or not base.isidentifier() or len(base) > 40:
        return None
    parts = [base] + [str(v) for v in loop_values] + ([str(item + 1)] if item is not None else [])
    nm = "_".join(parts)
    return None if any(c.name == nm or c.alias == nm for c in taken) else nm
