"""Interrupted renders: SIGINT stops after the frames already simulated are written (exit 130);
SIGKILL leaves only whole frames; --resume finishes either one byte-identically to a run that was
never interrupted."""
import os
import signal
import subprocess
import time

import pytest

from runhelp import assert_whole_frames, command, particles, same_bytes, visible

FRAMES = 60
CONFIG = """seed = 7
fps = 30
frames = 60
[solver]
integrator = "symplectic_euler"
h = 0.002
[render]
width = 160
height = 90
[[emitters]]
effect = "sparks"
position = [-1.2, 1.0, 0.0]
direction = [0.8, 0.6, 0.0]
rate = 3000.0
[[colliders]]
type = "plane"
"""


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    d = tmp_path_factory.mktemp("interrupt")
    cfg = d / "effect.toml"
    cfg.write_text(CONFIG)
    ref = d / "reference"
    r = particles("run", cfg, "--out", ref, "--quiet")
    assert r.returncode == 0, r.stderr
    assert assert_whole_frames(ref) == FRAMES
    return cfg, ref


def start_and_signal(cfg, out, sig, after_frames=4):
    """Start a run, wait until a few frames exist, send ``sig``; returns the finished process."""
    cmd, kw = command("run", cfg, "--out", out, "--quiet")
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)
    try:
        marker = out / f"frame_{after_frames - 1:05d}.png"
        while not marker.exists():
            assert proc.poll() is None, proc.communicate()
            time.sleep(0.01)
        proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, stdout, stderr


def resume_and_compare(cfg, out, ref, n_before):
    r = particles("run", cfg, "--out", out, "--quiet", "--resume")
    assert r.returncode == 0, r.stderr
    assert f"resumed at frame {n_before}" in r.stdout
    assert not [f for f in os.listdir(out) if f.endswith(".tmp")]
    assert same_bytes(out, ref) == FRAMES


@pytest.mark.slow
def test_sigint_stops_cleanly_and_resume_matches(setup, tmp_path):
    cfg, ref = setup
    out = tmp_path / "out"
    code, stdout, stderr = start_and_signal(cfg, out, signal.SIGINT)
    assert code == 130, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and "stopped by SIGINT" in lines[0] and "--resume" in lines[0], stderr
    assert "Traceback" not in stderr
    n = assert_whole_frames(out)
    assert 4 <= n < FRAMES
    assert f"frames 0..{n - 1} kept" in lines[0]
    assert [f for f in os.listdir(out) if f.startswith(".")] == [".particles-run.json"]  # no temporaries
    resume_and_compare(cfg, out, ref, n)


@pytest.mark.slow
def test_sigkill_leaves_only_whole_frames_and_resume_matches(setup, tmp_path):
    cfg, ref = setup
    out = tmp_path / "out"
    code, _, _ = start_and_signal(cfg, out, signal.SIGKILL)
    assert code == -signal.SIGKILL
    n = assert_whole_frames(out)  # a frame cut short can only be a hidden .tmp file
    assert 4 <= n < FRAMES
    assert all(f.startswith(".") for f in set(os.listdir(out)) - set(visible(out)))
    resume_and_compare(cfg, out, ref, n)


@pytest.mark.slow
def test_resume_cleans_temporaries_and_drops_a_gap(setup, tmp_path):
    cfg, ref = setup
    out = tmp_path / "out"
    r = particles("run", cfg, "--out", out, "--quiet", "--frames", "12")
    assert r.returncode == 0, r.stderr
    os.remove(out / "frame_00007.png")  # frames after a gap are not trusted
    (out / ".frame_00012.png.tmp").write_bytes(b"\x89PNG half")
    with open(out / "frame_00006.png", "r+b") as fh:  # a torn frame is not whole
        fh.truncate(100)
    r = particles("run", cfg, "--out", out, "--quiet", "--resume")
    assert r.returncode == 0, r.stderr
    assert "resumed at frame 6" in r.stdout
    assert same_bytes(out, ref) == FRAMES
    assert not (out / ".frame_00012.png.tmp").exists()


@pytest.mark.slow
def test_resume_refuses_other_settings(setup, tmp_path):
    cfg, _ = setup
    out = tmp_path / "out"
    assert particles("run", cfg, "--out", out, "--quiet", "--frames", "2").returncode == 0
    r = particles("run", cfg, "--out", out, "--quiet", "--resume", "--seed", "8")
    assert r.returncode == 2 and "other settings (config.seed)" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert assert_whole_frames(out) == 2


def run_on_terminal(argv, until: bytes, timeout=120):
    """Start ``particles argv`` with stderr on a pseudo-terminal; read it until ``until`` shows
    (the progress display is drawn: the frame loop has started). Returns (process, master fd,
    bytes read so far)."""
    import pty
    import select

    master, slave = pty.openpty()
    cmd, kw = command(*argv)
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=slave, **kw)
    os.close(slave)
    seen, t0 = b"", time.monotonic()
    while until not in seen:
        assert time.monotonic() - t0 < timeout and proc.poll() is None, (proc.poll(), seen[-500:])
        if select.select([master], [], [], 0.2)[0]:
            seen += os.read(master, 65536)
    return proc, master, seen


def read_rest(proc, master, timeout=60):
    import select

    seen = b""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        r = select.select([master], [], [], 0.1)[0]
        if r:
            try:
                chunk = os.read(master, 65536)
            except OSError:  # the child closed the terminal
                break
            if not chunk:
                break
            seen += chunk
        elif proc.poll() is not None:
            break
    os.close(master)
    return seen


def test_progress_on_a_terminal_and_sigterm_mid_frame(tmp_path):
    """On a terminal `particles run` shows frames done, the rate and the time left; SIGTERM in the
    middle of a frame of ~100,000 steps stops it there (the step loop polls the flag), not at the
    frame's end, and exits 143 with one line and only whole frames."""
    cfg = tmp_path / "slow.toml"
    cfg.write_text(CONFIG.replace("h = 0.002", "h = 3e-7").replace("frames = 60", "frames = 3"))
    out = tmp_path / "out"
    proc, master, seen = run_on_terminal(["run", cfg, "--out", out, "--max-steps", "10000000"],
                                         until=b"frames/s")
    assert b"0/3" in seen and b"effect" not in seen or b"slow" in seen  # label, frames done of total
    t_signal = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    rest = read_rest(proc, master)
    stdout = proc.stdout.read().decode()
    proc.wait(timeout=60)
    waited = time.monotonic() - t_signal
    text = (seen + rest).decode(errors="replace")
    assert proc.returncode == 143, text
    assert "stopped by SIGTERM after 0 of 3 frames (no frames kept in" in text and "--resume" in text
    assert "Traceback" not in text and stdout == ""
    assert waited < 10  # a frame here is ~111,000 steps (tens of seconds): it did not run to its end
    assert sorted(os.listdir(out)) == [".particles-run.json"]


@pytest.mark.slow
def test_quiet_or_not_a_terminal_draws_no_progress(tmp_path):
    cfg = tmp_path / "q.toml"
    cfg.write_text(CONFIG.replace("frames = 60", "frames = 2"))
    proc, master, seen = run_on_terminal(["run", cfg, "--out", tmp_path / "o", "--quiet"], until=b"")
    rest = read_rest(proc, master)
    assert proc.wait(timeout=120) == 0 and (seen + rest) == b""
