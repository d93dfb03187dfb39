"""Issue 20: careless users of the tools — `particles run`'s output folder and --frames, the
wedge farm's teardown, the progress display, `particles list` outside the checkout, the wheel's
configs. Each case works, or fails in one line naming the flag and the value, and changes nothing.
(The engine's API and config cases are tests/test_careless_frames.py, _input.py and _threads.py.)"""
import os

import numpy as np
import pytest
from helpers import one_line as _one_line

# -- particles run: the output folder and --frames ----------------------------------------------------
SPARKS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "configs", "sparks.toml")


def _call(*argv):
    import sys

    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from runhelp import call

    return call(*argv)


def test_a_second_run_into_a_locked_folder_is_refused_in_one_line(tmp_path):
    from engine.render.output import LOCK, lock_dir

    out = tmp_path / "out"
    held = lock_dir(str(out))  # a first run, still writing
    try:
        code, stdout, stderr = _call("run", SPARKS, "--frames", "1", "--size", "64x36", "--out", out, "--quiet")
        assert code == 2, stderr
        lines = stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"error: --out: {out} is being written by another "
                                                       f"particles run (pid {os.getpid()})"), stderr
        assert os.listdir(out) == [LOCK]  # the second run wrote nothing
        code, _, stderr = _call("run", SPARKS, "--frames", "1", "--size", "64x36", "--out", out, "--resume",
                                "--quiet")
        assert code == 2 and "another particles run" in stderr, stderr
    finally:
        held.release()
    assert os.listdir(out) == []  # the lock file goes with the run that held it
    again = lock_dir(str(out))  # and the folder can be locked again
    again.release()


@pytest.mark.slow
def test_two_runs_into_one_folder_the_second_is_refused(tmp_path):
    import subprocess
    import sys
    import time

    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from runhelp import command

    out = tmp_path / "out"
    cmd, kw = command("run", SPARKS, "--frames", "400", "--size", "64x36", "--out", out, "--quiet")
    first = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)
    try:
        deadline = time.monotonic() + 240
        while not (out / ".particles-run.json").exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        assert (out / ".particles-run.json").exists()
        code, _, stderr = _call("run", SPARKS, "--frames", "3", "--size", "80x40", "--seed", "9", "--out", out,
                                "--overwrite", "--quiet")
        assert code == 2 and f"pid {first.pid}" in stderr, stderr
    finally:
        first.terminate()
        first.wait(60)
    assert first.returncode in (0, 143), first.stderr.read()
    assert not (out / ".particles-run.lock").exists()  # the first run's lock went with it


def test_resume_refuses_a_mixed_folder(tmp_path):
    from engine.config import load_config
    from engine.render.output import OutputRefused, encode_png, frame_path
    from engine.render.resume import prepare_resume, run_record, write_record

    cfg = load_config(SPARKS, {"render.width": 64, "render.height": 36})
    out = str(tmp_path)
    record = run_record(cfg, "png", "cpu")
    write_record(out, record)
    for k, (w, h) in enumerate([(64, 36), (64, 36), (80, 40), (64, 36)]):  # another run's frame 2
        with open(frame_path(out, k), "wb") as fh:
            fh.write(encode_png(np.zeros((h, w, 3), np.uint8)))
    with pytest.raises(OutputRefused) as e:
        prepare_resume(out, record)
    text = _one_line(e)
    assert text.startswith(f"--resume: {out} is mixed: frame_00002.png is 80x40, this run renders 64x36"), text
    assert len(os.listdir(out)) == 5  # nothing removed
    os.remove(frame_path(out, 2))
    assert prepare_resume(out, record) == 2  # a gap: whole frames 0..1 kept, the one after it dropped


def test_out_at_a_symlink_loop_says_so(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    os.symlink(b, a)
    os.symlink(a, b)
    for out in (a, a / "sub"):
        code, _, stderr = _call("run", SPARKS, "--frames", "1", "--size", "64x36", "--out", out, "--quiet")
        assert code == 4, stderr
        lines = stderr.strip().splitlines()
        assert len(lines) == 1 and f"{a} is a symbolic link loop" in lines[0], stderr
        assert "File exists" not in stderr
    dangling = tmp_path / "gone"
    os.symlink(tmp_path / "nowhere" / "x", dangling)
    code, _, stderr = _call("run", SPARKS, "--frames", "1", "--size", "64x36", "--out", dangling, "--quiet")
    assert code == 4 and "which does not exist" in stderr, stderr


def test_run_frames_refuses_a_duration_that_validate_refuses(tmp_path):
    for duration, why in (("7200", "less than or equal to 3600"), ("0", "greater than 0"), ('"x"', "number")):
        cfg = tmp_path / "d.toml"
        cfg.write_text(f"fps = 30\nduration = {duration}\n[[emitters]]\nrate = 10.0\n")
        code, stdout, _ = _call("validate", cfg)
        assert code == 2 and f"duration: {duration.strip(chr(34))!s}" in stdout.replace("'", ""), stdout
        code, _, stderr = _call("run", cfg, "--frames", "1", "--size", "64x36", "--out", tmp_path / "o", "--quiet")
        assert code == 2, stderr
        lines = stderr.strip().splitlines()
        assert len(lines) == 1 and f"{cfg}: duration: " in lines[0] and why in lines[0], stderr
        assert not (tmp_path / "o").exists()


# -- particles wedge teardown -------------------------------------------------------------------------
def test_the_farm_shuts_down_with_dask_teardown_logs_silenced():
    import logging

    pytest.importorskip("distributed")
    from particles_tools.wedge import farm

    seen = {}

    class FakeClient:
        def run(self, fn, nanny=False):
            seen.setdefault("run", []).append((fn, nanny))

        def unsubscribe_topic(self, topic):
            pass

        def close(self):
            seen["client"] = logging.getLogger("distributed").getEffectiveLevel()

    class FakeCluster:
        def close(self):
            seen["cluster"] = {n: logging.getLogger(n).getEffectiveLevel() for n in ("distributed", "tornado",
                                                                                     "asyncio")}

    f = object.__new__(farm.Farm)
    f.client, f.cluster = FakeClient(), FakeCluster()
    levels = {n: logging.getLogger(n).level for n in ("distributed", "tornado", "asyncio")}
    try:
        f.close()
        assert seen["client"] > logging.CRITICAL
        assert all(v > logging.CRITICAL for v in seen["cluster"].values()), seen
        assert [nanny for _, nanny in seen["run"]] == [False, True]  # workers and nannies quietened first
        fn = seen["run"][0][0]
        fn()
        assert logging.getLogger("distributed").getEffectiveLevel() > logging.CRITICAL
    finally:
        for n, level in levels.items():
            logging.getLogger(n).setLevel(level)


@pytest.mark.slow
def test_the_progress_display_says_the_first_frame_compiles(tmp_path, monkeypatch):
    import contextlib

    from particles_tools import commands, progress

    notes = []

    class Bar:
        def advance(self, n=1, note=""):
            notes.append(("advance", note))

        def update(self, completed, note=""):
            notes.append(("update", note))

    @contextlib.contextmanager
    def fake(total, unit="items", label="", quiet=False, stream=None):
        yield Bar()

    monkeypatch.setattr(progress, "progress", fake)
    code, _, stderr = _call("run", SPARKS, "--frames", "2", "--size", "64x36", "--out", tmp_path / "o")
    assert code == 0, stderr
    assert notes[0] == ("update", commands.COMPILING) and "compiling kernels" in notes[0][1]
    assert notes[1][0] == "advance" and "compiling" not in notes[1][1]  # gone after the first frame


# -- particles list outside the checkout ----------------------------------------------------------------
def test_list_works_outside_the_checkout(tmp_path, monkeypatch):
    import shutil

    import particles_tools as tools

    monkeypatch.chdir(tmp_path)  # no configs/ here
    code, stdout, stderr = _call("list")
    assert code == 0, stderr
    assert stdout.splitlines()[0].startswith(f"configs in {tools.CONFIGS}/:") and "sparks.toml" in stdout
    # a wheel install: the configs under the prefix (pyproject's data-files)
    installed = tmp_path / "share" / "particles-engine" / "configs"
    installed.mkdir(parents=True)
    shutil.copy(SPARKS, installed / "sparks.toml")
    monkeypatch.setattr(tools, "CONFIGS", str(tmp_path / "no-checkout"))
    monkeypatch.setattr(tools, "INSTALLED_CONFIGS", str(installed))
    code, stdout, stderr = _call("list")
    assert code == 0 and f"configs in {installed}/:" in stdout and "sparks.toml" in stdout, stdout + stderr
    monkeypatch.setattr(tools, "INSTALLED_CONFIGS", str(tmp_path / "none"))
    code, stdout, stderr = _call("list")
    assert code == 2 and stderr.count("\n") == 1 and stderr.startswith("error: --dir: no configs/ folder in "), stderr


def test_the_wheel_ships_the_configs():
    try:
        import tomllib
    except ImportError:  # Python < 3.11
        import tomli as tomllib

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    with open(os.path.join(root, "pyproject.toml"), "rb") as fh:
        py = tomllib.load(fh)
    assert py["tool"]["setuptools"]["data-files"]["share/particles-engine/configs"] == ["configs/*.toml"]
    from particles_tools import INSTALLED_CONFIGS

    assert INSTALLED_CONFIGS.endswith(os.path.join("share", "particles-engine", "configs"))


def test_a_signal_inside_foreign_python_code_keeps_the_exit_code(tmp_path):
    """A stop signal that lands while Taichi runs Python through ``PyRun_String`` (pybind11's
    ``py::eval``) must still give 143 under ``python -m``: CPython ends such a process by SIGINT
    (-2) when an exact KeyboardInterrupt left that code, however it was caught later (CI saw it
    once). ``ctypes.pythonapi.PyRun_SimpleString`` stands in for Taichi's call."""
    import subprocess
    import sys

    from runhelp import ROOT

    (tmp_path / "stopme.py").write_text(
        "import ctypes, sys\n"
        "from particles_tools.signals import StopRequest\n"
        "with StopRequest() as stop:\n"
        "    try:\n"
        "        ctypes.pythonapi.PyRun_SimpleString(b'import os, signal, time\\n'\n"
        "            b'os.kill(os.getpid(), signal.SIGTERM)\\ntime.sleep(5)')\n"
        "    except KeyboardInterrupt:\n"
        "        pass\n"
        "sys.exit(128 + stop.signum)\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path), ROOT]))
    done = subprocess.run([sys.executable, "-m", "stopme"], env=env, capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 143, (done.returncode, done.stderr)
