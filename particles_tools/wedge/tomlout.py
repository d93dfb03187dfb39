"""Write a config table back as TOML (the standard library only reads it): each variant of a wedge
becomes a config file that ``particles run`` renders by itself.

Tables are written as inline tables and lists of tables as arrays of inline tables, one top-level
key per line: plain TOML 1.0 that any reader takes. :func:`dumps` reads its own output back and
refuses a table it would not write faithfully.
"""
from __future__ import annotations

import datetime
import json
import math
import re
import sys

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

_BARE = re.compile(r"[A-Za-z0-9_-]+")


def toml_key(k) -> str:
    """A key: bare where TOML allows it, else quoted."""
    k = str(k)
    return k if _BARE.fullmatch(k) else _string(k)


def _string(s: str) -> str:
    # a JSON string is a TOML basic string, given no surrogate escapes (ensure_ascii=False) and
    # DEL escaped (JSON leaves it raw; TOML does not allow it in a basic string)
    return json.dumps(s, ensure_ascii=False).replace("\x7f", "\\u007F")


def toml_value(v) -> str:
    """A value inline: numbers (nan and ±inf as TOML writes them), strings, booleans, dates,
    lists and tables. The tests' config fuzzer writes malformed configs with it too."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            return ("-inf" if v < 0 else "inf") if math.isinf(v) else "nan"
        return repr(v)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, datetime.date):
        return v.isoformat()
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{toml_key(k)} = {toml_value(x)}" for k, x in v.items()) + "}"
    raise ValueError(f"cannot write {type(v).__name__} {v!r} as TOML")


def dumps(data: dict) -> str:
    """``data`` (what ``tomllib`` reads: tables, lists, strings, numbers, booleans) as TOML text;
    ValueError if it does not read back equal (a date, a NaN)."""
    text = "".join(f"{toml_key(k)} = {toml_value(v)}\n" for k, v in data.items())
    if tomllib.loads(text) != data:
        raise ValueError("the table does not read back equal from TOML")
    return text
