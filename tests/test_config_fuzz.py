"""Fuzzing the config check: thousands of malformed configs, each breaking known keys, must give
exactly one error line per problem, naming its key, through the same code the CLI runs; exit 2,
no traceback, no output folder. A sample goes through real ``python -m engine`` processes."""
import os
import re
import shutil
import subprocess
import sys
import tempfile

try:
    import tomllib
except ImportError:  # Python < 3.11
    import tomli as tomllib

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from configgen import BASE, apply, malformed, to_toml
from flaggen import bad_call
from runhelp import ENV, call

FUZZ_EXAMPLES = 300  # per default run; the slow run checks SLOW_FUZZ_EXAMPLES more
SLOW_FUZZ_EXAMPLES = 1000
QUOTED = re.compile(r'"(?:[^"\\]|\\.)*"')


def names(problem: str, m) -> bool:
    """Does the problem text (after 'file: ') start with mutation m's key path?"""
    if m.unknown is None:
        return (problem.startswith(m.expected)
                and problem[len(m.expected):len(m.expected) + 1] in (":", ".", "["))
    head = f"{m.expected}." if m.expected else ""
    if not problem.startswith(head):
        return False
    rest = problem[len(head):]
    if rest.startswith(m.unknown + ": unknown key") and re.fullmatch(r"[A-Za-z0-9_-]+", m.unknown):
        return True
    q = QUOTED.match(rest)  # an odd key is written as a TOML quoted key: it must read back as itself
    return bool(q) and rest[q.end():].startswith(": unknown key") and \
        tomllib.loads(f"{q.group()} = 1") == {m.unknown: 1}


def check_lines(lines, prefix, muts, text):
    assert "Traceback" not in text
    assert lines and all(ln.startswith(prefix) for ln in lines), text
    problems = [ln[len(prefix):] for ln in lines]
    assert len(problems) == len(muts), (muts, text)
    for m in muts:
        assert sum(names(p, m) for p in problems) == 1, (m, text)
    for p in problems:
        assert any(names(p, m) for m in muts), (p, muts)


@pytest.fixture(scope="module")
def scratch():
    d = tempfile.mkdtemp(prefix="fuzz-")
    yield d
    shutil.rmtree(d, ignore_errors=True)


def test_base_config_is_valid(scratch):
    path = os.path.join(scratch, "base.toml")
    with open(path, "w") as fh:
        fh.write(to_toml(BASE))
    assert call("validate", path)[0] == 0


def fuzz_malformed(scratch, examples):
    seen = []

    @settings(max_examples=examples, deadline=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
    @given(muts=malformed)
    def check(muts):
        seen.append(muts)
        path = os.path.join(scratch, "bad.toml")
        with open(path, "w", encoding="utf-8") as fh:
            fh.write(to_toml(apply(muts)))
        code, out, err = call("validate", path)
        assert code == 2 and not err, (out, err)
        check_lines(out.splitlines(), f"{path}: ", muts, out)
        # `run` goes through the same check: same lines on stderr, nothing written
        dest = os.path.join(scratch, "out")
        code, out, err = call("run", path, "--out", dest, "--quiet")
        assert code == 2 and not out, (out, err)
        check_lines(err.splitlines(), f"error: {path}: ", muts, err)
        assert not os.path.exists(dest) and not os.path.exists(os.path.join("renders", "bad"))

    check()
    assert len(seen) >= examples


def test_malformed_configs_give_one_line_per_problem_naming_the_key(scratch):
    fuzz_malformed(scratch, FUZZ_EXAMPLES)


@pytest.mark.slow
def test_many_more_malformed_configs(scratch):
    fuzz_malformed(scratch, SLOW_FUZZ_EXAMPLES)


@settings(max_examples=200, deadline=None)
@given(junk=st.one_of(st.binary(max_size=80), st.text(max_size=80)),
       at=st.integers(0, len(to_toml(BASE))))
def test_garbage_files_give_one_line_and_exit_2(junk, at):
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "junk.toml")
        raw = to_toml(BASE).encode()
        raw = raw[:at] + (junk if isinstance(junk, bytes) else junk.encode("utf-8", "surrogatepass")) \
            + b"\n= broken\n" + raw[at:]
        with open(path, "wb") as fh:
            fh.write(raw)
        code, out, err = call("validate", path)
        assert code == 2 and not err
        lines = out.splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"{path}: config: "), out


@pytest.mark.parametrize("make,why", [
    (lambda d: os.path.join(d, "missing.toml"), "file not found"),
    (lambda d: d, "is a directory"),
    (lambda d: "/proc/self/mem", "cannot read"),  # opens, but every read fails (EIO)
    (lambda d: _write(d, b"\xff\xfe not utf-8 = 1\n"), "config: "),
    (lambda d: _write(d, b""), "emitters: a scene needs at least one emitter, body or rigid body"),
    (lambda d: _write(d, b"emitters = []\n"), "emitters: a scene needs at least one emitter, body or rigid body"),
    (lambda d: _write(d, b"[[emitters]]\nrate = nan\n[render]\nwidth = 0\nheight = inf\n"), "emitters[0].rate"),
])
def test_unreadable_and_odd_files(tmp_path, make, why):
    path = make(str(tmp_path))
    code, out, err = call("validate", path)
    assert code == 2 and why in out, out
    assert all(ln.startswith(f"{path}: ") for ln in out.splitlines())
    code, out, err = call("run", path, "--out", str(tmp_path / "out"))
    assert code == 2 and why in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def _write(d, data: bytes) -> str:
    path = os.path.join(d, "f.toml")
    with open(path, "wb") as fh:
        fh.write(data)
    return path


def real_command_check(muts, command):
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "bad.toml")
        with open(path, "w", encoding="utf-8") as fh:
            fh.write(to_toml(apply(muts)))
        out = os.path.join(d, "out")
        args = [path] if command == "validate" else [path, "--out", out, "--quiet"]
        r = subprocess.run([sys.executable, "-m", "engine", command, *args], capture_output=True,
                           text=True, cwd=d, env=ENV, timeout=120)
        assert r.returncode == 2, (r.stdout, r.stderr)
        text = r.stdout if command == "validate" else r.stderr
        check_lines(text.splitlines(), f"{path}: " if command == "validate" else f"error: {path}: ",
                    muts, r.stdout + r.stderr)
        assert sorted(os.listdir(d)) == ["bad.toml"]  # nothing written, not even renders/


FLAG_EXAMPLES = 400


def test_bad_flag_values_give_one_line_naming_the_flag(scratch, monkeypatch):
    """Every checked flag of every command, one bad value at a time: exit 2, one line on stderr
    naming the flag, nothing on stdout, nothing written (the rest of each call is valid)."""
    work = os.path.join(scratch, "flags")
    os.makedirs(work)
    config = os.path.join(scratch, "base.toml")
    with open(config, "w") as fh:
        fh.write(to_toml(BASE))
    monkeypatch.chdir(work)  # renders/, charts or stills would land here
    seen = []

    @settings(max_examples=FLAG_EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow])
    @given(case=bad_call())
    def check(case):
        argv, flag = case
        argv = [a.replace("{config}", config).replace("{out}", os.path.join(work, "out")) for a in argv]
        seen.append(flag)
        code, out, err = call(*argv)
        lines = err.splitlines()
        assert code == 2 and not out, (argv, out, err)
        assert len(lines) == 1 and lines[0].startswith(f"error: {flag}: "), (argv, err)
        assert os.listdir(work) == [], (argv, os.listdir(work))

    check()
    assert len(set(seen)) >= 15  # the draws reached most flags


# A real process per example (about a second each): a few in the default run, more in the slow one.
@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(muts=malformed, command=st.sampled_from(["run", "validate"]))
def test_malformed_configs_through_the_real_command(muts, command):
    real_command_check(muts, command)


@pytest.mark.slow
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(muts=malformed, command=st.sampled_from(["run", "validate"]))
def test_malformed_configs_through_the_real_command_many(muts, command):
    real_command_check(muts, command)
