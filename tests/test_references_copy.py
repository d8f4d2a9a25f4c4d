"""The vendored reference data equal the shared originals (when the shared folder is present)."""
from pathlib import Path

import pytest

from conftest import REFERENCES, CHECKOUT

SHARED = [CHECKOUT.parent / "shared" / "references", Path("/work/shared/references")]
FILES = ["andrews_squeezer.json", "pendulum_index3.json"]


@pytest.mark.parametrize("name", FILES)
def test_vendored_reference_is_verbatim(name):
    ours = (REFERENCES / name).read_bytes()
    assert ours.startswith(b"{")
    originals = [d / name for d in SHARED if (d / name).is_file()]
    for o in originals:  # where the shared folder exists, the copy must be identical
        assert o.read_bytes() == ours
