"""The command line as a user meets it: run, validate, list; exit codes and one-line errors."""
import os
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from runhelp import call
from helpers import quick

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ENV = dict(os.environ, TI_SKIP_VERSION_CHECK="ON", PYTHONPATH=ROOT)


def real_particles(*args, cwd=None):
    """``python -m engine ...`` in a fresh process (as a user runs it)."""
    return subprocess.run([sys.executable, "-m", "engine", *args], capture_output=True, text=True,
                          cwd=cwd or ROOT, env=ENV, timeout=300)


def particles(*args):
    """The same command in this process (no interpreter and Taichi start-up per call; the
    subprocess path is covered by real_particles, test_interrupt and the fuzz test)."""
    code, out, err = call(*[os.path.join(ROOT, a) if a.startswith("configs") else a for a in args])
    return subprocess.CompletedProcess(args, code, out, err)


def visible(folder):
    """The files a user sees: the run record and temporaries are hidden dot-files."""
    return sorted(f for f in os.listdir(folder) if not f.startswith("."))


def load(path):
    return np.asarray(Image.open(path).convert("RGB"))


@pytest.mark.slow
@pytest.mark.parametrize("config", ["sparks", "dust"])
def test_run_renders_non_blank_frames(tmp_path, config):
    out = tmp_path / config
    r = particles("run", f"configs/{config}.toml", "--frames", "12", "--out", str(out), "--quiet",
                  "--size", "160x90")
    assert r.returncode == 0, r.stderr
    files = visible(out)
    assert files == [f"frame_{k:05d}.png" for k in range(12)]
    img = load(out / files[-1])
    assert img.shape == (90, 160, 3)
    # not blank: the background has structure and the effect adds pixels well above it
    first = load(out / files[0]).astype(int)
    assert np.abs(img.astype(int) - first).sum(axis=2).max() > 60
    assert "peak live particles" in r.stdout


@pytest.mark.slow  # two whole CLI runs (~25 s): the default run stays under 5 minutes on 2 cores
def test_same_config_and_seed_give_byte_identical_pngs(tmp_path):
    outs = []
    for k in range(2):
        out = tmp_path / f"run{k}"
        r = real_particles("run", "configs/sparks.toml", "--frames", "8", "--out", str(out), "--quiet",
                           "--size", "128x72")
        assert r.returncode == 0, r.stderr
        outs.append(out)
    for name in visible(outs[0]):
        assert (outs[0] / name).read_bytes() == (outs[1] / name).read_bytes(), name


@pytest.mark.slow
def test_refuses_to_overwrite_without_flag(tmp_path):
    out = tmp_path / "o"
    assert particles("run", "configs/dust.toml", "--frames", "1", "--out", str(out), "--quiet",
                     "--size", "64x36").returncode == 0
    r = particles("run", "configs/dust.toml", "--frames", "1", "--out", str(out), "--quiet")
    assert r.returncode == 2 and "--overwrite" in r.stderr and "Traceback" not in r.stderr
    r = particles("run", "configs/dust.toml", "--frames", "1", "--out", str(out), "--quiet",
                  "--overwrite", "--size", "64x36")
    assert r.returncode == 0


@pytest.mark.parametrize("body,key", [
    ('[[emitters]]\nrat = 10\n', "emitters[0].rat"),
    ('[[emitters]]\nrate = -5\n', "emitters[0].rate"),
    ('[[emitters]]\nrate = "fast"\n', "emitters[0].rate"),
    ('fps = 30\n', "emitters"),
    ('[[emitters]]\nrate = 10\n[solver]\nintegrator = "rk5"\n', "solver.integrator"),
    ('[[emitters]]\nrate = 10\n[[colliders]]\ntype = "sphere"\nradius = 0\n', "colliders[0].radius"),
    ('this is = = not toml', "not valid TOML"),
])
def test_bad_config_exits_2_with_one_line_naming_the_key(tmp_path, body, key):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(body)
    out = tmp_path / "out"
    for cmd in (["validate", str(cfg)], ["run", str(cfg), "--out", str(out)]):
        r = particles(*cmd)
        assert r.returncode == 2, (cmd, r.stdout, r.stderr)
        text = (r.stdout + r.stderr).strip()
        assert "Traceback" not in text
        lines = [ln for ln in text.splitlines() if ln.strip()]
        assert len(lines) == 1 and key in lines[0], text
    assert not out.exists()  # no output for bad input


def test_missing_config_file(tmp_path):
    r = particles("run", str(tmp_path / "nope.toml"))
    assert r.returncode == 2 and "file not found" in r.stderr and "Traceback" not in r.stderr


def test_validate_and_list_shipped_configs():
    r = particles("validate", *sorted(f"configs/{f}" for f in os.listdir(os.path.join(ROOT, "configs"))))
    assert r.returncode == 0 and r.stdout.count(": ok") >= 2, r.stdout + r.stderr
    r = particles("list")
    assert r.returncode == 0 and "sparks.toml" in r.stdout and "dust" in r.stdout


@pytest.mark.slow
def test_mp4_output(tmp_path):
    out = tmp_path / "m"
    r = particles("run", "configs/dust.toml", "--frames", "8", "--out", str(out), "--format", "mp4",
                  "--quiet", "--size", "96x54", "--arch", "cpu")
    assert r.returncode == 0, r.stderr
    assert visible(out) == ["dust.mp4"]
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(out / "dust.mp4"))
    meta = next(reader)
    frames = list(reader)
    assert meta["size"] == (96, 54) and len(frames) == 8


@pytest.mark.slow
def test_gif_output_is_whole(tmp_path):
    out = tmp_path / "g"
    r = particles("run", "configs/sparks.toml", "--frames", "6", "--out", str(out), "--format", "gif",
                  "--quiet", "--size", "96x54")
    assert r.returncode == 0, r.stderr
    assert visible(out) == ["sparks.gif"]
    assert Image.open(out / "sparks.gif").n_frames == 6


@pytest.mark.parametrize("integrator", quick(["euler", "midpoint", "rk4", "symplectic_euler", "verlet"],
                                               keep={"rk4"}))
def test_divergence_exits_3_naming_integrator_h_and_time(tmp_path, integrator):
    # drag k = 2000 1/s at h = 1/30 s: hk ≈ 67, far outside every explicit method's stability region
    cfg = tmp_path / "stiff.toml"
    cfg.write_text(f'fps = 30\nframes = 40\n[solver]\nintegrator = "{integrator}"\nh = 0.0333334\n'
                   '[forces]\ndrag = 2000.0\n[render]\nwidth = 32\nheight = 18\n'
                   '[[emitters]]\nrate = 50.0\nspeed = [1.0, 2.0]\n')
    out = tmp_path / "out"
    r = particles("run", str(cfg), "--out", str(out), "--quiet")
    assert r.returncode == 3, r.stderr
    msg = r.stderr.strip().splitlines()
    assert len(msg) == 1 and integrator in msg[0] and "h=0.03333" in msg[0] and "t=" in msg[0], msg
    frames = visible(out)
    assert 1 <= len(frames) < 40 and all(f.startswith("frame_") for f in frames)
