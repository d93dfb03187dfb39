"""What a wedge renders: the product of the ``--set`` lists (× ``--seeds``), each variant checked
with the same validation ``particles run`` uses before anything renders. Each variant's whole config
is kept as TOML text: that file is what a worker hands to ``particles run``.

A key is a config path with list items by index (``emitters.0.rate``, ``forces.turbulence.strength``,
``solver.h``); a value is read as a TOML value (``2.5``, ``3``, ``true``, ``[0.0, 1.0, 0.0]``,
``"rk4"``), else as a bare word (``rk4``). Values are split on the commas outside brackets and
quotes, so a vector is one value. Pure Python: no Taichi, nothing written.
"""
from __future__ import annotations

import copy
import hashlib
import itertools
import math
import os
import re
import sys
from dataclasses import dataclass, field, replace
from typing import List, Optional, Tuple

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from ..errors import UserError

#: more variants than this is a typo, not a wedge (and would allocate without bound)
MAX_VARIANTS = 10_000
_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_]*|[0-9]+")


@dataclass(frozen=True)
class Variant:
    """One point of the wedge: ``id`` (``v000``...), ``sets`` the (key, value) pairs it sets,
    ``texts`` the values as typed (for the index and labels), ``seed`` from ``--seeds`` or None;
    once validated, ``frames`` (how many it renders) and ``config_text`` (its whole config as
    TOML: what ``particles run`` renders for it)."""

    id: str
    sets: Tuple[Tuple[str, object], ...]
    texts: Tuple[str, ...]
    seed: Optional[int] = None
    frames: int = 0
    config_text: str = ""

    def label(self, keys) -> str:
        """``emitters.0.rate=200 seed=8`` (the values as typed)."""
        parts = [f"{k}={t}" for k, t in zip(keys, self.texts)]
        return " ".join(parts + ([f"seed={self.seed}"] if self.seed is not None else []))


@dataclass
class Wedge:
    """The whole request: the config path and its SHA-256 (workers check they read the same file),
    the ``--set`` keys and value texts, the seeds, the run settings every variant shares."""

    config: str
    config_sha256: str
    keys: List[str]
    values: List[List[str]]
    seeds: Optional[List[int]]
    frames: Optional[int]
    size: Optional[str]
    variants: List[Variant] = field(default_factory=list)
    name: str = ""  # the config's name (its file name unless it sets one)

    @property
    def columns(self) -> List[str]:
        return self.keys + (["seed"] if self.seeds is not None else [])

    def record(self) -> dict:
        """What decides the variants' pixels and ids, stored in the wedge folder for --resume."""
        return {"config": self.config, "config_sha256": self.config_sha256, "keys": self.keys,
                "values": self.values, "seeds": self.seeds, "frames": self.frames, "size": self.size}


def split_values(text: str) -> List[str]:
    """``1,[0,1,0],"a,b"`` → ``['1', '[0,1,0]', '"a,b"']``: commas outside brackets and quotes."""
    out, depth, quote, cur = [], 0, None, []
    for ch in text:
        if quote:
            quote = None if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            out.append("".join(cur).strip())
            cur = []
            continue
        cur.append(ch)
    out.append("".join(cur).strip())
    return out


def parse_value(text: str):
    """A TOML value (``2.5``, ``3``, ``true``, ``[0, 1, 0]``, ``"rk4"``); ``.5`` as a number;
    anything else as a bare word."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def parse_set(item: str) -> Tuple[str, List[str]]:
    """``KEY=V1,V2,...`` → (key, [value texts]); raises UserError naming the flag."""
    key, eq, rest = item.partition("=")
    key = key.strip()
    if not eq or not key:
        raise UserError(f"--set: {item!r} is not KEY=V1,V2,... (e.g. emitters.0.rate=200,400)")
    parts = key.split(".")
    if not all(_KEY.fullmatch(p) for p in parts) or parts[0].isdigit():
        raise UserError(f"--set: {key!r} is not a config path (names and list indexes joined by "
                        f"dots, e.g. emitters.0.rate or forces.turbulence.strength)")
    texts = split_values(rest)
    if any(t == "" for t in texts):
        raise UserError(f"--set {key}: empty value in {rest!r}; give V1,V2,...")
    return key, texts


def set_path(data: dict, key: str, value) -> None:
    """Set ``data[a][b][0][c] = value`` for ``key = "a.b.0.c"``: missing tables are created, a
    list item must exist. Raises ValueError with a message naming the key."""
    node = data
    parts = key.split(".")
    for depth, part in enumerate(parts):
        last = depth == len(parts) - 1
        where = ".".join(parts[:depth]) or "the config"
        if isinstance(node, list):
            if not part.isdigit():
                raise ValueError(f"{where} is a list; {part!r} is not an index")
            k = int(part)
            if k >= len(node):
                raise ValueError(f"{where} has {len(node)} item(s); index {k} is out of range")
        elif isinstance(node, dict):
            if part.isdigit():
                raise ValueError(f"{where} is a table, not a list; {part!r} is not a key")
            k = part
            if not last and k not in node:
                node[k] = {}
        else:
            raise ValueError(f"{where} is a value ({node!r}), not a table or a list")
        if last:
            node[k] = value
        else:
            node = node[k]


def parse_size(text: str):
    """``640x360`` → (640, 360); UserError naming --size otherwise (the range is the config's)."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise UserError(f"--size: {text!r} is not WxH (e.g. 640x360)") from None
    return w, h


def variant_data(base: dict, frames, size, variant: Variant) -> dict:
    """One variant's whole config as a table: the file's (``base``, named), then ``--frames``,
    ``--size``, the seed and the ``--set`` values, as ``particles run`` would apply its own flags.
    Raises ValueError naming the ``--set`` key whose path does not fit."""
    data = copy.deepcopy(base)
    if frames is not None:
        data.pop("duration", None)
        data["frames"] = frames
    pairs = [] if size is None else list(zip(("render.width", "render.height"), parse_size(size)))
    pairs += [] if variant.seed is None else [("seed", variant.seed)]
    for key, value in pairs + list(variant.sets):
        try:
            set_path(data, key, value)
        except ValueError as e:
            raise ValueError(f"--set {key}: {e}") from None
    return data


def file_sha256(path: str) -> str:
    with open(path, "rb") as fh:
        return hashlib.sha256(fh.read()).hexdigest()


def build(config: str, sets: List[str], seeds: Optional[int], frames, size) -> Wedge:
    """Parse the ``--set`` lists, expand the product (seeds innermost) and validate every
    variant's whole config. Raises UserError with one line per distinct problem, naming the key,
    value and the variants it occurs in; nothing is written."""
    from engine.config import ConfigError, load_config, read_toml
    from . import tomlout

    if frames is not None and frames < 1:
        raise UserError(f"--frames: {frames} is not allowed: must be >= 1")
    if seeds is not None and seeds < 1:
        raise UserError(f"--seeds: {seeds} is not allowed: must be >= 1")
    if size is not None:
        parse_size(size)
    try:
        base = read_toml(config)
    except ConfigError as e:
        raise UserError("\n".join(f"{config}: {p}" for p in e.problems)) from None
    if base.get("name", "") == "":  # as particles run names a config
        base["name"] = os.path.splitext(os.path.basename(config))[0]
    parsed = [parse_set(s) for s in sets]
    keys = [k for k, _ in parsed]
    dup = sorted({k for k in keys if keys.count(k) > 1})
    if dup:
        raise UserError(f"--set: {dup[0]} is given more than once; put all its values in one list")
    if seeds is not None and "seed" in keys:
        raise UserError("--seeds and --set seed=...: choose one")
    if not parsed and seeds is None:
        raise UserError("--set: nothing to wedge; give --set KEY=V1,V2,... or --seeds N")
    count = math.prod(len(t) for _, t in parsed) * (seeds or 1)
    if count > MAX_VARIANTS:
        raise UserError(f"--set: {count:,} variants (the product of the lists"
                        f"{' x --seeds' if seeds else ''}) is more than {MAX_VARIANTS:,}")
    seed_list = None
    if seeds is not None:
        base_seed = base.get("seed", 0)
        if not isinstance(base_seed, int) or isinstance(base_seed, bool):
            base_seed = 0  # the config's own problem; validation below names it
        seed_list = [base_seed + k for k in range(seeds)]
    wedge = Wedge(os.path.abspath(config), file_sha256(config), keys, [t for _, t in parsed],
                  seed_list, frames, size)
    width = max(3, len(str(count - 1)))
    combos = itertools.product(*([list(zip(itertools.repeat(k), t)) for k, t in parsed]
                                 + [seed_list or [None]]))
    problems = {}  # problem line -> variant ids, in order of first appearance
    for n, combo in enumerate(combos):
        pairs, seed = combo[:-1], combo[-1]
        v = Variant(f"v{n:0{width}d}", tuple((k, parse_value(t)) for k, t in pairs),
                    tuple(t for _, t in pairs), seed)
        try:
            data = variant_data(base, frames, size, v)
            cfg = load_config(data)
            v = replace(v, frames=cfg.frame_count, config_text=tomlout.dumps(data))
            wedge.name = wedge.name or cfg.name
        except ConfigError as e:
            for p in e.problems:
                problems.setdefault(f"{_culprit(p, v, keys) or config}: {p}", []).append(v.id)
        except ValueError as e:  # a --set path that does not fit the config
            problems.setdefault(str(e), []).append(v.id)
        wedge.variants.append(v)
    if problems:
        lines = []
        for line, ids in problems.items():
            shown = ", ".join(ids[:4]) + (f" and {len(ids) - 4} more" if len(ids) > 4 else "")
            lines.append(f"{line} (variant{'s' if len(ids) > 1 else ''} {shown})")
        raise UserError("\n".join(lines))
    return wedge


def _culprit(problem: str, v: Variant, keys) -> Optional[str]:
    """``--set emitters.0.rate=-5`` when the problem is at that key's path (``emitters[0].rate``
    or inside it), None when it is elsewhere (the config file's own problem)."""
    for key, text in zip(keys, v.texts):
        path = re.sub(r"\.(\d+)", r"[\1]", key)
        if re.match(re.escape(path) + r"[:.\[ ]", problem):
            return f"--set {key}={text}"
    return None
