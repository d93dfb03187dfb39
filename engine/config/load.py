"""Read and validate scene configs; turn every problem into one line naming the key and value."""
from __future__ import annotations

import copy
import difflib
import os
import re
import sys
import typing
from typing import Any, List, Union

from pydantic import BaseModel, ValidationError

from .schema import Scene

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


class ConfigError(Exception):
    """Bad input: ``problems`` holds one line per problem, each naming the key path and value."""

    def __init__(self, problems: List[str]):
        self.problems = problems
        super().__init__("; ".join(problems))


_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")
_LONG_KEY = 64


def key_name(part) -> str:
    """A key as TOML would write it: bare when it can be, else a quoted string with escapes, so a
    key holding a newline, a dot or nothing at all still names itself on one line."""
    if not isinstance(part, str):
        part = str(part)
    if len(part) > _LONG_KEY:  # a 1 MB key must not make a 1 MB error line
        return key_name(part[:_LONG_KEY // 2]) + f"...({len(part):,} characters)"
    if _BARE_KEY.fullmatch(part):
        return part
    out = ['"']
    for ch in part:
        if ch in '"\\':
            out.append("\\" + ch)
        elif not ch.isprintable():  # control and line-break characters (U+0085, U+2028...)
            out.append(f"\\u{ord(ch):04x}" if ord(ch) <= 0xFFFF else f"\\U{ord(ch):08x}")
        else:
            out.append(ch)
    return "".join(out) + '"'


def _key_path(loc) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            name = key_name(str(part))
            out += f".{name}" if out else name
    return out or "config"


def _tags(tp) -> dict:
    """{tag: model} when ``tp`` is a union of models told apart by a literal ``type`` key (the
    colliders, the bodies), else {}."""
    if typing.get_origin(tp) is not Union:
        return {}
    out = {}
    for arg in typing.get_args(tp):
        field = arg.model_fields.get("type") if isinstance(arg, type) and issubclass(arg, BaseModel) else None
        if field is None or typing.get_origin(field.annotation) is not typing.Literal:
            return {}
        out.update((tag, arg) for tag in typing.get_args(field.annotation))
    return out


def _walk(loc):
    """Follow an error's ``loc`` through the Scene's types. Returns (the key path as the config
    writes it, the model whose keys live at the end or None, the tagged union crossed last as
    {tag: model} with the tag taken). Pydantic puts the tag into the location of an error inside
    a tagged union (``bodies[0].cloth.strands``); the config has no such key, so it is dropped."""
    tp: Any = Scene
    clean, union, tag = [], {}, None
    for part in loc:
        tp = _unwrap(tp)
        tags = _tags(tp)
        if tags and part in tags:
            union, tag, tp = tags, part, tags[part]
            continue
        clean.append(part)
        if isinstance(part, int):
            args = typing.get_args(tp)
            tp = args[0] if args else None
        elif isinstance(tp, type) and issubclass(tp, BaseModel) and part in tp.model_fields:
            tp = tp.model_fields[part].annotation
        else:
            tp = None
    tp = _unwrap(tp)
    model = tp if isinstance(tp, type) and issubclass(tp, BaseModel) else _tags(tp) or None
    return clean, model, (union, tag)


def _model_at(loc) -> typing.Optional[type]:
    """The model class whose fields live at ``loc`` (for suggesting a key), or None."""
    model = _walk(loc)[1]
    return model if isinstance(model, type) else None


def _or(words) -> str:
    words = list(words)
    return words[0] if len(words) == 1 else f"{', '.join(words[:-1])} or {words[-1]}"


_NOUNS = {"bodies": "body", "colliders": "collider"}


def _other_variant(loc, key) -> typing.Optional[str]:
    """For a key refused inside a tagged union that another variant takes (``strands`` on a
    cloth), or nearly takes (``strand``): the rest of the line that says so and lists the
    variant's own keys; else None (the plain unknown-key line)."""
    clean, _, (union, tag) = _walk(loc)
    if tag is None or not isinstance(key, str):
        return None
    every = list(dict.fromkeys(k for m in union.values() for k in m.model_fields))
    near = difflib.get_close_matches(key, every, n=1, cutoff=0.8)
    name = key if key in every else near[0] if near else None
    if name is None or name in union[tag].model_fields:
        return None  # no other variant's key: the usual suggestion among this variant's keys
    takers = [t for t, m in union.items() if name in m.model_fields]
    common = set.intersection(*(set(m.model_fields) for m in union.values())) | {"type"}
    own = [k for k in union[tag].model_fields if k not in common]
    noun = _NOUNS.get(str(clean[0]) if clean else "", "table")
    head = f": {key_name(key)} is" if name == key else f"; did you mean {name!r}? It is"
    return (f"{head} a key of a {_or(takers)} {noun}, not of a {tag} "
            f"({tag}'s own keys: {', '.join(own) if own else 'none'})")


def _unwrap(tp):
    while True:
        origin = typing.get_origin(tp)
        if origin is typing.Annotated:
            tp = typing.get_args(tp)[0]
        elif origin is Union and type(None) in typing.get_args(tp):
            tp = next(a for a in typing.get_args(tp) if a is not type(None))
        else:
            return tp


def _short(v) -> str:
    r = repr(v)
    return r if len(r) <= 60 else r[:57] + "..."


def format_errors(err: ValidationError) -> List[str]:
    """One line per pydantic error, each starting with the key path it is about."""
    lines = []
    for e in err.errors():
        try:
            line = _format_error(e)
        except Exception:  # never let formatting hide the problem itself
            line = f"{_key_path(e.get('loc', ()))}: {e.get('msg', 'invalid value')}"
        lines.append(" ".join(line.splitlines()))
    return lines


def _expected(loc) -> str:
    """The tags the tagged union at ``loc`` takes, as 'a', 'b' or 'c'."""
    tags = _walk(loc)[1]
    return _or(map(repr, tags)) if isinstance(tags, dict) and tags else "a type"


def _format_error(e) -> str:
    loc = list(e["loc"])
    clean, _, _ = _walk(loc)  # without the tag of a union: colliders[0].radius, bodies[0].strands
    path = _key_path(clean)
    kind, msg = e["type"], e["msg"]
    if kind == "extra_forbidden":
        other = _other_variant(loc[:-1], loc[-1])
        if other:
            return f"{path}: unknown key{other}"
        parent = _model_at([p for p in loc[:-1]])
        names = list(parent.model_fields) if parent else []
        near = difflib.get_close_matches(str(loc[-1]), names, n=1, cutoff=0.5)
        hint = f"; did you mean {near[0]!r}?" if near else (
            f"; valid keys: {', '.join(names)}" if names else "")
        return f"{path}: unknown key{hint}"
    elif kind in ("value_error", "config_check"):
        return f"{path}: {msg.removeprefix('Value error, ')}"
    elif kind == "missing":
        return f"{path}: required key is missing"
    elif kind == "union_tag_not_found":
        return f"{path}.type: required key is missing; expected {_expected(loc)}"
    elif kind == "union_tag_invalid":
        given = e.get("input")
        given = given.get("type") if isinstance(given, dict) else given
        return f"{path}.type: {_short(given)} is not allowed; expected {_expected(loc)}"
    else:
        return f"{path}: {_short(e.get('input'))} is not allowed: {msg[:1].lower() + msg[1:]}"


def apply_presets(data: dict):
    """Fill each emitter from its ``effect`` preset (effects/<name>.py), key by key: what the
    config says wins. Returns (data, problems): an unknown preset name is one problem, and the
    rest of the config is still checked."""
    from effects import PRESETS

    data = copy.deepcopy(data)
    problems = []
    for i, em in enumerate(data.get("emitters", []) if isinstance(data.get("emitters"), list) else []):
        if isinstance(em, dict) and "effect" in em:
            name = em["effect"]
            if not isinstance(name, str) or name not in PRESETS:
                near = difflib.get_close_matches(str(name), list(PRESETS), n=1)
                problems.append(f"emitters[{i}].effect: {_short(name)} is not a preset"
                                + (f"; did you mean {near[0]!r}?" if near else "")
                                + f" (presets: {', '.join(PRESETS)})")
                del em["effect"]  # reported above; check the rest of the emitter as it is
                continue
            merged = copy.deepcopy(PRESETS[name].EMITTER)
            merged.update(em)
            data["emitters"][i] = merged
    return data, problems


def validate(data: dict) -> Scene:
    if not isinstance(data, dict):
        raise ConfigError([f"config: expected a table of keys, got {type(data).__name__}"])
    check_depth(data)
    data, problems = apply_presets(data)
    try:
        scene = Scene.model_validate(data)
    except ValidationError as e:
        raise ConfigError(problems + format_errors(e)) from None
    if problems:
        raise ConfigError(problems)
    return scene


MAX_CONFIG_BYTES = 1 << 20  # 1 MiB: the largest shipped config is about 3 KB
MAX_DEPTH = 32  # tables and arrays nested deeper than this are refused (the schema needs 5)
_BOM = b"\xef\xbb\xbf"


def read_toml(path: Union[str, os.PathLike]) -> dict:
    """The TOML table in ``path``: at most :data:`MAX_CONFIG_BYTES` bytes of UTF-8 (a leading BOM,
    as Windows editors write, is skipped), nested at most :data:`MAX_DEPTH` deep. Only regular
    files: a FIFO would block and ``/dev/zero`` never ends. Raises ConfigError (one line)."""
    p = os.fspath(path)
    if not os.path.exists(p):
        raise ConfigError([f"config: file not found: {p}"])
    if os.path.isdir(p):
        raise ConfigError([f"config: {p} is a directory, not a TOML file"])
    if not os.path.isfile(p):
        raise ConfigError([f"config: {p} is not a regular file (a device, FIFO or socket)"])
    try:
        with open(p, "rb") as fh:  # bounded read: /proc files report size 0 but may hold more
            raw = fh.read(MAX_CONFIG_BYTES + 1)
    except OSError as e:
        raise ConfigError([f"config: cannot read {p}: {e.__class__.__name__}: {e}"]) from None
    if len(raw) > MAX_CONFIG_BYTES:
        raise ConfigError([f"config: {p} is larger than {MAX_CONFIG_BYTES // 1024} KB; "
                           f"a config is a short text file"])
    raw = raw[len(_BOM):] if raw.startswith(_BOM) else raw
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ConfigError([f"config: {p} is not UTF-8 text (byte 0x{raw[e.start]:02x} at offset "
                           f"{e.start})"]) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError([f"config: {p} is not valid TOML: {e}"]) from None
    except RecursionError:  # inline arrays/tables nested about a thousand deep
        raise ConfigError([f"config: {p} nests arrays or tables more than {MAX_DEPTH} levels "
                           f"deep"]) from None
    check_depth(data, p)
    return data


def check_depth(data, where: str = "config") -> None:
    """Refuse data nested deeper than :data:`MAX_DEPTH` (iteratively: no recursion to overflow),
    before deepcopy or validation recurse into it."""
    todo = [(data, 0)]
    while todo:
        node, depth = todo.pop()
        if depth > MAX_DEPTH:
            raise ConfigError([f"config: {where} nests arrays or tables more than {MAX_DEPTH} "
                               f"levels deep"])
        if isinstance(node, dict):
            todo += [(v, depth + 1) for v in node.values()]
        elif isinstance(node, (list, tuple)):
            todo += [(v, depth + 1) for v in node]


def config_data(cfg: Scene) -> dict:
    """The plain data of a validated config that validates back to an equal one: the keys the
    config gave (or a preset set), not every default — a check such as an ``interact`` key that
    applies to one kind only reads which keys were given."""
    return cfg.model_dump(exclude_none=True, exclude_unset=True)


def load_config(path_or_dict, overrides: typing.Optional[dict] = None) -> Scene:
    """A validated :class:`Scene` from a TOML path or a dict; ``overrides`` are dotted keys
    (``{"solver.integrator": "rk4", "render.width": 320}``) applied before validation."""
    if isinstance(path_or_dict, dict):
        check_depth(path_or_dict)
        data = copy.deepcopy(path_or_dict)
    else:
        data = read_toml(path_or_dict)
    if isinstance(data, dict) and not data.get("name") and not isinstance(path_or_dict, dict):
        data["name"] = os.path.splitext(os.path.basename(os.fspath(path_or_dict)))[0]
    for key, value in (overrides or {}).items():
        node = data
        parts = key.split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ConfigError([f"{key}: cannot override inside a non-table value"])
        node[parts[-1]] = value
    return validate(data)
