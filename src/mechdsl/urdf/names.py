"""Names in the imported .mech text: URDF names made into mechdsl names (letters, digits and _,
not starting with a digit, not a reserved word or a built-in name), each used once."""
from __future__ import annotations

import hashlib
import re

RESERVED = {
    "model", "end", "equation", "extends", "parameter", "coordinate", "output", "input", "constant", "each",
    "kinetic", "potential", "dissipation", "force", "connect", "for", "in", "loop", "scene", "if", "then",
    "elseif", "else", "and", "or", "not", "true", "false", "time", "world", "pi", "der", "Real", "Integer",
    "Boolean",
}


def _builtins() -> set[str]:
    from ..semantic.components import CLASSES
    from ..semantic.evaluate import ALL_FUNCS

    return set(CLASSES) | set(ALL_FUNCS)


class Names:
    def __init__(self):
        self.used: set[str] = set(RESERVED) | _builtins()

    def take(self, wanted: str) -> str:
        """A fresh mechdsl name close to ``wanted``."""
        base = mangle(wanted)
        name, k = base, 2
        while name in self.used:
            name = f"{base}_{k}"
            k += 1
        self.used.add(name)
        return name


def mangle(s: str) -> str:
    out = re.sub(r"[^A-Za-z0-9_]", "_", s) or "unnamed"
    if out[0].isdigit():
        out = "_" + out
    if len(out) > 120:
        out = out[:100] + "_" + hashlib.sha256(s.encode()).hexdigest()[:8]
    return out
