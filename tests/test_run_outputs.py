"""Where frames go and what happens when they cannot: the config's ``output`` folder stays inside
renders/, unwritable output and a full disk give one line and exit 4 with no partial frame,
capacity overflow is reported, and frames do not depend on the CPU thread count."""
import errno
import os
import re

import pytest

from engine.render import output
from runhelp import assert_whole_frames, call, particles, same_bytes

TINY = """seed = 2
fps = 30
frames = 6
{extra}
[render]
width = 48
height = 32
[[emitters]]
effect = "sparks"
rate = {rate}
{emitter}
"""


def write_cfg(folder, name="fx", extra="", rate=400.0, emitter=""):
    path = folder / f"{name}.toml"
    path.write_text(TINY.format(extra=extra, rate=rate, emitter=emitter))
    return path


@pytest.mark.slow
def test_config_output_folder_lands_under_renders(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    cfg = write_cfg(tmp_path, extra='output = "shots/my_sparks"')
    code, out, err = call("run", cfg, "--quiet")
    assert code == 0, err
    assert assert_whole_frames(tmp_path / "renders" / "shots" / "my_sparks") == 6
    # without `output` the default stays renders/<config name>
    cfg = write_cfg(tmp_path, name="plain")
    assert call("run", cfg, "--quiet")[0] == 0
    assert assert_whole_frames(tmp_path / "renders" / "plain") == 6


@pytest.mark.parametrize("value", ["/tmp/x", "../x", "a/../../x", "C:/x", "", "..", "a\\\\b"])
def test_config_output_cannot_leave_renders(tmp_path, monkeypatch, value):
    monkeypatch.chdir(tmp_path)
    cfg = write_cfg(tmp_path, extra=f'output = "{value}"')
    code, out, err = call("run", cfg, "--quiet")
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and f"{cfg}: output: " in lines[0], err
    assert not (tmp_path / "renders").exists()


@pytest.mark.slow
def test_config_output_through_a_symlink_is_refused_but_out_may_go_anywhere(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "renders").mkdir()
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    os.symlink(elsewhere, tmp_path / "renders" / "link")
    cfg = write_cfg(tmp_path, extra='output = "link/fx"')
    code, out, err = call("run", cfg, "--quiet")
    assert code == 2 and "leads outside renders/" in err, err
    assert os.listdir(elsewhere) == []
    code, out, err = call("run", cfg, "--quiet", "--out", elsewhere / "fx")  # the command line may
    assert code == 0, err
    assert assert_whole_frames(elsewhere / "fx") == 6


@pytest.mark.parametrize("target", ["file", "/proc/particles-test/out"])
def test_unwritable_output_exits_4_with_one_line(tmp_path, target):
    cfg = write_cfg(tmp_path)
    out = tmp_path / "a-file" if target == "file" else target
    if target == "file":
        out.write_text("not a folder")
    code, stdout, err = call("run", cfg, "--out", out, "--quiet")
    lines = err.strip().splitlines()
    assert code == 4 and len(lines) == 1 and str(out) in lines[0], err
    if target == "file":
        assert out.read_text() == "not a folder"


def test_disk_full_mid_run_exits_4_and_leaves_no_partial_frame(tmp_path, monkeypatch):
    cfg = write_cfg(tmp_path)
    out = tmp_path / "out"
    real_write = output._write_bytes
    calls = []
    failed = []

    def write(path, data):
        calls.append(path)
        if "frame_00003" in os.path.basename(path):  # frame 3: half a file, then the disk is full
            failed.append(int(re.search(r"frame_(\d+)", os.path.basename(path)).group(1)))
            real_write(path, data[: len(data) // 2])
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real_write(path, data)

    monkeypatch.setattr(output, "_write_bytes", write)
    code, stdout, err = call("run", cfg, "--out", out, "--quiet", "--workers", 2)
    lines = err.strip().splitlines()
    assert code == 4, err
    assert len(lines) == 1 and "No space left on device" in lines[0] and str(out) in lines[0], err
    # two encoders in parallel finish frames in any order: frames before the failed one are still
    # written, frames after it are not (or are removed): the folder ends at the failed frame
    k = failed[0]
    assert k == 3 and f"writing frame {k} " in lines[0] and f"frames 0..{k - 1} kept" in lines[0]
    assert assert_whole_frames(out) == k
    assert [f for f in os.listdir(out) if f.startswith(".")] == [".particles-run.json"]


@pytest.mark.slow
def test_emitter_over_capacity_keeps_running_and_reports_drops(tmp_path):
    # 1,200 particles/s living 5 s into 40 slots: 6 frames want 240 particles; 200 do not fit
    cfg = write_cfg(tmp_path, rate=1200.0, emitter="lifetime = 5.0\nlifetime_randomness = 0.0\ncapacity = 40")
    code, stdout, err = call("run", cfg, "--out", tmp_path / "out", "--quiet")
    assert code == 0, err
    assert assert_whole_frames(tmp_path / "out") == 6
    m = re.search(r"peak live particles ([\d,]+) of ([\d,]+); dropped ([\d,]+)", stdout)
    assert m, stdout
    peak, cap, dropped = (int(g.replace(",", "")) for g in m.groups())
    assert peak == cap == 40
    assert 195 <= dropped <= 200
    assert "particles did not fit" in err and f"{dropped:,}" in err


@pytest.mark.slow  # (the default run checks 1 vs 2 threads in tests/test_render.py)
def test_frames_are_identical_with_one_and_two_threads(tmp_path):
    outs = []
    for threads, where in ((1, "before"), (2, "after"), (2, "again")):
        out = tmp_path / f"t{threads}{where}"
        args = ["run", "configs/sparks.toml", "--frames", "10", "--size", "160x90", "--out", out,
                "--quiet"]
        r = particles(*(["--threads", threads] + args if where == "before" else args + ["--threads", threads]))
        assert r.returncode == 0, r.stderr
        outs.append(out)
    assert same_bytes(outs[0], outs[1]) == 10
    assert same_bytes(outs[1], outs[2]) == 10


def test_bad_thread_count_is_bad_input(tmp_path):
    r = particles("--threads", "0", "run", "configs/sparks.toml", "--out", tmp_path / "o")
    assert r.returncode == 2 and "--threads" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "o").exists()


def test_frames_land_in_order_even_when_encoders_finish_out_of_order(tmp_path, monkeypatch):
    """Encoders run in parallel, but a frame is renamed into place only after the one before it:
    the visible frames are a prefix of the run at every moment (a SIGKILL leaves no gap)."""
    import threading

    import numpy as np

    real_encode = output.encode_png
    release = threading.Event()
    seen = []

    def encode(img, level=1):
        if img[0, 0, 0] == 0:  # frame 0 waits until frame 1 has been written under its hidden name
            assert release.wait(10)
        return real_encode(img, level)

    def write(path, data):
        with open(path, "wb") as fh:
            fh.write(data)
        if ".frame_00001" in path:  # frame 1 is whole before frame 0: it must still wait for it
            release.set()
        seen.append(sorted(f for f in os.listdir(out) if not f.startswith(".")))

    out = tmp_path / "out"
    out.mkdir()
    monkeypatch.setattr(output, "encode_png", encode)
    monkeypatch.setattr(output, "_write_bytes", write)
    w = output.FrameWriter(str(out), "png", workers=2)
    for k in range(4):
        w.submit(k, np.full((4, 4, 3), k, np.uint8))
    w.close()
    assert sorted(os.listdir(out)) == [f"frame_{k:05d}.png" for k in range(4)]
    for names in seen:  # every listing taken while frames were being written: a prefix
        assert names == [f"frame_{k:05d}.png" for k in range(len(names))], names
