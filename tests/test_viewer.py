"""The live viewer in a real window on a virtual X screen (Xvfb), and its no-display message."""
import os
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
    num = 140 + os.getpid() % 50
    proc = subprocess.Popen([xvfb, f":{num}", "-screen", "0", "800x600x24", "-nolisten", "tcp"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    sock = f"/tmp/.X11-unix/X{num}"
    for _ in range(100):
        if os.path.exists(sock):
            break
        time.sleep(0.05)
    yield f":{num}"
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
