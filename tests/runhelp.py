"""Running ``particles`` for tests: in this process (fast, shares the Taichi session) or as a real
``python -m engine`` subprocess; and checking what landed in an output folder."""
import contextlib
import io
import os
import subprocess
import sys

from PIL import Image

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ENV = dict(os.environ, TI_SKIP_VERSION_CHECK="ON", PYTHONPATH=ROOT)


def call(*argv):
    """``particles`` in this process: (exit code, stdout, stderr)."""
    from particles_tools import main as cli

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli.main([str(a) for a in argv])
    return code, out.getvalue(), err.getvalue()


def command(*argv, cwd=None, **kw):
    return [sys.executable, "-m", "engine", *[str(a) for a in argv]], dict(
        cwd=cwd or ROOT, env=ENV, **kw)


def particles(*argv, cwd=None):
    cmd, kw = command(*argv, cwd=cwd)
    return subprocess.run(cmd, capture_output=True, text=True, timeout=600, **kw)


def visible(folder):
    return sorted(f for f in os.listdir(folder) if not f.startswith("."))


def assert_whole_frames(folder):
    """Only frame_00000.png .. frame_{n-1}.png, each a complete PNG; returns n."""
    names = visible(folder)
    assert names == [f"frame_{k:05d}.png" for k in range(len(names))], names
    for name in names:
        with Image.open(os.path.join(folder, name)) as im:
            im.load()  # raises on a truncated file
    return len(names)


def same_bytes(a, b):
    na, nb = visible(a), visible(b)
    assert na == nb, (na, nb)
    for name in na:
        with open(os.path.join(a, name), "rb") as fa, open(os.path.join(b, name), "rb") as fb:
            assert fa.read() == fb.read(), name
    return len(na)
