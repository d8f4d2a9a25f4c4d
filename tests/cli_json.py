"""The shipped JSON Schema of ``mech --json`` (mechdsl/schemas/cli-output.schema.json), read from
the installed package, and a validator for the tests."""
from __future__ import annotations

import json
from importlib import resources


def schema() -> dict:
    return json.loads((resources.files("mechdsl") / "schemas" / "cli-output.schema.json").read_text(encoding="utf-8"))


def validate(doc: dict) -> None:
    import jsonschema          # test extra: a missing install fails, it does not skip

    cls = jsonschema.validators.validator_for(schema())
    cls.check_schema(schema())
    cls(schema()).validate(doc)
