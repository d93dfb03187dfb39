"""Malformed scene configs for fuzzing: a valid base config, mutations that each break exactly one
key (and say which key the error must name), and a small TOML writer (nan/inf, dates, odd keys).

A mutation is ``Mutation(sets, expected, scope)``: ``sets`` maps key locations to new values
(DELETE removes the key); ``expected`` is the key path the one error line must start with;
``scope`` is None for a problem in one value, or the location of the table whose cross-key check
reports it (such checks only run once every value in that table is valid, so ``combine`` never
puts them together with a value problem inside the same table).
"""
import copy
import datetime
import math
from dataclasses import dataclass
from typing import Optional, Tuple

from hypothesis import strategies as st

from particles_tools.wedge.tomlout import toml_key as _key, toml_value as _value

DELETE = object()

BASE = {
    "seed": 5,
    "fps": 30,
    "frames": 4,
    "camera": {"position": [0.0, 2.0, 8.0], "look_at": [0.0, 1.0, 0.0], "fov": 45.0},
    "solver": {"integrator": "rk4", "h": 0.01, "adaptive": False, "tolerance": 0.001},
    "forces": {"gravity": [0.0, -9.81, 0.0], "drag": 0.1, "wind": [0.0, 0.0, 0.0]},
    "render": {"width": 64, "height": 36, "exposure": 1.0, "grid": True},
    "emitters": [
        {"name": "a", "effect": "sparks", "rate": 100.0, "speed": [1.0, 2.0], "lifetime": 1.0,
         "start": 0.0, "stop": 2.0, "spread": 10.0, "lifetime_randomness": 0.2, "capacity": 500},
        {"name": "b", "shape": "sphere", "radius": 0.5, "rate": 0.0, "direction": [0.0, 1.0, 0.0],
         "bursts": [{"time": 0.0, "count": 10, "cycles": 2, "interval": 0.5}],
         "path": [{"time": 0.0, "position": [0.0, 0.0, 0.0]}, {"time": 1.0, "position": [1.0, 0.0, 0.0]}],
         "color": [[0.0, 1.0, 1.0, 1.0], [1.0, 0.5, 0.5, 0.5]], "blend": "alpha"},
    ],
    "colliders": [
        {"type": "plane", "normal": [0.0, 1.0, 0.0], "restitution": 0.5},
        {"type": "sphere", "center": [1.0, 0.5, 0.0], "radius": 0.5, "friction": 0.1},
    ],
}

E0, E1, C0, C1 = ("emitters", 0), ("emitters", 1), ("colliders", 0), ("colliders", 1)
B0, P1 = E1 + ("bursts", 0), E1 + ("path", 1)

# Every table and the keys it may hold (the schema's documented keys).
TABLES = {
    (): "name output seed fps duration frames camera solver forces render emitters bodies colliders",
    ("camera",): "position look_at fov",
    ("solver",): "integrator h adaptive tolerance atol max_steps_per_frame",
    ("forces",): "gravity drag wind turbulence attractors vortices",
    ("render",): "width height exposure background grid show_colliders density_shading",
    E0: "name effect shape position path radius box_size surface direction spread speed "
        "inherit_velocity rate bursts start stop lifetime lifetime_randomness drag gravity_scale "
        "buoyancy cooling turbulence sub_emitters emitting capacity blend "
        "color alpha size size_randomness streak",
    B0: "time count cycles interval",
    P1: "time position",
    C0: "name restitution friction kill path visible angular_velocity rotates type point normal",
    C1: "name restitution friction kill path visible angular_velocity rotates type center radius",
}
TABLES[E1] = TABLES[E0]

# Numbers with their allowed ranges: (location, is_int, low, high, low_open, high_open).
NUMBERS = [
    (("seed",), True, 0, 2**32 - 1, False, False),
    (("fps",), False, 1, 1000, False, False),
    (("frames",), True, 1, 1_000_000, False, False),
    (("camera", "fov"), False, 1, 170, True, True),
    (("solver", "h"), False, 0, 1, True, False),
    (("solver", "tolerance"), False, 0, 1, True, False),
    (("forces", "drag"), False, 0, 1e6, False, False),
    (("render", "width"), True, 16, 8192, False, False),
    (("render", "height"), True, 16, 8192, False, False),
    (("render", "exposure"), False, 0, 100, True, False),
    (E0 + ("rate",), False, 0, 1e8, False, False),
    (E0 + ("lifetime",), False, 0, 1e4, True, False),
    (E0 + ("spread",), False, 0, 180, False, False),
    (E0 + ("lifetime_randomness",), False, 0, 1, False, False),
    (E0 + ("capacity",), True, 1, 50_000_000, False, False),
    (E0 + ("speed", 0), False, 0, 1e6, False, False),
    (E1 + ("radius",), False, 0, 1e6, False, False),
    (E1 + ("color", 1, 2), False, 0, 100, False, False),
    (B0 + ("count",), True, 1, 10_000_000, False, False),
    (B0 + ("interval",), False, 0, 1e6, True, False),
    (P1 + ("time",), False, 0, 1e6, False, False),
    (P1 + ("position", 2), False, -math.inf, math.inf, False, False),
    (C0 + ("restitution",), False, 0, 1, False, False),
    (C1 + ("radius",), False, 0, 1e5, True, False),
    (("camera", "position", 1), False, -math.inf, math.inf, False, False),
    (("forces", "gravity", 0), False, -math.inf, math.inf, False, False),
]

STRINGS = [("name",), ("solver", "integrator"), E0 + ("shape",), E1 + ("blend",), E0 + ("effect",)]
BOOLS = [("solver", "adaptive"), ("render", "grid"), E1 + ("surface",), C0 + ("kill",)]
VEC3 = [("camera", "look_at"), ("forces", "wind"), E0 + ("position",), E1 + ("direction",),
        C0 + ("normal",), C1 + ("center",), P1 + ("position",)]
ENUMS = {("solver", "integrator"): ("euler", "midpoint", "rk4", "symplectic_euler", "verlet"),
         E0 + ("shape",): ("point", "sphere", "box", "disc", "cone"),
         E1 + ("blend",): ("additive", "alpha"),
         E0 + ("effect",): ("sparks", "dust")}

BAD_OUTPUTS = ["/tmp/escape", "../up", "a/../../b", "..", "C:/x", "c:x", "", " ", "a\\b", "a//b",
               "~/x", "./x", "x/\n", "a/./b", "\x00"]
BAD_NAMES = ["a/b", "..", ".hidden", "x\x00y", "a\\b", "C:", "tab\there", "x" * 101]


@dataclass(frozen=True)
class Mutation:
    sets: Tuple[Tuple[tuple, object], ...]
    expected: str
    scope: Optional[tuple] = None
    claims: Optional[tuple] = None  # widen the location it owns (a collider's type owns the collider)
    unknown: Optional[str] = None  # an unknown key added to the table at ``expected``

    def owned(self):
        return [self.claims] if self.claims is not None else [loc for loc, _ in self.sets]


def key_path(loc) -> str:
    out = ""
    for p in loc:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else p)
    return out


def _prefix(a, b):
    return a[:len(b)] == b or b[:len(a)] == a


def _conflict(m, n) -> bool:
    if any(_prefix(a, b) for a in m.owned() for b in n.owned()):
        return True
    for x, y in ((m, n), (n, m)):
        if x.scope is not None:
            if y.scope is None and any(loc[:len(x.scope)] == x.scope for loc in y.owned()):
                return True  # a value problem inside the table hides its cross-key check
            if y.scope is not None and y.scope != x.scope and _prefix(x.scope, y.scope):
                return True  # a failing inner table hides the outer table's check
    return False


def combine(muts):
    kept = []
    for m in muts:
        if not any(_conflict(m, k) for k in kept):
            kept.append(m)
    return kept


def apply(muts, base=BASE) -> dict:
    d = copy.deepcopy(base)
    for m in muts:
        for loc, value in m.sets:
            node = d
            for p in loc[:-1]:
                node = node[p]
            if value is DELETE:
                del node[loc[-1]]
            else:
                node[loc[-1]] = value
    return d


def _one(loc, value, expected=None, **kw) -> Mutation:
    return Mutation(((loc, value),), expected if expected is not None else key_path(loc), **kw)


# -- strategies ---------------------------------------------------------------------------------
odd_text = st.text(max_size=8)
bare_key = st.from_regex(r"[A-Za-z_][A-Za-z0-9_-]{0,11}", fullmatch=True)


@st.composite
def unknown_key(draw):
    table = draw(st.sampled_from(sorted(TABLES, key=str)))
    key = draw(st.one_of(bare_key, odd_text).filter(lambda k: k not in TABLES[table].split()))
    return Mutation(((table + (key,), 1),), key_path(table), claims=table + (key,), unknown=key)


def _not_number():
    return st.one_of(odd_text, st.booleans(), st.just([1.0]), st.just({"x": 1}),
                     st.dates(min_value=datetime.date(1, 1, 1)), st.just([]))


@st.composite
def wrong_type(draw):
    kind = draw(st.sampled_from(["number", "string", "bool", "vec3", "table", "list"]))
    if kind == "number":
        loc, is_int = draw(st.sampled_from([(n[0], n[1]) for n in NUMBERS]))
        bad = _not_number() if not is_int else st.one_of(_not_number(), st.just(2.5))
        return _one(loc, draw(bad))
    if kind == "string":
        return _one(draw(st.sampled_from(STRINGS)), draw(st.one_of(
            st.integers(-5, 5), st.floats(allow_nan=False), st.booleans(), st.just(["x"]))))
    if kind == "bool":
        return _one(draw(st.sampled_from(BOOLS)), draw(st.one_of(
            st.integers(0, 1), st.sampled_from(["true", "yes", ""]), st.just([True]))))
    if kind == "vec3":
        return _one(draw(st.sampled_from(VEC3)), draw(st.one_of(
            st.lists(st.floats(-1, 1), max_size=2), st.lists(st.floats(-1, 1), min_size=4, max_size=5),
            st.just([0.0, "1", 0.0]), st.just("0 0 0"), st.just(0.0))))
    if kind == "table":
        loc = draw(st.sampled_from([("camera",), ("solver",), ("forces",), ("render",), E0, E1, C1, B0]))
        return _one(loc, draw(st.one_of(st.integers(), odd_text, st.just([1, 2]))))
    loc = draw(st.sampled_from([("emitters",), ("colliders",), E0 + ("bursts",), E1 + ("path",),
                                E1 + ("color",)]))
    return _one(loc, draw(st.one_of(st.integers(), st.just({"a": 1.0}), odd_text)))


@st.composite
def out_of_range(draw):
    loc, is_int, lo, hi, lo_open, hi_open = draw(st.sampled_from(NUMBERS))
    cands = [math.nan, math.inf, -math.inf]
    if math.isfinite(lo):
        cands += [lo if lo_open else lo - (1 if is_int else 0.5), lo - 1e6, -1e300]
    if math.isfinite(hi):
        cands += [hi if hi_open else hi + (1 if is_int else hi * 0.5 + 1), 1e300]
        if is_int:
            cands.append(2**63 - 1)
    value = draw(st.sampled_from(cands))
    if is_int and isinstance(value, float) and math.isfinite(value):
        value = int(value)
    return _one(loc, value)


@st.composite
def bad_enum(draw):
    loc, allowed = draw(st.sampled_from(sorted(ENUMS.items(), key=str)))
    value = draw(st.one_of(odd_text, st.sampled_from(["rk5", "RK4", "Euler", "cube", "add"]))
                 .filter(lambda v: v not in allowed))
    return _one(loc, value)


@st.composite
def structural(draw):
    return draw(st.sampled_from([
        _one(C0 + ("type",), "cube", claims=C0),
        _one(C1 + ("type",), DELETE, claims=C1),
        _one(B0 + ("count",), DELETE),
        _one(("render", "width"), 0),
        _one(("render", "height"), 0),
        _one(("render", "width"), -640),
        _one(("emitters",), [{}] * 65),  # too many emitters
        _one(E1 + ("color",), [[0.0, 1.0, 1.0]]),
    ]))


@st.composite
def bad_path_or_name(draw):
    if draw(st.booleans()):
        return _one(("output",), draw(st.sampled_from(BAD_OUTPUTS)))
    return _one(("name",), draw(st.sampled_from(BAD_NAMES)))


CHECKS = [  # cross-key problems: each reported by its table's check, at its key
    Mutation(((E0 + ("start",), 3.0),), "emitters[0].stop", scope=E0),
    Mutation(((E0 + ("speed",), [2.0, 1.0]),), "emitters[0].speed", scope=E0),
    Mutation(((E0 + ("rate",), 0.0),), "emitters[0].rate", scope=()),
    Mutation(((("emitters",), []),), "emitters", scope=()),  # no emitter and no body
    Mutation(((E1 + ("direction",), [0.0, 0.0, 0.0]),), "emitters[1].direction", scope=E1),
    Mutation(((E1 + ("color",), [[0.5, 1.0, 1.0, 1.0], [0.2, 1.0, 1.0, 1.0]]),), "emitters[1].color",
             scope=E1),
    Mutation(((P1 + ("time",), 0.0),), "emitters[1].path", scope=E1),
    Mutation(((E1 + ("alpha",), [[0.0, 1.0]] * 9),), "emitters[1].alpha", scope=E1),
    Mutation(((C0 + ("normal",), [0.0, 0.0, 0.0]),), "colliders[0].normal", scope=C0),
    Mutation(((("duration",), 2.0),), "frames", scope=()),
    Mutation(((E0 + ("capacity",), DELETE), (E0 + ("rate",), 1e8), (E0 + ("lifetime",), 1e4)),
             "emitters", scope=()),
]

mutation = st.one_of(unknown_key(), wrong_type(), out_of_range(), bad_enum(), structural(),
                     bad_path_or_name(), st.sampled_from(CHECKS))
malformed = st.lists(mutation, min_size=1, max_size=4).map(combine)


# -- TOML writer (keys and values as the wedge writes them; tables laid out like a hand-written
# config) --------------------------------------------------------------------------------------


def to_toml(d: dict) -> str:
    """Scalars first, then tables as [table] and lists of tables as [[table]], like a hand-written
    config; everything deeper inline."""
    lines, tables = [], []
    for k, v in d.items():
        if isinstance(v, dict):
            tables.append(f"\n[{_key(k)}]")
            tables += [f"{_key(kk)} = {_value(vv)}" for kk, vv in v.items()]
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            for item in v:
                tables.append(f"\n[[{_key(k)}]]")
                tables += [f"{_key(kk)} = {_value(vv)}" for kk, vv in item.items()]
        else:
            lines.append(f"{_key(k)} = {_value(v)}")
    return "\n".join(lines + tables) + "\n"
