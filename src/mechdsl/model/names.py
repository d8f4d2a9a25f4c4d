"""The one reader of state names: a coordinate ``"theta"`` or its speed ``"der(theta)"``.

Start values, sweeps, pins, linearization points and result columns all name a state this
way; ``split_state`` is the only place that parses ``der(...)`` (``eom.start.state_key`` turns
it into an index of [q; qd]).
"""
from __future__ import annotations


def split_state(key: str) -> tuple[str, bool]:
    """(coordinate name, whether it is the speed) of a state name: ``"c"`` -> ("c", False),
    ``"der(c)"`` -> ("c", True); surrounding blanks are ignored."""
    k = str(key).strip()
    if k.startswith("der(") and k.endswith(")") and len(k) > 5:
        return k[4:-1], True
    return k, False


def state_name(name: str, speed: bool) -> str:
    """The inverse of ``split_state``."""
    return f"der({name})" if speed else name
