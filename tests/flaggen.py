"""Bad command-line values for fuzzing, as configgen.py makes bad config keys: every checked flag of
every command with what it accepts, and strategies that draw one value it must refuse. The
refusal must be one line naming the flag (``error: --h: ...``), exit 2, nothing written.

Kinds (each with its own idea of "bad", written here independently of particles_tools/flags.py):
``("int", lo, hi)``, ``("real", lo, hi, lo_open)``, ``("size",)`` (WxH, 16..8192),
``("folder",)`` (not empty), ``("choice", allowed...)``, ``("bytes",)`` (4GB, 512MB, 100).
"""
import math

from hypothesis import strategies as st

RUN = {
    "--frames": ("int", 1, 1_000_000),
    "--out": ("folder",),
    "--format": ("choice", "png", "gif", "mp4"),
    "--size": ("size",),
    "--seed": ("int", 0, 2**32 - 1),
    "--integrator": ("choice", "euler", "midpoint", "rk4", "symplectic_euler", "verlet"),
    "--max-memory": ("bytes",),
    "--max-steps": ("int", 1, 10**12),
    "--max-work": ("real", 1.0, 1e18, False),
    "--workers": ("int", 1, 64),
    "--threads": ("int", 1, 1024),
    "--arch": ("choice", "cpu", "cuda", "vulkan", "metal", "gpu", "auto"),
}
ODE = {
    "--method": ("choice", "euler", "midpoint", "rk4", "symplectic_euler", "verlet"),
    "--h": ("real", 0.0, 1e3, True),
    "--tol": ("real", 0.0, 1.0, True),
    "--t-end": ("real", -1e6, 1e6, False),
    "--points": ("int", 1, 100_000),
    "--max-steps": ("int", 1, 10**9),
}
# command → (arguments that make the rest of the call valid, {flag: kind})
COMMANDS = {
    "run": (["{config}", "--out", "{out}", "--quiet"], RUN),
    "ode": (["decay"], ODE),
    "list": ([], {"--dir": ("folder",)}),
    "chart": (["--quick"], {"--out": ("folder",)}),
    "view": (["{config}"], {"--frames": ("int", 1, 1_000_000), "--screenshot": ("folder",)}),
    "gallery": ([], {"--out": ("folder",), "--configs": ("folder",)}),
}
GLOBAL = {"--arch": RUN["--arch"], "--threads": RUN["--threads"]}  # before the command


def _is_int(text):
    try:
        int(text.strip())
        return True
    except ValueError:
        return False


def _as_float(text):
    try:
        return float(text.strip())
    except ValueError:
        return None


@st.composite
def bad_value(draw, kind):
    name = kind[0]
    junk = st.text(max_size=12).filter(lambda t: "\x00" not in t)
    if name == "int":
        lo, hi = kind[1], kind[2]
        return draw(st.one_of(
            junk.filter(lambda t: not _is_int(t)),
            st.sampled_from(["1.5", "1e3", "0x10", "", " ", "one"]),
            st.integers(max_value=lo - 1).map(str), st.integers(min_value=hi + 1).map(str)))
    if name == "real":
        lo, hi, lo_open = kind[1:]
        outside = [f"{hi * 2 + 1:g}", "1e308", "nan", "inf", "-inf", "NaN", "-nan"]
        outside += [f"{lo:g}"] if lo_open else [f"{lo - 1:g}", f"{lo - 1e6:g}"]
        return draw(st.one_of(junk.filter(lambda t: _as_float(t) is None), st.sampled_from(outside),
                              st.floats(allow_nan=True, allow_infinity=True).filter(
                                  lambda v: not (math.isfinite(v) and (v > lo if lo_open else v >= lo)
                                                 and v <= hi)).map(repr)))
    if name == "size":
        return draw(st.one_of(
            st.sampled_from(["0x0", "15x16", "16x15", "16x8193", "8193x16", "16", "x", "axb",
                             "-16x16", "16x16x16", "", "16 x 16x"]),
            st.tuples(st.integers(-10, 15), st.integers(16, 64)).map(lambda p: f"{p[0]}x{p[1]}"),
            st.tuples(st.integers(16, 64), st.integers(8193, 10**6)).map(lambda p: f"{p[0]}x{p[1]}")))
    if name == "folder":
        return draw(st.sampled_from(["", " ", "   ", "\t"]))
    if name == "choice":
        allowed = kind[1:]
        return draw(junk.filter(lambda t: t not in allowed))
    if name == "bytes":
        return draw(st.sampled_from(["", "GB", "-1GB", "4XB", "0", "0GB", "1e3", "four", "4 G B"]))
    raise ValueError(name)


@st.composite
def bad_call(draw):
    """(argv, flag) for one bad value: the rest of the call is valid."""
    if draw(st.integers(0, 9)) == 0:
        flag, kind = draw(st.sampled_from(sorted(GLOBAL.items())))
        return [f"{flag}={draw(bad_value(kind))}", "ode", "decay"], flag
    cmd = draw(st.sampled_from(sorted(COMMANDS)))
    base, table = COMMANDS[cmd]
    flag, kind = draw(st.sampled_from(sorted(table.items())))
    value = draw(bad_value(kind))
    if flag == "--out":
        base = [a for a in base if a not in ("--out", "{out}")]
    return [cmd, *base, f"{flag}={value}"], flag
