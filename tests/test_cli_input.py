"""Every command checks its input like the config loader does (issue 16): one line on stderr naming
the flag or key and the value, exit 2, no traceback, nothing written. Each case of the issue is a
row here; the fuzz test (test_config_fuzz.py) covers the flags at random."""
import json
import signal
import subprocess

import pytest

from runhelp import call, command, particles

TINY = """seed = 1
fps = 30
frames = 2
[render]
width = 48
height = 32
[[emitters]]
rate = 50.0
{extra}
"""


def cfg_file(folder, extra="", body=None, name="fx.toml"):
    path = folder / name
    path.write_text(body if body is not None else TINY.format(extra=extra))
    return path


def one_error_line(code, err, expect_code=2):
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == expect_code, err
    assert "Traceback" not in err and len(lines) == 1 and lines[0].startswith("error: "), err
    return lines[0]


@pytest.mark.parametrize("args, flag", [
    (["--size", "641x361", "--format", "mp4"], "--size: 641x361 is not allowed with --format mp4"),
    (["--size", "0x0"], "--size: '0x0'"),  # names the flag, not render.width
    (["--size", "abc"], "--size: 'abc' is not WxH"),
    (["--out", ""], "--out: '' is empty: give a path"),
    (["--frames", "0"], "--frames: '0'"),
    (["--frames", "x"], "--frames: 'x' is not a whole number"),
    (["--seed", "-1"], "--seed: '-1'"),
    (["--integrator", "rk5"], "--integrator: 'rk5'"),
    (["--format", "avi"], "--format: 'avi'"),
    (["--max-memory", "lots"], "--max-memory: 'lots'"),
    (["--threads", "0"], "--threads: '0'"),
    (["--resume", "--overwrite"], "--resume and --overwrite"),
    (["--resume", "--format", "gif"], "--resume: works for PNG frames only"),
    (["--bogus"], "unrecognized arguments: --bogus"),
])
def test_run_flags_give_one_line_naming_the_flag(tmp_path, args, flag):
    out = tmp_path / "out"
    code, stdout, err = call("run", cfg_file(tmp_path), "--quiet", *(["--out", out] if "--out" not in args else []),
                             *args)
    assert flag in one_error_line(code, err)
    assert not out.exists() and not (tmp_path / "renders").exists()


def test_odd_config_size_with_mp4_names_the_key(tmp_path):
    path = cfg_file(tmp_path, body=TINY.format(extra="").replace("width = 48", "width = 47"))
    code, _, err = call("run", path, "--format", "mp4", "--out", tmp_path / "out")
    line = one_error_line(code, err)
    assert "render.width: 47 is odd" in line and "--size 46x32" in line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("extra, key", [
    ("[camera]\nposition = [0.0, 1.0, 2.0]\nlook_at = [0.0, 1.0, 2.0]", "camera.look_at"),
    ('[[colliders]]\ntype = "plane"\nname = "g"\n[[colliders]]\ntype = "sphere"\nname = "g"',
     "colliders: names must be unique, repeated: 'g'"),
    ('[[bodies]]\ntype = "chain"\nname = "b"\n[[bodies]]\ntype = "chain"\nname = "b"',
     "bodies: names must be unique"),
    ('name = "e"\n[[emitters]]\nname = "e"\nrate = 5.0', "emitters: names must be unique"),
    # a key of another soft-body type is refused, naming the key (bodies are a union tagged by type)
    ('[[bodies]]\ntype = "cloth"\nstrands = 40', "bodies[0].strands: unknown key: strands is a key of a hair body"),
    ('[[bodies]]\ntype = "chain"\nresolution = [4, 4]', "bodies[0].resolution: unknown key"),
    ('[[bodies]]\ntype = "jelly"\nresolution = [3, 3, 3]\nsize = [1.0, 1.0, 1.0]\nplane = "xy"',
     "bodies[0].plane: unknown key: plane is a key of a cloth body, not of a jelly"),
    ('[[bodies]]\ntype = "blob"', "bodies[0].type: 'blob' is not allowed; expected 'chain', 'hair', "
     "'cloth', 'jelly' or 'solid'"),
    (f'[[colliders]]\ntype = "plane"\nname = "{"n" * 100_000}"', "colliders[0].name"),
])
def test_config_problems_name_the_key(tmp_path, extra, key):
    path = cfg_file(tmp_path, extra=extra)
    for cmd in (["validate", path], ["run", path, "--out", tmp_path / "out"]):
        code, out, err = call(*cmd)
        text = out if cmd[0] == "validate" else err
        lines = text.strip().splitlines()
        assert code == 2 and len(lines) == 1 and key in lines[0], text
        assert len(lines[0]) < 400  # a 100 KB name does not make a 100 KB line
    assert not (tmp_path / "out").exists()


def _deep(d):
    return cfg_file(d, body="x = " + "[" * 5000 + "]" * 5000 + "\n")


def _big(d):
    return cfg_file(d, body="# padding\n" * 200_000)


@pytest.mark.parametrize("make, why", [
    (_deep, "nests arrays or tables more than 32 levels deep"),
    (_big, "is larger than 1024 KB"),
    (lambda d: "/dev/zero", "is not a regular file"),
])
def test_odd_input_files_are_refused_before_reading_them(tmp_path, make, why):
    path = make(tmp_path)
    code, out, err = call("validate", path)
    lines = out.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith(f"{path}: config: ") and why in out
    code, _, err = call("run", path, "--out", tmp_path / "out")
    assert why in one_error_line(code, err)


def test_a_utf8_bom_is_accepted(tmp_path):
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + TINY.format(extra="").encode())
    assert call("validate", path)[:2] == (0, f"{path}: ok\n")


BASE = TINY.format(extra="")


@pytest.mark.parametrize("body, flags, limit", [
    (BASE.replace("rate = 50.0", "rate = 1e8\nlifetime = 0.4"), [], "--max-memory: the run needs about"),
    (BASE.replace("frames = 2", "frames = 120").replace("[render]", "[solver]\nh = 1e-7\n[render]"), [],
     "--max-steps: the run plans 40,000,080 integrator steps (120 frames), over the limit of 2,000,000"),
    (BASE, ["--max-memory", "10KB"], "over the limit of 10.0 KB"),
    (BASE, ["--max-work", "100"], "--max-work: the run plans"),
])
def test_budgets_refuse_before_any_work(tmp_path, body, flags, limit):
    code, _, err = call("run", cfg_file(tmp_path, body=body), "--out", tmp_path / "out", *flags)
    line = one_error_line(code, err)
    assert limit in line and "raise --max" in line, line
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_raising_the_limit_lets_the_run_go(tmp_path):
    path = cfg_file(tmp_path, body=TINY.format(extra="").replace("[render]", "[solver]\nh = 1e-3\n[render]"))
    code, _, err = call("run", path, "--out", tmp_path / "a", "--quiet", "--max-steps", "40")
    assert "--max-steps: the run plans 68 integrator steps" in one_error_line(code, err)
    code, out, err = call("run", path, "--out", tmp_path / "a", "--quiet", "--max-steps", "68")
    assert code == 0 and "68 steps" in out, err


def test_duration_times_fps_cannot_pass_the_frame_cap(tmp_path):
    path = cfg_file(tmp_path, body=TINY.format(extra="").replace("frames = 2", "duration = 3600.0")
                    .replace("fps = 30", "fps = 1000"))
    code, out, _ = call("validate", path)
    assert code == 2 and "duration: 3600 s at fps 1000 is 3,600,000 frames; at most 1,000,000" in out


@pytest.mark.slow
def test_resume_with_nothing_left_says_so_and_simulates_nothing(tmp_path):
    path = cfg_file(tmp_path)
    out = tmp_path / "out"
    assert call("run", path, "--out", out, "--quiet")[0] == 0
    code, stdout, err = call("run", path, "--out", out, "--quiet", "--resume")
    assert code == 0 and not err
    assert stdout.strip() == f"fx: nothing to resume: {out} already holds 2 whole frame(s) of 2"


@pytest.mark.parametrize("args, flag", [
    (["--h", "0"], "--h: '0'"), (["--h=-0.01"], "--h: '-0.01'"), (["--h", "nan"], "--h: 'nan'"),
    (["--t-end=-1"], "--t-end: -1 is not allowed: must be after the start t=0"),
    (["--points=-1"], "--points: '-1'"), (["--tol=-1"], "--tol: '-1'"),
    (["--h", "1e-9"], "--max-steps: --h 1e-09 from t=0 to 10 is 10,000,000,000 steps"),
    (["--method", "rk5"], "--method: 'rk5'"),
])
def test_ode_flags_are_checked_and_work_is_bounded(args, flag):
    code, out, err = call("ode", "lotka-volterra", *args)
    assert flag in one_error_line(code, err) and not out


def test_ode_csv_header_names_the_variables():
    code, out, err = call("ode", "lotka-volterra", "--points", "2")
    assert code == 0, err
    assert out.splitlines()[0] == "t,x,y" and len(out.splitlines()) == 4


def test_list_of_a_missing_folder_and_a_closed_pipe(tmp_path):
    code, _, err = call("list", "--dir", tmp_path / "nope")
    assert "--dir: " in one_error_line(code, err)
    cmd, kw = command("list")
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kw)
    proc.stdout.readline()
    proc.stdout.close()  # `particles list | head -1`
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) in (0, 141) and err == "", err


@pytest.mark.slow
def test_arch_that_cannot_start_is_an_error_and_auto_records_what_ran(tmp_path):
    import taichi as ti

    path = cfg_file(tmp_path)
    r = particles("--arch", "cuda", "run", path, "--out", tmp_path / "c", "--quiet")
    if ti.lang.misc.is_arch_supported(ti.cuda):  # a CUDA machine: it simply runs there
        assert r.returncode == 0, r.stderr
    else:
        assert "--arch: cuda cannot start on this machine" in one_error_line(r.returncode, r.stderr)
        assert not (tmp_path / "c").exists()
    r = particles("run", path, "--out", tmp_path / "a", "--quiet", "--arch", "auto")
    assert r.returncode == 0, r.stderr
    with open(tmp_path / "a" / ".particles-run.json") as fh:
        ran = json.load(fh)["arch"]
    assert ran in ("cpu", "cuda", "vulkan", "metal") and ran != "auto"


def test_ode_stops_on_sigterm_with_one_line():
    cmd, kw = command("ode", "kepler", "--h", "1e-7", "--points", "100000", "--max-steps", "100000000")
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)
    try:
        proc.wait(timeout=4)  # imports, compiles, then steps for far longer than this
    except subprocess.TimeoutExpired:
        pass
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=30)
    assert "stopped by SIGTERM" in one_error_line(proc.returncode, err, 143) and out == ""


def test_second_signal_ends_the_process_at_once(tmp_path):
    """After the first signal the default action is back: a second one kills even code that
    never polls (here a busy loop standing for a long kernel)."""
    script = tmp_path / "stuck.py"
    script.write_text(
        "import os, signal, sys, time\n"
        "from particles_tools.signals import StopRequest\n"
        "with StopRequest(raise_now=False) as stop:\n"
        "    os.kill(os.getpid(), signal.SIGTERM)\n"
        "    while not stop.requested:\n"
        "        time.sleep(0.01)\n"
        "    print('first seen', flush=True)\n"
        "    os.kill(os.getpid(), signal.SIGTERM)\n"
        "    t = time.time()\n"
        "    while time.time() - t < 30:\n"
        "        pass\n"
        "print('never')\n")
    cmd, kw = command()
    r = subprocess.run([cmd[0], str(script)], capture_output=True, text=True, timeout=60,
                       **{k: v for k, v in kw.items()})
    assert r.returncode == -signal.SIGTERM and r.stdout == "first seen\n", (r.stdout, r.stderr)


def test_parser_choices_match_the_engine():
    from engine import runtime
    from particles_tools import cli
    from particles_tools.problems import PROBLEMS

    assert cli.ARCH_CHOICES == runtime.ARCHES  # kept apart: `validate` imports no Taichi
    assert set(cli.PROBLEM_NAMES) == set(PROBLEMS)
    code, _, err = call("--arch", "vulkan", "ode", "decay")  # this process runs on the CPU already
    assert "--arch: " in one_error_line(code, err)


@pytest.mark.parametrize("cmd", ["profile", "view"])
@pytest.mark.parametrize("case", ["missing", "bad value"])
def test_the_tools_that_play_a_config_check_it_as_run_does(tmp_path, cmd, case):
    """``profile`` and ``view`` build a config as a game does, through the API; a missing file or
    a bad value is the one line ``particles run`` gives, exit 2, before any kernel compiles
    (``profile`` printed the API's traceback, exit 1)."""
    path = tmp_path / "nope.toml" if case == "missing" else cfg_file(tmp_path, body="fps = 'x'\n")
    r = particles(cmd, path)
    line = one_error_line(r.returncode, r.stderr)
    assert str(path) in line and ("file not found" if case == "missing" else "fps: 'x' is not allowed") in line
    assert r.stdout == ""


@pytest.mark.parametrize("args", [["chart", "--only", "kepler", "--quick"], ["gallery", "--quiet"]])
@pytest.mark.parametrize("where", ["a file", "under a file"])
def test_chart_and_gallery_out_that_cannot_be_a_folder(tmp_path, args, where):
    """``--out`` a file, or a path through one: one line naming the flag, exit 4 (an output
    failure, as ``particles run --out``), the file untouched; it was a traceback."""
    f = tmp_path / "afile"
    f.write_text("mine")
    out = f if where == "a file" else f / "sub"
    r = particles(*args, "--out", out)
    line = one_error_line(r.returncode, r.stderr, expect_code=4)
    assert line.startswith("error: --out: ") and str(out) in line and f.read_text() == "mine"
