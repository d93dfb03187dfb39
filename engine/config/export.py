"""The config schema as JSON Schema (draft 2020-12), for editors and outside validators.

Taplo (the TOML toolkit behind VS Code's "Even Better TOML") completes keys, shows their
documentation and flags bad values from a JSON Schema: ``particles schema --out
particles.schema.json`` writes it, and the checkout's ``.taplo.toml`` associates it with
``configs/*.toml`` (README, "Editing configs"). The schema is generated from the same pydantic
models that validate a config, so the two cannot disagree on a key; what only the models check
(cross-field rules such as increasing keyframe times) the loader still reports in one line.
"""
from __future__ import annotations

import json

from .schema import Scene

SCHEMA_ID = "https://particles-engine.invalid/particles.schema.json"


def json_schema() -> dict:
    """The scene config's JSON Schema (a dict)."""
    s = Scene.model_json_schema(mode="validation")
    s["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    s["$id"] = SCHEMA_ID
    s["title"] = "particles-engine scene config"
    s["description"] = ("An effect or physics scene run by `particles run` (engine/config/schema.py). "
                        "Units: metres, seconds, degrees; colours linear RGB.")
    return s


def schema_text() -> str:
    """The schema as stable, indented JSON text (sorted keys, trailing newline)."""
    return json.dumps(json_schema(), indent=1, sort_keys=True, ensure_ascii=False) + "\n"
