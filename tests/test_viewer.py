"""The live viewer in a real window on a virtual X screen (Xvfb), and its no-display message."""
import os
import select
import shutil
import subprocess
import sys
import time

import numpy as np
import pytest
from PIL import Image

from test_cli import ENV, ROOT


@pytest.fixture(scope="module")
def xdisplay():
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        if os.environ.get("CI"):
            pytest.fail("Xvfb is missing: .ci/run installs it (Debian package xvfb)")
        pytest.skip("Xvfb not installed (apt-get install xvfb x11-apps)")
    # -displayfd: the server takes a free display and writes its number once it accepts
    # clients (a socket file that exists is not yet a server that answers)
    r, w = os.pipe()
    proc = subprocess.Popen([xvfb, "-displayfd", str(w), "-screen", "0", "800x600x24", "-nolisten", "tcp"],
                            pass_fds=(w,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(w)
    got, deadline = b"", time.monotonic() + 30
    while not got.endswith(b"\n") and time.monotonic() < deadline:
        if select.select([r], [], [], 0.5)[0]:
            chunk = os.read(r, 16)
            if not chunk:
                break  # the server ended before it was ready
            got += chunk
    os.close(r)
    if not got.endswith(b"\n"):
        proc.kill()
        pytest.fail(f"Xvfb did not start (exit {proc.wait(timeout=10)})")
    yield f":{int(got)}"
    proc.terminate()
    proc.wait(timeout=10)


@pytest.mark.slow
def test_viewer_shows_frames_in_a_window(tmp_path, xdisplay):
    shot = tmp_path / "shot.png"
    env = dict(ENV, DISPLAY=xdisplay)
    proc = subprocess.Popen([sys.executable, "-m", "engine", "view", "configs/sparks.toml", "--frames", "40",
                             "--screenshot", str(shot)], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    grabbed = None
    if shutil.which("xwd"):  # a real screen grab while the window is up
        for _ in range(200):
            time.sleep(0.1)
            if proc.poll() is not None:
                break
            raw = subprocess.run(["xwd", "-root", "-display", xdisplay, "-silent"], capture_output=True).stdout
            px = np.frombuffer(raw[-800 * 600 * 4:], np.uint8) if len(raw) > 800 * 600 * 4 else None
            if px is not None and px.std() > 5:
                grabbed = px
                break
    out, err = proc.communicate(timeout=240)
    assert proc.returncode == 0, err
    assert "frames/s" in out
    img = np.asarray(Image.open(shot).convert("RGB")).astype(float)
    assert img.std() > 5 and img.max() > 120  # the scene, with the overlay text, not a blank window
    if shutil.which("xwd"):
        assert grabbed is not None, "the virtual screen stayed blank"


def test_viewer_says_clearly_when_there_is_no_display():
    env = {k: v for k, v in ENV.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    r = subprocess.run([sys.executable, "-m", "engine", "view", "configs/sparks.toml"], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "no display" in r.stderr and "Traceback" not in r.stderr


def test_viewer_says_clearly_when_no_server_answers_on_the_display():
    """DISPLAY set, but no X server there (one that went away): one line naming the display,
    exit 2, nothing on stdout, no traceback (Taichi's own error log and blank lines held back)."""
    num = next(n for n in range(900, 1000) if not os.path.exists(f"/tmp/.X11-unix/X{n}")
               and not os.path.exists(f"/tmp/.X{n}-lock"))
    env = dict({k: v for k, v in ENV.items() if k != "WAYLAND_DISPLAY"}, DISPLAY=f":{num}")
    r = subprocess.run([sys.executable, "-m", "engine", "view", "configs/sparks.toml"], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=120)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert f"':{num}'" in lines[0] and "cannot open a window" in lines[0]
    assert "Traceback" not in r.stderr and r.stdout.strip() == ""


def test_viewer_refuses_a_bad_config_in_one_line_before_a_window_opens(tmp_path):
    # a config the loader accepts key by key but no scene can be built from (a silent emitter),
    # and a file that is not there: exit 2, one line naming the file and the key, no traceback
    cfg = tmp_path / "silent.toml"
    cfg.write_text(open(os.path.join(ROOT, "configs", "sparks.toml")).read().replace(
        "rate = 1800.0", "rate = 0.0"))
    for path, needle in ((cfg, "emitters[0].rate"), (tmp_path / "missing.toml", "not found")):
        r = subprocess.run([sys.executable, "-m", "engine", "view", str(path)], cwd=ROOT, env=ENV,
                           capture_output=True, text=True, timeout=120)
        lines = r.stderr.strip().splitlines()
        assert r.returncode == 2 and len(lines) == 1, r.stderr
        assert str(path) in lines[0] and needle in lines[0] and "Traceback" not in r.stderr
